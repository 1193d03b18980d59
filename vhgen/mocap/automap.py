"""Automatic skeleton mapping: any humanoid BVH skeleton onto the MakeHuman ``cmu_mb`` bones.

Three kinds of evidence, used together:

* **Names** (:mod:`vhgen.mocap.jointnames`): side and part evidence per joint.
* **Topology**: the pelvis is where the two leg chains meet (or a joint named pelvis above
  that), the chest where the two arm chains meet; each chain from there to its end (foot,
  hand, head) is aligned in order with the target parts (hip joint, thigh, shin / clavicle,
  upper arm, forearm / spine segments, neck) by the best total name score, with long
  segments preferred where names are silent. Joints on no chain, fingers, twist helpers,
  end markers and a static root above the pelvis map to none and fold into their mapped
  parent.
* **Geometry** (world positions from forward kinematics, so bone-local OFFSET conventions
  do not matter): the world up axis (head above the feet over the clip), the subject's
  left (up x forward, forward from the feet), which catches mirrored naming, and a
  reference frame (the frame with the straightest, most upright limbs) that defines the
  straightened reference pose.

A mapping is accepted only if every essential part is found (pelvis, head, both thighs,
shins, feet, upper arms, forearms, hands); otherwise :class:`RetargetError` names what is
missing. The result is a :class:`~vhgen.mocap.retarget.RetargetMap` named ``auto`` with a
confidence in [0, 1] and an explanation per joint; :func:`map_to_yaml` writes it as an
editable map file.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.errors import RetargetError
from vhgen.mocap.bvh import Motion
from vhgen.mocap.jointnames import ESSENTIAL, PART_BONES, NameInfo, classify
from vhgen.mocap.retargetmap import Retargeter, RetargetMap

AXES = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0),
        "-y": (0.0, -1.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}


@dataclass
class _Skeleton:
    motion: Motion
    info: list[NameInfo]
    children: list[list[int]]
    ancestors: list[set[int]]
    seg: np.ndarray  # (J,) length of the bone from the parent to each joint, file units

    def is_anc(self, a: int, b: int) -> bool:
        """a is a proper ancestor of b."""
        return a in self.ancestors[b]

    def path(self, a: int, b: int) -> list[int]:
        """Joints from a (exclusive) down to b (inclusive); a must be an ancestor of b."""
        out = []
        while b != a:
            out.append(b)
            b = int(self.motion.parents[b])
        return out[::-1]

    def lca(self, a: int, b: int) -> int:
        anc = self.ancestors[a] | {a}
        while b not in anc:
            b = int(self.motion.parents[b])
        return b


def joint_tree(parents: np.ndarray) -> tuple[list[list[int]], list[set[int]]]:
    """Children and ancestor sets of every joint (parents before children)."""
    children: list[list[int]] = [[] for _ in range(len(parents))]
    ancestors: list[set[int]] = []
    for j, p in enumerate(parents):
        if p >= 0:
            children[p].append(j)
        ancestors.append(set() if p < 0 else ancestors[p] | {int(p)})
    return children, ancestors


def _skeleton(motion: Motion) -> _Skeleton:
    children, ancestors = joint_tree(motion.parents)
    seg = np.linalg.norm(motion.translations[0], axis=1)
    seg[motion.parents < 0] = 0.0
    return _Skeleton(motion, [classify(nm) for nm in motion.names], children, ancestors, seg)


def _pick(sk: _Skeleton, part: str, side: str | None) -> int | None:
    """Best joint named as ``part`` on ``side``; of two on one chain, the upper one."""
    cand = [j for j, i in enumerate(sk.info)
            if i.kind == "body" and i.side == side and i.parts.get(part, 0) > 0]
    if not cand:
        return None
    # drop candidates below another candidate (Kinect v2 AnkleLeft > FootLeft)
    top = [j for j in cand if not any(sk.is_anc(k, j) for k in cand)]
    return max(top, key=lambda j: (sk.info[j].parts[part], -len(sk.ancestors[j])))


def _align(sk: _Skeleton, chain: list[int], parts: list[tuple[str, bool]]
           ) -> tuple[dict[int, str], dict[int, float]]:
    """Assign ordered ``parts`` (name, required) to joints of ``chain`` (top to bottom).

    Maximises the sum of name scores plus a small bonus for long segments on required
    parts; optional parts are only given to joints whose name supports them. Returns
    joint -> part and joint -> name evidence.
    """
    usable = [j for j in chain if sk.info[j].kind in ("body", "other")]
    total = float(sum(sk.seg[j] for j in chain[1:])) + 1e-12
    best: tuple[float, dict[int, str]] | None = None
    idx_of = {j: k for k, j in enumerate(chain)}
    n_req = sum(1 for _, r in parts if r)
    for k in range(n_req, len(parts) + 1):
        for sel_parts in itertools.combinations(range(len(parts)), k):
            if any(parts[p][1] and p not in sel_parts for p in range(len(parts))):
                continue
            for joints in itertools.combinations(usable, k):
                score = 0.0
                ok = True
                for p, j in zip(sel_parts, joints, strict=True):
                    name_s = sk.info[j].parts.get(parts[p][0], 0.0)
                    if not parts[p][1] and name_s <= 0:
                        ok = False
                        break
                    score += name_s
                if not ok:
                    continue
                # segment from each required joint to the next chosen joint (or chain end)
                ends = [idx_of[j] for j in joints[1:]] + [len(chain) - 1]
                for p, j, e in zip(sel_parts, joints, ends, strict=True):
                    if parts[p][1]:
                        length = float(sum(sk.seg[chain[m]] for m in range(idx_of[j] + 1, e + 1)))
                        score += 0.3 * length / total - (0.5 if length <= 1e-9 else 0.0)
                if best is None or score > best[0] + 1e-12:
                    best = (score, {j: parts[p][0] for p, j in zip(sel_parts, joints,
                                                                   strict=True)})
    if best is None:
        return {}, {}
    ev = {j: sk.info[j].parts.get(p, 0.0) for j, p in best[1].items()}
    return best[1], ev


def _named_first(sk: _Skeleton, joints: list[int]) -> list[int]:
    """The joints whose names say they are spine/neck. Unrecognised names take a spine or
    neck bone only in a skeleton whose names are mostly unrecognised (otherwise an unnamed
    helper inserted in a named spine folds instead of taking a target bone)."""
    named = [j for j in joints if sk.info[j].parts]
    body = [i for i in sk.info if i.kind in ("body", "other")]
    anonymous = sum(1 for i in body if i.kind == "other") > 0.5 * len(body)
    return joints if anonymous and not named else named


def _spread(joints: list[int], targets: list[str]) -> dict[int, str]:
    """First and last joints take the first and last targets; middle ones fold."""
    if not joints or not targets:
        return {}
    if len(joints) <= len(targets):
        return dict(zip(joints, targets, strict=False))
    out = {joints[k]: targets[k] for k in range(len(targets) - 1)}
    out[joints[-1]] = targets[-1]
    return out


def _snap_axis(v: np.ndarray) -> str:
    k = int(np.argmax(np.abs(v)))
    return ("+" if v[k] > 0 else "-") + "xyz"[k]


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 1e-12, v / np.where(n > 1e-12, n, 1.0), 0.0)


def _foot_forward(sk: _Skeleton, foot: int, toe: int | None, g: np.ndarray,
                  p: np.ndarray) -> np.ndarray:
    """(F, 3) heel-to-toe direction of one foot in file world coordinates (0 if unknown)."""
    m = sk.motion
    if toe is not None:
        return p[:, toe] - p[:, foot]
    if np.isfinite(m.end_sites[foot]).all():
        return np.einsum("fab,b->fa", g[:, foot], m.end_sites[foot])
    kids = sk.children[foot]
    if kids:
        return np.mean([p[:, c] - p[:, foot] for c in kids], axis=0)
    return np.zeros_like(p[:, foot])


def _forward(sk: _Skeleton, inv: dict[str, int], g: np.ndarray, p: np.ndarray,
             upv: np.ndarray) -> tuple[np.ndarray | None, str]:
    """(F, 3) horizontal forward of the subject per frame (its length weighs the frame),
    from the feet (heel to toe) if they point somewhere horizontal, else from the knees
    (which bend forward); None if neither says anything."""
    def horiz(v: np.ndarray) -> np.ndarray:
        return v - np.outer(v @ upv, upv)
    feet = [_foot_forward(sk, inv[f"{s}Foot"], inv.get(f"{s}ToeBase"), g, p)
            for s in ("Left", "Right")]
    fh = horiz(feet[0] + feet[1])
    length = np.linalg.norm(feet[0], axis=1) + np.linalg.norm(feet[1], axis=1)
    if float(np.linalg.norm(fh, axis=1).mean()) > 0.3 * float(length.mean()) > 0:
        return _unit(fh), "feet"
    knee = np.zeros_like(fh)
    leg = 0.0
    for s in ("Left", "Right"):
        hip, kn, ank = (p[:, inv[f"{s}{b}"]] for b in ("UpLeg", "Leg", "Foot"))
        knee += horiz(kn - 0.5 * (hip + ank))
        leg += float(np.linalg.norm(ank - hip, axis=1).mean())
    if leg > 0 and float(np.linalg.norm(knee, axis=1).mean()) > 0.02 * leg:
        return knee / leg, "knees"
    return None, ""


def auto_map(motion: Motion) -> RetargetMap:
    """An automatic retarget map for ``motion``; raises RetargetError if not humanoid."""
    sk = _skeleton(motion)
    info = sk.info
    src = motion.source or "<string>"
    key: dict[str, int | None] = {}
    for part in ("foot", "hand"):
        for side in ("L", "R"):
            key[f"{part}{side}"] = _pick(sk, part, side)
    key["head"] = _pick(sk, "head", None)
    # topology fallback for unnamed ends: the child of the named joint above
    for end, above in (("foot", "shin"), ("hand", "forearm")):
        for side in ("L", "R"):
            j = _pick(sk, above, side)
            if key[f"{end}{side}"] is None and j is not None and sk.children[j]:
                key[f"{end}{side}"] = sk.children[j][0]
    if key["head"] is None:
        j = _pick(sk, "neck", None)
        if j is not None and sk.children[j]:
            key["head"] = max(sk.children[j], key=lambda c: sk.seg[c] if info[c].side is None
                              else -1.0)
    words = {"footL": "left foot", "footR": "right foot", "handL": "left hand",
             "handR": "right hand", "head": "head"}
    missing = [words[k] for k, v in key.items() if v is None]
    if missing:
        raise RetargetError(
            f"{src}: not a complete humanoid skeleton ({motion.num_joints} joints, root "
            f"{motion.names[0]!r}): no {', '.join(missing)} found ({_recognised(sk)}); "
            "refusing rather than leaving limbs at rest. Map it by hand: a retarget-map "
            "YAML passed with --map.")
    fl, fr, hl, hr, head = (int(key[k] or 0) for k in ("footL", "footR", "handL", "handR",
                                                         "head"))  # none is None here
    pelvis = sk.lca(fl, fr)
    named_pelvis = _pick(sk, "pelvis", None)
    chest = sk.lca(hl, hr)
    pelvis_why = "pelvis: where the leg chains meet"
    if named_pelvis is not None and sk.is_anc(named_pelvis, pelvis) and \
            sk.is_anc(named_pelvis, chest):
        pelvis = named_pelvis
        pelvis_why = "pelvis: name, above where the leg chains meet"
    problems = []
    if not (chest == pelvis or sk.is_anc(pelvis, chest)):
        problems.append(f"the arms ({motion.names[hl]!r}, {motion.names[hr]!r}) do not hang "
                        f"from the body above the pelvis {motion.names[pelvis]!r}")
    if not sk.is_anc(pelvis, head):
        problems.append(f"the head {motion.names[head]!r} is not above the pelvis "
                        f"{motion.names[pelvis]!r}")
    if chest != pelvis and (sk.is_anc(chest, fl) or sk.is_anc(chest, fr)):
        problems.append("a foot hangs from the chest")
    if problems:
        raise RetargetError(f"{src}: not a humanoid hierarchy: {'; '.join(problems)}")

    mapping: dict[int, str] = {pelvis: "Hips", head: "Head"}
    evidence: dict[int, float] = {pelvis: info[pelvis].parts.get("pelvis", 0.0),
                                  head: info[head].parts.get("head", 0.0)}
    why: dict[int, str] = {pelvis: pelvis_why,
                           head: "head: end of the spine chain"}
    hip_split = sk.lca(fl, fr)  # the pelvis, or a spine joint below a named pelvis (Biped)
    for side, foot, hand in (("L", fl, hl), ("R", fr, hr)):
        leg = sk.path(hip_split, foot)
        got, ev = _align(sk, leg[:-1], [("hipjoint", False), ("thigh", True), ("shin", True)])
        got[foot] = "foot"
        ev[foot] = info[foot].parts.get("foot", 0.0)
        toes = [c for c in range(len(info)) if foot in sk.ancestors[c] and
                info[c].kind == "body" and info[c].parts.get("toe", 0) > 0]
        if toes:
            toe = max(toes, key=lambda c: (info[c].parts["toe"], -len(sk.ancestors[c])))
            got[toe], ev[toe] = "toe", info[toe].parts["toe"]
        arm = sk.path(chest, hand) if chest != hand else []
        got_a, ev_a = _align(sk, arm[:-1], [("clavicle", False), ("upperarm", True),
                                            ("forearm", True)])
        got_a[hand] = "hand"
        ev_a[hand] = info[hand].parts.get("hand", 0.0)
        got.update(got_a)
        ev.update(ev_a)
        for j, part in got.items():
            mapping[j] = PART_BONES[(part, side)]
            evidence[j] = ev[j]
            limb = "leg" if part in ("thigh", "shin", "hipjoint") else "arm"
            why[j] = (f"{part}: name {motion.names[j]!r}" if ev[j] >= 0.5 else
                      f"{part}: position on the {limb} chain")
    # spine: pelvis (excl.) .. chest (incl.); neck: chest (excl.) .. head (excl.)
    if chest != pelvis:
        spine = _named_first(sk, [j for j in sk.path(pelvis, chest)[:-1]
                                  if info[j].kind in ("body", "other")]) + [chest]
        chest_is_neck = info[chest].parts.get("neck", 0) > max(
            info[chest].parts.get("chest", 0), info[chest].parts.get("spine", 0))
        lower = [j for j in spine if j != chest]
        targets = {chest: "Neck" if chest_is_neck else "Spine1"}
        if chest_is_neck and lower:
            targets[lower.pop()] = "Spine1"
        targets.update(_spread(lower, ["LowerBack", "Spine"]))
        for j, t in targets.items():
            mapping[j] = t
            evidence[j] = max(info[j].parts.get(p, 0.0) for p in ("spine", "chest", "neck"))
            why[j] = ("chest: where the arm chains meet" if j == chest
                      else "spine: between pelvis and chest")
    top = chest if sk.is_anc(chest, head) else pelvis
    necks = _named_first(sk, [j for j in sk.path(top, head)[:-1]
                              if info[j].kind in ("body", "other") and j not in mapping])
    neck_targets = ["Neck1"] if "Neck" in mapping.values() else ["Neck", "Neck1"]
    for j, t in _spread(necks, neck_targets).items():
        mapping[j] = t
        evidence[j] = info[j].parts.get("neck", 0.0)
        why[j] = "neck: between chest and head"

    lacking = [w for b, w in ESSENTIAL.items() if b not in mapping.values()]
    if lacking:
        raise RetargetError(
            f"{src}: not a complete humanoid skeleton ({motion.num_joints} joints): no "
            f"{', '.join(lacking)} found on the limb chains ({_recognised(sk)}); refusing "
            "rather than leaving limbs at rest.")

    # geometry: world up, the subject's left, mirrored names
    g, p = motion.world_transforms()
    notes: list[str] = []
    feet_mid = 0.5 * (p[:, fl] + p[:, fr])
    up_vec = _unit(p[:, head] - feet_mid).mean(axis=0)
    up = _snap_axis(up_vec)
    upv = np.asarray(AXES[up])
    conf_factor = 1.0
    inv = {t: j for j, t in mapping.items()}
    fwd, cue = _forward(sk, inv, g, p, upv)
    if fwd is None:
        notes.append("no forward cue (feet or knees): left/right taken from the names only")
        conf_factor *= 0.9
    else:
        left_geo = np.cross(upv, fwd)  # (F, 3), per-frame weights in its length
        weight = float(np.linalg.norm(left_geo, axis=1).mean())
        votes = []
        for a, b in (("LeftUpLeg", "RightUpLeg"), ("LeftArm", "RightArm"),
                     ("LeftHand", "RightHand")):
            d = _unit(p[:, inv[a]] - p[:, inv[b]])
            votes.append(float(np.mean(np.sum(d * left_geo, axis=1))) / weight)
        if all(v < -0.2 for v in votes):
            swap = {"Left": "Right", "Right": "Left", "LHip": "RHip", "RHip": "LHip"}
            for j, t in list(mapping.items()):
                for a, b in swap.items():
                    if t.startswith(a):
                        mapping[j] = b + t[len(a):]
                        why[j] += "; side swapped by geometry"
                        break
            notes.append("mirrored naming: joints named left are on the subject's right "
                         f"(up {up}, forward from the {cue}); sides swapped by geometry")
            conf_factor *= 0.8
        elif not all(v > 0.2 for v in votes):
            notes.append("left/right: names and geometry disagree or are unclear "
                         f"(votes thighs/arms/hands {', '.join(f'{v:+.2f}' for v in votes)}, "
                         f"forward from the {cue}); kept the names")
            conf_factor *= 0.7
    inv = {t: j for j, t in mapping.items()}
    if motion.parents[pelvis] >= 0:
        notes.append(f"the pelvis {motion.names[pelvis]!r} is not the file's root "
                     f"({motion.names[0]!r} above it is ignored)")

    # reference frame: straight knees and elbows, legs along -up
    def seg_dir(a: str, b: str) -> np.ndarray:
        return _unit(p[:, inv[b]] - p[:, inv[a]])
    bend = np.zeros(motion.num_frames)
    for s in ("Left", "Right"):
        th, sh = seg_dir(f"{s}UpLeg", f"{s}Leg"), seg_dir(f"{s}Leg", f"{s}Foot")
        ua, fa = seg_dir(f"{s}Arm", f"{s}ForeArm"), seg_dir(f"{s}ForeArm", f"{s}Hand")
        bend += np.arccos(np.clip(np.sum(th * sh, 1), -1, 1))
        bend += np.arccos(np.clip(np.sum(ua * fa, 1), -1, 1))
        bend += np.arccos(np.clip(-(th @ upv), -1, 1)) + np.arccos(np.clip(-(sh @ upv), -1, 1))
    ref_frame = int(np.argmin(np.round(bend, 9)))

    ess = []
    for bone in ESSENTIAL:
        e = evidence.get(inv[bone], 0.0)
        ess.append(1.0 if e >= 0.9 else 0.85 if e >= 0.5 else 0.6)
    confidence = round(float(np.mean(ess)) * conf_factor, 3)
    joints: dict[str, str | None] = {}
    reasons: dict[str, str] = {}
    for j, name in enumerate(motion.names):
        tj = mapping.get(j)
        joints[name] = tj
        if tj is not None:
            reasons[name] = why[j]
        else:
            reasons[name] = _unmapped_reason(sk, j, mapping)
    return RetargetMap(name="auto", target_rig="cmu_mb", units_m=None, joints=joints,
                       reference_directions={}, source=None, up=up,
                       reference_frame=ref_frame, confidence=confidence,
                       notes=tuple(notes), reasons=reasons)


def _recognised(sk: _Skeleton, limit: int = 12) -> str:
    """'recognised: left thigh 'femur_l', ...; not recognised: ...' for refusals."""
    side_w = {"L": "left ", "R": "right ", None: ""}
    rec, unrec = [], []
    for i in sk.info:
        if i.parts:
            part = max(i.parts, key=lambda k: i.parts[k])
            rec.append(f"{side_w[i.side]}{part} {i.name!r}")
        elif i.kind in ("body", "other"):
            unrec.append(repr(i.name))

    def cut(xs: list[str]) -> str:
        return ", ".join(xs[:limit]) + (f" and {len(xs) - limit} more" if len(xs) > limit
                                         else "")
    out = [f"recognised: {cut(rec)}" if rec else "no joint name recognised"]
    if unrec:
        out.append(f"not recognised: {cut(unrec)}")
    return "; ".join(out)


def _unmapped_reason(sk: _Skeleton, j: int, mapping: dict[int, str]) -> str:
    i = sk.info[j]
    par = int(sk.motion.parents[j])
    while par >= 0 and par not in mapping:
        par = int(sk.motion.parents[par])
    into = f"folds into {mapping[par]}" if par >= 0 else "above the pelvis: ignored"
    what = {"finger": "finger", "end": "end marker", "twist": "twist/roll helper"}.get(
        i.kind, "no counterpart")
    return f"{what}; {into}"


def map_to_yaml(rmap: RetargetMap, motion_source: str | None = None) -> str:
    """The map as an editable retarget-map YAML (explanations as comments); loading it
    with :meth:`RetargetMap.load` gives the same retargeting."""
    from vhgen.mocap.units import UNITS_M

    name = rmap.name if rmap.confidence is None or motion_source is None else \
        f"auto_{Path(motion_source).stem}"
    lines = [f"# Retarget map written by `vhgen corpus build --explain` for {motion_source}.",
             "# Edit the targets (a cmu_mb bone or null) and pass the file back with --map,",
             "# or as `retarget:` in a scene config."]
    if rmap.confidence is not None:
        lines.append(f"# automatic mapping, confidence {rmap.confidence}")
    lines += [f"# note: {n}" for n in rmap.notes]
    unit = "auto" if rmap.units_m is None else next(
        (k for k, v in UNITS_M.items() if v == rmap.units_m), repr(rmap.units_m))
    lines += [f"name: {name}", f"target_rig: {rmap.target_rig}", f"units: {unit}",
              "# the file's world up axis (+x -x +y -y +z -z)", f"up: '{rmap.up}'"]
    if rmap.reference_frame is not None:
        lines += ["# the frame whose posture is straightened into the reference pose; every",
                  "# mapped bone is straightened onto the rig's rest direction unless listed",
                  "# under reference_directions",
                  f"reference_frame: {rmap.reference_frame}"]
    lines.append("joints:")
    width = max(len(_yaml_key(k)) for k in rmap.joints) + 1
    for k, v in rmap.joints.items():
        val = "null" if v is None else v
        why = rmap.reasons.get(k, "")
        lines.append(f"  {_yaml_key(k) + ':':{width}} {val:14s}" + (f" # {why}" if why else ""))
    if rmap.reference_directions:
        lines.append("reference_directions:")
        for k, d in rmap.reference_directions.items():
            lines.append(f"  {k}: [{', '.join(f'{x:g}' for x in d)}]")
    return "\n".join(lines) + "\n"


def explain_table(motion: Motion, rmap: RetargetMap, rt: Retargeter) -> str:
    """Human-readable mapping of one file: a header (dialect or auto, confidence, up axis,
    reference frame, units, reference-pose error, notes) and one row per source joint."""
    how = "automatic" if rmap.confidence is not None else f"map {rmap.name!r}"
    conf = 1.0 if rmap.confidence is None else rmap.confidence
    ref = "rest (OFFSETs)" if rmap.reference_frame is None else f"frame {rmap.reference_frame}"
    out = [f"{motion.source}: {motion.num_joints} joints, {motion.num_frames} frames",
           f"mapping: {how}, confidence {conf:.2f}; up {rmap.up}; reference pose: {ref}; "
           f"units {rt.units_m:g} m{' (detected)' if rt.units_detected else ''}; "
           f"worst reference-pose bone error {rt.ref_error_deg:.1f} deg "
           f"({rt.ref_error_bone or '-'})"]
    out += [f"note: {n}" for n in rmap.notes]
    depth = [0] * motion.num_joints
    for j, par in enumerate(motion.parents):
        depth[j] = 0 if par < 0 else depth[par] + 1
    labels = [" " * min(depth[j], 8) + n for j, n in enumerate(motion.names)]
    w = max(len(lab) for lab in labels)
    out.append(f"{'joint':{w}}  {'target bone':14s}  why")
    for lab, n in zip(labels, motion.names, strict=True):
        t = rmap.joints.get(n)
        out.append(f"{lab:{w}}  {t or '-':14s}  {rmap.reasons.get(n, '')}")
    return "\n".join(out)


def report_table(entries: list[dict]) -> str:
    """The corpus report as a table: file, status, dialect or auto, confidence, poses kept,
    worst reference-pose bone error."""
    rows = [("file", "status", "mapping", "conf", "up", "frames", "kept", "ref err deg",
             "note / error")]
    for e in entries:
        note = e.get("error") or "; ".join(e.get("notes", []))
        conf, err = e.get("confidence"), e.get("ref_error_deg")
        rows.append((Path(e["file"]).name, e["status"], e.get("dialect") or "-",
                     "-" if conf is None else f"{conf:.2f}", e.get("up") or "-",
                     str(e.get("frames", 0)), str(e.get("poses_kept", 0)),
                     "-" if err is None else f"{err:.1f} ({e.get('ref_error_bone', '')})",
                     note[:90]))
    widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]) - 1)]
    return "\n".join("  ".join(f"{r[c]:{widths[c]}}" for c in range(len(widths))) + "  " + r[-1]
                     for r in rows)


def _yaml_key(k: str) -> str:
    plain = k.replace("_", "").replace(".", "").replace("-", "").isalnum()
    return k if plain and not k[0].isdigit() and k.lower() not in (
        "null", "true", "false", "yes", "no", "on", "off", "y", "n") else repr(k)
