"""Skeleton fuzzing for the automatic mapping tests: rename joints into other conventions,
reorder children, insert and remove intermediate joints, rotate the rest pose, switch the
up axis, add a static root, mirror the names. Every operation keeps the world motion of the
remaining joints exactly (removal moves the removed rotation into position channels)."""

from __future__ import annotations

import numpy as np

from vhgen.mocap.bvh import Motion, forward_kinematics
from vhgen.mocap.retarget import up_rotation

_SPINE = ["Hips", "LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head"]
_LIMBS = ["HipJoint", "UpLeg", "Leg", "Foot", "ToeBase", "Shoulder", "Arm", "ForeArm", "Hand"]


def _table(spine: list[str], limbs: list[str]) -> dict[str, str]:
    """Target bone -> name; limb patterns use {s} (Left), {S} (L), {l} (l)."""
    d = dict(zip(_SPINE, spine, strict=True))
    for side in ("Left", "Right"):
        for bone, pat in zip(_LIMBS, limbs, strict=True):
            target = (side[0] + bone) if bone == "HipJoint" else side + bone
            d[target] = pat.replace("{s}", side).replace("{S}", side[0]).replace(
                "{l}", side[0].lower())
    return d


CONVENTIONS: dict[str, dict[str, str]] = {
    "mixamo": _table(["mixamorig:Hips", "mixamorig:Spine", "mixamorig:Spine1",
                      "mixamorig:Spine2", "mixamorig:Neck", "mixamorig:Neck1", "mixamorig:Head"],
                     ["mixamorig:{s}HipJoint", "mixamorig:{s}UpLeg", "mixamorig:{s}Leg",
                      "mixamorig:{s}Foot", "mixamorig:{s}ToeBase", "mixamorig:{s}Shoulder",
                      "mixamorig:{s}Arm", "mixamorig:{s}ForeArm", "mixamorig:{s}Hand"]),
    "biped": _table(["Bip01 Pelvis", "Bip01 Spine", "Bip01 Spine1", "Bip01 Spine2",
                     "Bip01 Neck", "Bip01 Neck1", "Bip01 Head"],
                    ["Bip01 {S} Hip", "Bip01 {S} Thigh", "Bip01 {S} Calf", "Bip01 {S} Foot",
                     "Bip01 {S} Toe0", "Bip01 {S} Clavicle", "Bip01 {S} UpperArm",
                     "Bip01 {S} Forearm", "Bip01 {S} Hand"]),
    "xsens": _table(["Pelvis", "L5", "L3", "T8", "Neck", "Neck2", "Head"],
                    ["{s}HipJoint", "{s}UpperLeg", "{s}LowerLeg", "{s}Foot", "{s}Toe",
                     "{s}Shoulder", "{s}UpperArm", "{s}ForeArm", "{s}Hand"]),
    "bandai": _table(["Hips", "Spine", "Spine_1", "Chest", "Neck", "Neck_1", "Head"],
                     ["HipJoint_{S}", "UpperLeg_{S}", "LowerLeg_{S}", "Foot_{S}", "Toes_{S}",
                      "Shoulder_{S}", "UpperArm_{S}", "LowerArm_{S}", "Hand_{S}"]),
    "kinect": _table(["HipCenter", "SpineMid", "Spine", "Chest", "Neck", "Neck2", "Head"],
                     ["HipJoint{s}", "Hip{s}", "Knee{s}", "Ankle{s}", "Foot{s}",
                      "Collar{s}", "Shoulder{s}", "Elbow{s}", "Wrist{s}"]),
    "daz": _table(["hip", "abdomen", "abdomen2", "chest", "neck", "neck2", "head"],
                  ["{l}Buttock", "{l}Thigh", "{l}Shin", "{l}Foot", "{l}Toe", "{l}Collar",
                   "{l}Shldr", "{l}ForeArm", "{l}Hand"]),
    "sfu": _table(["Hips", "Abdomen", "Spine", "Chest", "Neck", "Neck1", "Head"],
                  ["{s}HipJoint", "{s}Hip", "{s}Knee", "{s}Ankle", "{s}Toe", "{s}Collar",
                   "{s}Shoulder", "{s}Elbow", "{s}Wrist"]),
    "rigify": _table(["DEF-hips", "DEF-spine", "DEF-spine.001", "DEF-chest", "DEF-neck",
                      "DEF-neck.001", "DEF-head"],
                     ["DEF-hipjoint.{S}", "DEF-thigh.{S}", "DEF-shin.{S}", "DEF-foot.{S}",
                      "DEF-toe.{S}", "DEF-shoulder.{S}", "DEF-upper_arm.{S}",
                      "DEF-forearm.{S}", "DEF-hand.{S}"]),
    "motive": _table(["Hip", "Ab", "Spine", "Chest", "Neck", "Neck2", "Head"],
                     ["{S}HipJoint", "{S}Thigh", "{S}Shin", "{S}Foot", "{S}Toe", "{S}Shoulder",
                      "{S}UArm", "{S}FArm", "{S}Hand"]),
    "unreal": _table(["pelvis", "spine_01", "spine_02", "spine_03", "neck_01", "neck_02",
                      "head"],
                     ["hipjoint_{l}", "thigh_{l}", "calf_{l}", "foot_{l}", "ball_{l}",
                      "clavicle_{l}", "upperarm_{l}", "lowerarm_{l}", "hand_{l}"]),
    "asf": _table(["hips", "lowerback", "upperback", "thorax", "lowerneck", "upperneck", "head"],
                  ["{l}hipjoint", "{l}femur", "{l}tibia", "{l}foot", "{l}toes", "{l}clavicle",
                   "{l}humerus", "{l}radius", "{l}wrist"]),
}


def make(m: Motion, names, parents, offsets, ends, rotations, translations) -> Motion:
    return Motion(names=list(names), parents=np.asarray(parents, np.int64),
                  offsets=np.asarray(offsets, np.float64), end_sites=np.asarray(ends),
                  channels=[("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation",
                             "Xrotation")] * len(names),
                  frame_time=m.frame_time, rotations=np.asarray(rotations),
                  translations=np.asarray(translations), source=m.source)


def crop(m: Motion, n: int) -> Motion:
    return make(m, m.names, m.parents, m.offsets, m.end_sites, m.rotations[:n],
                m.translations[:n])


def rename(m: Motion, joints: dict[str, str | None], conv: str) -> Motion:
    """Mapped joints take the convention's name of their target bone; others keep theirs."""
    table = CONVENTIONS[conv]
    names = []
    for n in m.names:
        t = joints.get(n)
        new = table.get(t, n) if t else n
        names.append(new if new not in names else f"{new}_{len(names)}")
    return make(m, names, m.parents, m.offsets, m.end_sites, m.rotations, m.translations)


def mirror_names(m: Motion) -> Motion:
    swap = {"Left": "Right", "Right": "Left"}
    names = []
    for n in m.names:
        for a, b in swap.items():
            if a in n:
                n = n.replace(a, "\0").replace(b, a).replace("\0", b)
                break
        names.append(n)
    return make(m, names, m.parents, m.offsets, m.end_sites, m.rotations, m.translations)


def reorder(m: Motion, rng: np.random.Generator) -> Motion:
    """Depth-first order with every joint's children shuffled."""
    kids: list[list[int]] = [[] for _ in m.names]
    for j, p in enumerate(m.parents):
        if p >= 0:
            kids[p].append(j)
    order: list[int] = []
    stack = [int(np.flatnonzero(m.parents < 0)[0])]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(rng.permutation(kids[j]).tolist())
    new_of = {old: k for k, old in enumerate(order)}
    parents = [new_of[int(m.parents[j])] if m.parents[j] >= 0 else -1 for j in order]
    return make(m, [m.names[j] for j in order], parents, m.offsets[order], m.end_sites[order],
                m.rotations[:, order], m.translations[:, order])


def insert(m: Motion, child: int, name: str, frac: float) -> Motion:
    """A joint without rotation between ``child`` and its parent, ``frac`` along the bone."""
    par = int(m.parents[child])
    n = m.num_joints
    order = list(range(child)) + [n] + list(range(child, n))  # new joint before child
    parents = np.append(m.parents, par)
    parents[child] = n
    offsets = np.vstack([m.offsets, frac * m.offsets[child]])
    offsets[child] = (1 - frac) * m.offsets[child]
    trans = np.concatenate([m.translations, frac * m.translations[:, child:child + 1]], 1)
    trans[:, child] *= 1 - frac
    rots = np.concatenate([m.rotations, np.broadcast_to(np.eye(3), (m.num_frames, 1, 3, 3))], 1)
    ends = np.vstack([m.end_sites, np.full(3, np.nan)])
    names = m.names + [name]
    new_of = {old: k for k, old in enumerate(order)}
    par_new = [new_of[int(parents[j])] if parents[j] >= 0 else -1 for j in order]
    return make(m, [names[j] for j in order], par_new, offsets[order], ends[order],
                rots[:, order], trans[:, order])


def remove(m: Motion, r: int) -> Motion:
    """Drop joint ``r``; its rotation moves into its children (rotation and per-frame
    position channels), so every other joint keeps its world motion exactly."""
    par = int(m.parents[r])
    rots, trans = m.rotations.copy(), m.translations.copy()
    offsets = m.offsets.copy()
    for c in np.flatnonzero(m.parents == r):
        rots[:, c] = m.rotations[:, r] @ m.rotations[:, c]
        trans[:, c] = m.translations[:, r] + np.einsum("fab,fb->fa", m.rotations[:, r],
                                                       m.translations[:, c])
        offsets[c] = trans[0, c]
    keep = [j for j in range(m.num_joints) if j != r]
    new_of = {old: k for k, old in enumerate(keep)}
    parents = []
    for j in keep:
        p = int(m.parents[j])
        p = par if p == r else p
        parents.append(new_of[p] if p >= 0 else -1)
    return make(m, [m.names[j] for j in keep], parents, offsets[keep], m.end_sites[keep],
                rots[:, keep], trans[:, keep])


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def rotate_rest(m: Motion, rng: np.random.Generator) -> Motion:
    """New joint frames ``G'_j = G_j Q_j^T`` (random Q_j): OFFSETs, End Sites and local
    rotations change, the world motion does not (bone-local rests like Rokoko's)."""
    q = np.stack([random_rotation(rng) for _ in m.names])
    rots = np.empty_like(m.rotations)
    trans = np.empty_like(m.translations)
    offsets = np.empty_like(m.offsets)
    for j, p in enumerate(m.parents):
        qp = q[p] if p >= 0 else np.eye(3)
        rots[:, j] = qp @ m.rotations[:, j] @ q[j].T
        trans[:, j] = m.translations[:, j] @ qp.T
        offsets[j] = qp @ m.offsets[j]
    ends = np.einsum("jab,jb->ja", q, m.end_sites)
    return make(m, m.names, m.parents, offsets, ends, rots, trans)


def switch_up(m: Motion, up: str, base_up: str = "+y") -> Motion:
    """The same motion (whose world up axis is ``base_up``) in a world whose up axis is
    ``up``: a proper rotation taking base_up to up (and the heading along)."""
    u = up_rotation(up).T @ up_rotation(base_up)
    rots, trans = m.rotations.copy(), m.translations.copy()
    for j in np.flatnonzero(m.parents < 0):
        rots[:, j] = u @ rots[:, j]
        trans[:, j] = trans[:, j] @ u.T
    return make(m, m.names, m.parents, m.offsets, m.end_sites, rots, trans)


def static_root(m: Motion, rng: np.random.Generator, name: str = "Reference") -> Motion:
    """A new root joint above the old one with a constant rotation and offset."""
    q = random_rotation(rng)
    t0 = rng.normal(size=3) * 10
    n = m.num_joints
    old_root = int(np.flatnonzero(m.parents < 0)[0])
    rots = np.concatenate([np.broadcast_to(q, (m.num_frames, 1, 3, 3)), m.rotations], 1)
    trans = np.concatenate([np.broadcast_to(t0, (m.num_frames, 1, 3)), m.translations], 1)
    # the old root, now a child: x_world = q (R x) + t0 + q t  -> compensate
    rots[:, old_root + 1] = q.T @ m.rotations[:, old_root]
    trans[:, old_root + 1] = (m.translations[:, old_root] - t0) @ q
    parents = np.concatenate([[-1], np.where(m.parents >= 0, m.parents + 1, 0)])
    offsets = np.vstack([t0, m.offsets])
    ends = np.vstack([np.full(3, np.nan), m.end_sites])
    assert n + 1 == len(parents)
    return make(m, [name] + m.names, parents, offsets, ends, rots, trans)


def same_world(a: Motion, b: Motion, pairs: list[tuple[int, int]]) -> float:
    """Largest position difference of joint pairs (a index, b index) over all frames."""
    pa = forward_kinematics(a.parents, a.rotations, a.translations)[1]
    pb = forward_kinematics(b.parents, b.rotations, b.translations)[1]
    return float(max(np.abs(pa[:, i] - pb[:, k]).max() for i, k in pairs))


def drop_subtree(m: Motion, top: int) -> Motion:
    """Remove joint ``top`` and everything below it."""
    gone = {top}
    for j, p in enumerate(m.parents):
        if p in gone:
            gone.add(j)
    keep = [j for j in range(m.num_joints) if j not in gone]
    new_of = {old: k for k, old in enumerate(keep)}
    parents = [new_of[int(m.parents[j])] if m.parents[j] >= 0 else -1 for j in keep]
    return make(m, [m.names[j] for j in keep], parents, m.offsets[keep], m.end_sites[keep],
                m.rotations[:, keep], m.translations[:, keep])


def to_bvh_text(m: Motion, rng: np.random.Generator) -> str:
    """BVH text of ``m`` with position channels on every joint, a random Euler order per
    joint, some angles shifted by +-360 deg, leading spaces on data rows, CRLF line ends and
    a blank line after MOTION (traps seen in real exports)."""
    from vhgen.rotations import matrix_to_euler

    orders = [str(rng.choice(["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])) for _ in m.names]
    kids: list[list[int]] = [[] for _ in m.names]
    for j, p in enumerate(m.parents):
        if p >= 0:
            kids[p].append(j)
    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        kw = "ROOT" if m.parents[j] < 0 else "JOINT"
        lines.append(f"{pad}{kw} {m.names[j]}")
        lines.append(pad + "{")
        lines.append(f"{pad}  OFFSET {' '.join(repr(float(x)) for x in m.offsets[j])}")
        rot = " ".join(f"{a}rotation" for a in orders[j])
        lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition {rot}")
        for c in kids[j]:
            emit(c, depth + 1)
        if np.isfinite(m.end_sites[j]).all():
            lines.extend([f"{pad}  End Site", pad + "  {",
                          f"{pad}    OFFSET {' '.join(repr(float(x)) for x in m.end_sites[j])}",
                          pad + "  }"])
        lines.append(pad + "}")

    emit(int(np.flatnonzero(m.parents < 0)[0]), 0)
    order_idx = []

    def walk(j: int) -> None:
        order_idx.append(j)
        for c in kids[j]:
            walk(c)
    walk(int(np.flatnonzero(m.parents < 0)[0]))
    cols = []
    for j in order_idx:
        ang = np.rad2deg(matrix_to_euler(m.rotations[:, j], orders[j]))
        ang += 360.0 * rng.integers(-1, 2, size=ang.shape)
        cols += [m.translations[:, j], ang]
    data = np.concatenate(cols, axis=1)
    lines += ["MOTION", "", f"Frames: {m.num_frames}", f"Frame Time: {m.frame_time!r}"]
    lines += [" " + " ".join(repr(float(x)) for x in row) for row in data]
    return "\r\n".join(lines) + "\r\n"
