"""Retargeting BVH motion onto the MakeHuman rig.

Method (after Monzani et al.'s intermediate skeleton, reduced to rotations):

1. Both skeletons are put into one *reference pose*: bones listed in the map's
   ``reference_directions`` are turned, root first, by the smallest rotation that points
   them along a canonical world direction; other bones keep their rest orientation
   relative to their parent. This gives world rotations ``S_b`` (source, relative to the
   BVH zero pose) and ``T_b`` (target, relative to the mesh's rest pose).
2. Each frame, the target bone's skinning rotation (world, relative to rest) is
   ``A_b(t) = G_J(t) @ S_b^T @ T_b`` where ``G_J(t)`` is the world rotation of the source
   joint J mapped to b. A source frame equal to the reference pose gives ``A_b = T_b``; in
   every frame, a straightened bone points exactly where its source bone points.
3. Target bones with no source joint carry their parent's rotation. Source joints mapped
   to null contribute through the world rotations of their mapped descendants, so their
   rotation is never lost.
4. The root position is the source root position scaled by the ratio of the target's to
   the source's root height above its lowest joint (End Sites included) in the reference
   pose, so feet stay on the floor whatever the two skeletons' proportions.

Poses on the target rig are (F, B, 3, 3) world skinning rotations plus (F, 3) root head
positions, float64 metres; :func:`local_rotations` gives the parent-relative form.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.body.skinning import posed_heads
from vhgen.errors import ConfigError, RetargetError
from vhgen.mocap.bvh import Motion
from vhgen.mocap.jointnames import ESSENTIAL
from vhgen.mocap.units import detect_units, parse_units, skeleton_height
from vhgen.rotations import min_rotation
from vhgen.yamlio import check_keys, configs_dir, find_config, load_yaml


@dataclass(frozen=True)
class RetargetMap:
    """A source dialect's joint map onto a target rig, as declared in ``configs/retarget``."""

    name: str
    target_rig: str
    units_m: float | None  # metres per file unit; None = detect from the skeleton size
    joints: dict[str, str | None]
    reference_directions: dict[str, tuple[float, float, float]]
    source: str | None = None
    # The file's world up axis (+y for the shipped maps); see :func:`up_rotation`.
    up: str = "+y"
    # None: the zero-rotation rest pose is the reference and only the bones listed in
    # reference_directions are straightened (the shipped maps). A frame number: that
    # frame's posture (world positions, so bone-local OFFSETs do not matter) is the
    # reference, every mapped bone is straightened (onto reference_directions, else onto
    # the target's rest direction) and the root is turned by its body frame (up, left).
    reference_frame: int | None = None
    confidence: float | None = None  # automatic maps: in [0, 1]
    notes: tuple[str, ...] = ()
    reasons: dict[str, str] = field(default_factory=dict)  # per source joint, why

    @classmethod
    def load(cls, name_or_path: str | Path) -> RetargetMap:
        path = find_config("retarget", name_or_path)
        d = load_yaml(path)
        check_keys(d, {"name", "target_rig", "units", "joints", "reference_directions",
                       "description", "up", "reference_frame"},
                   {"name", "target_rig", "joints"}, path, "")
        units = parse_units(d.get("units", "auto"), path, "units")
        joints = d["joints"]
        if not isinstance(joints, dict) or not joints:
            raise ConfigError(path, "joints", "must be a non-empty mapping source -> target")
        for k, v in joints.items():
            if v is not None and not isinstance(v, str):
                raise ConfigError(path, f"joints.{k}", f"target must be a bone name or null, "
                                                       f"got {v!r}")
        refs = {}
        for k, v in (d.get("reference_directions") or {}).items():
            arr = np.asarray(v, dtype=np.float64) if isinstance(v, list) else None
            if arr is None or arr.shape != (3,) or not np.isfinite(arr).all() or \
                    np.linalg.norm(arr) == 0:
                raise ConfigError(path, f"reference_directions.{k}",
                                  f"must be a non-zero [x, y, z], got {v!r}")
            refs[k] = (float(arr[0]), float(arr[1]), float(arr[2]))
        up = str(d.get("up", "+y"))
        if up not in UP_ROTATIONS:
            raise ConfigError(path, "up", f"must be one of {', '.join(UP_ROTATIONS)}, "
                                          f"got {d.get('up')!r}")
        ref = d.get("reference_frame")
        if ref is not None and (isinstance(ref, bool) or not isinstance(ref, int) or ref < 0):
            raise ConfigError(path, "reference_frame",
                              f"must be a frame number >= 0 (or absent), got {ref!r}")
        return cls(name=str(d["name"]), target_rig=str(d["target_rig"]), units_m=units,
                   joints=dict(joints), reference_directions=refs, source=str(path), up=up,
                   reference_frame=ref)

    def check_target(self, rig: Rig) -> None:
        """Every bone the map names must exist in the rig."""
        named = {v for v in self.joints.values() if v} | set(self.reference_directions)
        missing = sorted(named - set(rig.names))
        if missing:
            raise ConfigError(self.source, "joints",
                              f"target bones not in rig {self.target_rig}: {', '.join(missing)}")


def load_all_maps(folder: str | Path | None = None) -> list[RetargetMap]:
    """Every map in ``configs/retarget`` (or ``folder``), sorted by name."""
    folder = Path(folder) if folder is not None else configs_dir() / "retarget"
    return [RetargetMap.load(p) for p in sorted(folder.glob("*.yaml"))]


def missing_essentials(rmap: RetargetMap, motion: Motion) -> list[str]:
    """Essential target parts (pelvis, head, legs, arms) that no joint of ``motion`` maps
    to under ``rmap``, in words."""
    mapped = {rmap.joints.get(n) for n in motion.names}
    return [w for b, w in ESSENTIAL.items() if b not in mapped]


def detect_dialect(motion: Motion, maps: list[RetargetMap]) -> RetargetMap:
    """The shipped map that knows every joint of ``motion`` and maps most of them, if it
    maps every essential part; otherwise an automatic map (:func:`vhgen.mocap.automap.
    auto_map`, name ``auto``, with a confidence and an explanation per joint).

    Raises RetargetError naming what is missing when the skeleton is not a complete
    humanoid.
    """
    from vhgen.mocap.automap import auto_map

    best, best_key, best_unknown = None, None, None
    for m in maps:
        unknown = [n for n in motion.names if n not in m.joints]
        mapped = sum(1 for n in motion.names if m.joints.get(n))
        key = (len(unknown), -mapped)
        if best_key is None or key < best_key:
            best, best_key, best_unknown = m, key, unknown
    if best is not None and not best_unknown and not missing_essentials(best, motion):
        return best
    return auto_map(motion)


UP_ROTATIONS = {
    "+y": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "-y": ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0)),  # 180 deg about X
    "+z": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)),  # -90 deg about X
    "-z": ((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),  # +90 deg about X
    "+x": ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),  # +90 deg about Z
    "-x": ((0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),  # -90 deg about Z
}


def up_rotation(up: str) -> np.ndarray:
    """(3, 3) float64 rotation taking the file's up axis (``+y``, ``-z``...) to +Y; a proper
    rotation, so the skeleton's handedness is kept."""
    return np.array(UP_ROTATIONS[up], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Retargeter:
    """A map bound to one source skeleton and one fitted target rig."""

    rig: Rig
    source_index: np.ndarray  # (B,) source joint per target bone, -1 = none
    source_ref: np.ndarray  # (B, 3, 3) S_b
    target_ref: np.ndarray  # (B, 3, 3) T_b
    scale: float  # metres per source unit, corrected for the skeletons' proportions
    source_root: int
    dialect: str
    units_m: float  # metres per file unit (declared by the map or detected)
    units_detected: bool
    world_fix: np.ndarray = field(default_factory=lambda: np.eye(3))  # file up -> +Y
    # worst angle between a mapped target bone and its source bone in the straightened
    # reference pose (degrees), and that bone
    ref_error_deg: float = 0.0
    ref_error_bone: str = ""

    def apply(self, motion: Motion, frames: np.ndarray | None = None) -> tuple[np.ndarray,
                                                                              np.ndarray]:
        """Target poses for ``frames`` (all by default).

        Returns rotations (F, B, 3, 3) world skinning rotations and root (F, 3) position of
        the root bone's head, float64 metres, in the mesh frame.
        """
        g, p = motion.world_transforms()
        if frames is not None:
            g, p = g[frames], p[frames]
        if not np.array_equal(self.world_fix, np.eye(3)):
            g = self.world_fix @ g
            p = p @ self.world_fix.T
        f = g.shape[0]
        b = len(self.rig.names)
        out = np.empty((f, b, 3, 3), dtype=np.float64)
        corr = np.swapaxes(self.source_ref, -1, -2) @ self.target_ref  # S^T T
        for k in range(b):
            j = self.source_index[k]
            if j >= 0:
                out[:, k] = g[:, j] @ corr[k]
            else:
                par = self.rig.parents[k]
                # no source: keep the rest orientation relative to the parent
                out[:, k] = out[:, par] if par >= 0 else np.eye(3)
        root = p[:, self.source_root] * self.scale
        return out, root


def _reference_rotations(parents: np.ndarray, directions: np.ndarray,
                         canon: dict[int, np.ndarray]) -> np.ndarray:
    """World rotations putting bone k along canon[k] (parents first), others inherit."""
    n = len(parents)
    out = np.empty((n, 3, 3))
    for k in range(n):
        par = parents[k]
        base = out[par] if par >= 0 else np.eye(3)
        if k in canon:
            r, ok = min_rotation(base @ directions[k], canon[k])
            out[k] = (r if ok else np.eye(3)) @ base
        else:
            out[k] = base
    return out


def build_retargeter(motion: Motion, rig: Rig, rmap: RetargetMap) -> Retargeter:
    """Bind ``rmap`` to a parsed source skeleton and a fitted rig; validate the mapping."""
    rmap.check_target(rig)
    unknown = [n for n in motion.names if n not in rmap.joints]
    if unknown:
        raise RetargetError(
            f"{motion.source}: joints not in retarget map {rmap.name!r}: {', '.join(unknown)}. "
            f"Add them to {rmap.source} (map to a target bone, or to null).")
    src_of: dict[str, int] = {}
    for j, name in enumerate(motion.names):
        tgt = rmap.joints[name]
        if tgt is None:
            continue
        if tgt in src_of:
            raise RetargetError(f"{motion.source}: joints {motion.names[src_of[tgt]]!r} and "
                                f"{name!r} both map to target bone {tgt!r}")
        src_of[tgt] = j
    root_name = rig.names[int(np.flatnonzero(rig.parents < 0)[0])]
    if root_name not in src_of:
        raise RetargetError(f"{motion.source}: no source joint maps to the root bone "
                            f"{root_name!r}")
    b = len(rig.names)
    source_index = np.array([src_of.get(n, -1) for n in rig.names], dtype=np.int64)
    if rmap.reference_frame is not None:
        from vhgen.mocap.reference import bind_framed

        return bind_framed(motion, rig, rmap, source_index, root_name)

    # rest directions. Target: head -> tail. Source: joint -> the source joint of the target
    # bone whose head sits at this bone's tail (a descendant), else the End Site.
    rest = motion.rest_positions()
    tgt_dir = rig.tails - rig.heads
    src_dir = np.zeros((b, 3))
    ancestors = _ancestor_sets(motion.parents)
    for k in range(b):
        j = source_index[k]
        if j < 0:
            continue
        dist = np.linalg.norm(rig.heads - rig.tails[k], axis=1)
        for c in np.flatnonzero(dist < 1e-6):
            jc = source_index[c]
            if jc >= 0 and j in ancestors[jc] and np.linalg.norm(rest[jc] - rest[j]) > 1e-9:
                src_dir[k] = rest[jc] - rest[j]
                break
        else:
            if np.isfinite(motion.end_sites[j]).all():
                src_dir[k] = motion.end_sites[j]
    canon = {rig.index(n): np.asarray(v, float) for n, v in rmap.reference_directions.items()}
    # a source bone's direction is expressed in its joint's frame; at rest that is world
    source_ref = _reference_rotations(rig.parents, src_dir, canon)
    target_ref = _reference_rotations(rig.parents, tgt_dir, canon)

    # root height above the lowest joint in the reference pose, both skeletons
    src_world = np.empty((motion.num_joints, 3, 3))
    for j, par in enumerate(motion.parents):
        ks = np.flatnonzero(source_index == j)
        src_world[j] = source_ref[ks[0]] if len(ks) else (src_world[par] if par >= 0 else
                                                           np.eye(3))
    src_pos = np.empty((motion.num_joints, 3))
    for j, par in enumerate(motion.parents):
        src_pos[j] = 0.0 if par < 0 else src_pos[par] + src_world[par] @ motion.offsets[j]
    ends = np.isfinite(motion.end_sites).all(axis=1)
    src_low = min(src_pos[:, 1].min(), (src_pos[ends] + np.einsum(
        "jab,jb->ja", src_world[ends], motion.end_sites[ends]))[:, 1].min(initial=np.inf))
    src_drop = src_pos[motion.parents < 0][0, 1] - src_low
    tgt_heads = posed_heads(rig, target_ref, rig.heads[rig.parents < 0][0])
    tgt_tails = tgt_heads + np.einsum("bij,bj->bi", target_ref, tgt_dir)
    tgt_drop = tgt_heads[rig.parents < 0][0, 1] - min(tgt_heads[:, 1].min(), tgt_tails[:, 1].min())
    if src_drop <= 1e-9 or tgt_drop <= 1e-9:
        raise RetargetError(f"{motion.source}: the root is the lowest joint in the reference "
                            "pose; cannot scale the root translation")
    scale = tgt_drop / src_drop
    units_m, detected = rmap.units_m, False
    if units_m is None:
        ends_world = rest + np.where(np.isfinite(motion.end_sites), motion.end_sites, np.nan)
        _, units_m = detect_units(skeleton_height(rest, ends_world))
        detected = True
    err, err_bone = reference_error(rig, source_index, source_ref @ src_dir[..., None],
                                    target_ref @ tgt_dir[..., None])
    return Retargeter(rig=rig, source_index=source_index, source_ref=source_ref,
                      target_ref=target_ref, scale=float(scale),
                      source_root=int(source_index[rig.index(root_name)]), dialect=rmap.name,
                      units_m=float(units_m), units_detected=detected, ref_error_deg=err,
                      ref_error_bone=err_bone)


def mapping_report(rmap: RetargetMap, rt: Retargeter) -> dict:
    """Report fields of one file's mapping: how it was chosen, confidence (1.0 for a map
    that names every joint: shipped or given), the straightened reference pose's worst
    bone-direction error and notes (conflicts such as mirrored names)."""
    how = "auto" if rmap.confidence is not None else "map"
    return {"mapping": how, "confidence": 1.0 if rmap.confidence is None else rmap.confidence,
            "up": rmap.up, "reference_frame": rmap.reference_frame,
            "ref_error_deg": round(rt.ref_error_deg, 3), "ref_error_bone": rt.ref_error_bone,
            "notes": list(rmap.notes)}


def reference_error(rig: Rig, source_index: np.ndarray, src: np.ndarray,
                    tgt: np.ndarray) -> tuple[float, str]:
    """Worst angle (degrees) between mapped source and target bone directions (B, 3[, 1])
    in the reference pose, over bones whose source direction is known; and that bone."""
    src = src.reshape(len(rig.names), 3)
    tgt = tgt.reshape(len(rig.names), 3)
    ns, nt = np.linalg.norm(src, axis=1), np.linalg.norm(tgt, axis=1)
    ok = (source_index >= 0) & (ns > 1e-9) & (nt > 1e-12)
    if not ok.any():
        return 0.0, ""
    cos = np.sum(src[ok] * tgt[ok], axis=1) / (ns[ok] * nt[ok])
    ang = np.rad2deg(np.arccos(np.clip(cos, -1.0, 1.0)))
    k = int(np.argmax(ang))
    return float(ang[k]), rig.names[int(np.flatnonzero(ok)[k])]


def _ancestor_sets(parents: np.ndarray) -> list[set[int]]:
    out: list[set[int]] = []
    for p in parents:
        out.append(set() if p < 0 else out[p] | {int(p)})
    return out


def local_rotations(rig: Rig, world: np.ndarray) -> np.ndarray:
    """Parent-relative rotations A_parent^T A_b (world-aligned, root keeps its world value)."""
    world = np.asarray(world, np.float64)
    out = world.copy()
    for k, par in enumerate(rig.parents):
        if par >= 0:
            out[..., k, :, :] = np.swapaxes(world[..., par, :, :], -1, -2) @ world[..., k, :, :]
    return out


def world_rotations(rig: Rig, local: np.ndarray) -> np.ndarray:
    """Inverse of :func:`local_rotations`."""
    local = np.asarray(local, np.float64)
    out = local.copy()
    for k, par in enumerate(rig.parents):
        if par >= 0:
            out[..., k, :, :] = out[..., par, :, :] @ local[..., k, :, :]
    return out
