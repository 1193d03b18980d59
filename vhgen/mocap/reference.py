"""The straightened reference pose taken from a frame (maps with ``reference_frame``).

Used by automatic maps and by maps a user wrote from them. Unlike the shipped maps, which
read the rest pose off the OFFSETs, the reference is the posture of one frame in world
coordinates, so bone-local OFFSET conventions (Rokoko's bones along +X), rest poses other
than T/A and static roots do not matter:

* ``W`` turns the file's world up axis onto +Y (``up``).
* The source is *rebased* on frame F: ``C_j = W G_j(F)``, so ``G'_j(t) = W G_j(t) C_j^T`` is
  the identity at F and bone vectors at F are plain world vectors.
* The source root is turned by the rotation taking its body frame (up: pelvis to chest;
  left: right thigh to left thigh) onto the target's; every mapped bone is then turned,
  parents first, by the smallest rotation putting its source vector (to the source joint
  of the next mapped target bone down the chain, else its End Site or end-marker/finger
  children) along its canonical direction: ``reference_directions`` if listed, else the
  target's own rest direction of the same span. The target follows the same rule, so with
  no listed directions the target's reference pose is its rest pose.
* Each frame, ``A_b(t) = W G_J(t) (S_b C_J)^T T_b``: every straightened target bone points
  exactly where its source span points; roll about a bone's own axis comes from frame F.
"""

from __future__ import annotations

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.body.skinning import posed_heads
from vhgen.errors import RetargetError
from vhgen.mocap.automap import joint_tree
from vhgen.mocap.bvh import Motion
from vhgen.mocap.jointnames import classify
from vhgen.mocap.retargetmap import (
    Retargeter,
    RetargetMap,
    reference_error,
    up_rotation,
)
from vhgen.mocap.units import estimate_units
from vhgen.rotations import min_rotation

_UP_BONES = ("Spine1", "Neck", "Spine", "LowerBack", "Neck1", "Head")


def _continuation(rig: Rig, source_index: np.ndarray, k: int) -> int:
    """The first mapped target bone down the chain from bone k (head at k's tail, through
    unmapped bones); -1 if none."""
    while True:
        d = np.linalg.norm(rig.heads - rig.tails[k], axis=1)
        kids = [c for c in np.flatnonzero((rig.parents == k) & (d < 1e-6))]
        if not kids:
            return -1
        c = int(kids[0])
        if source_index[c] >= 0:
            return c
        k = c


def _tip(motion: Motion, j: int, gw: np.ndarray, pw: np.ndarray,
         children: list[list[int]]) -> np.ndarray:
    """Source vector of joint j with no mapped continuation: its End Site, else the mean
    of the points (joints and End Sites) of its end-marker and finger subtrees that are not
    at j itself (fingers often start at the wrist); never eyes or other side branches.
    0 if there is none."""
    if np.isfinite(motion.end_sites[j]).all() and np.linalg.norm(motion.end_sites[j]) > 1e-9:
        return gw[j] @ motion.end_sites[j]
    pts = []
    stack = [c for c in children[j] if classify(motion.names[c]).kind in ("end", "finger")]
    while stack:
        c = stack.pop()
        pts.append(pw[c])
        if np.isfinite(motion.end_sites[c]).all():
            pts.append(pw[c] + gw[c] @ motion.end_sites[c])
        stack.extend(children[c])
    vec = [q - pw[j] for q in pts if np.linalg.norm(q - pw[j]) > 1e-9]
    return np.mean(vec, axis=0) if vec else np.zeros(3)


def _body_frame(left: np.ndarray, up: np.ndarray) -> np.ndarray | None:
    """Columns (left, up, forward) orthonormal, up kept; None if degenerate."""
    nu = np.linalg.norm(up)
    if nu < 1e-12:
        return None
    u = up / nu
    lft = left - (left @ u) * u
    nl = np.linalg.norm(lft)
    if nl < 1e-9 * max(1.0, float(np.linalg.norm(left))):
        return None
    lft = lft / nl
    return np.stack([lft, u, np.cross(lft, u)], axis=1)


def bind_framed(motion: Motion, rig: Rig, rmap: RetargetMap, source_index: np.ndarray,
                root_name: str) -> Retargeter:
    """A :class:`Retargeter` for a map with ``reference_frame`` (see the module doc)."""
    f_ref = int(rmap.reference_frame or 0)
    if f_ref >= motion.num_frames:
        raise RetargetError(f"{motion.source}: reference_frame {f_ref} of map {rmap.name!r} "
                            f"is beyond the clip's {motion.num_frames} frames")
    w = up_rotation(rmap.up)
    g, p = motion.world_transforms()
    gw = w @ g[f_ref]
    pw = p[f_ref] @ w.T
    nb, nj = len(rig.names), motion.num_joints
    children, ancestors = joint_tree(motion.parents)

    src_vec = np.zeros((nb, 3))
    tgt_vec = rig.tails - rig.heads
    for k in range(nb):
        j = int(source_index[k])
        if j < 0:
            continue
        c = _continuation(rig, source_index, k)
        jc = int(source_index[c]) if c >= 0 else -1
        if jc >= 0 and j in ancestors[jc] and np.linalg.norm(pw[jc] - pw[j]) > 1e-9:
            src_vec[k] = pw[jc] - pw[j]
            tgt_vec[k] = rig.heads[c] - rig.heads[k]
        else:
            src_vec[k] = _tip(motion, j, gw, pw, children)

    root = rig.index(root_name)
    j_root = int(source_index[root])
    s_ref = np.empty((nb, 3, 3))
    t_ref = np.empty((nb, 3, 3))
    up_bone = next((rig.index(n) for n in _UP_BONES if n in rig.names
                    and source_index[rig.index(n)] >= 0), -1)
    s_root = np.eye(3)
    if up_bone >= 0 and {"LeftUpLeg", "RightUpLeg"} <= set(rig.names):
        lt, rt = rig.index("LeftUpLeg"), rig.index("RightUpLeg")
        if source_index[lt] >= 0 and source_index[rt] >= 0:
            bs = _body_frame(pw[source_index[lt]] - pw[source_index[rt]],
                             pw[source_index[up_bone]] - pw[j_root])
            bt = _body_frame(rig.heads[lt] - rig.heads[rt], rig.heads[up_bone] - rig.heads[root])
            if bs is not None and bt is not None:
                s_root = bt @ bs.T
    for k in range(nb):
        par = rig.parents[k]
        if par < 0:
            s_ref[k], t_ref[k] = s_root, np.eye(3)
            continue
        s_ref[k], t_ref[k] = s_ref[par], t_ref[par]
        if source_index[k] < 0:
            continue
        name = rig.names[k]
        canon = np.asarray(rmap.reference_directions.get(name, tgt_vec[k]), np.float64)
        r, ok = min_rotation(s_ref[par] @ src_vec[k], canon)
        if ok:
            s_ref[k] = r @ s_ref[par]
        r, ok = min_rotation(t_ref[par] @ tgt_vec[k], canon)
        if ok:
            t_ref[k] = r @ t_ref[par]

    # source reference pose positions below the pelvis (a static root above is ignored)
    sub = [j for j in range(nj) if j == j_root or j_root in ancestors[j]]
    r_world = np.empty((nj, 3, 3))
    pos = np.zeros((nj, 3))
    pts = []
    for j in sub:
        ks = np.flatnonzero(source_index == j)
        par = int(motion.parents[j])
        r_world[j] = s_ref[ks[0]] if len(ks) else r_world[par]
        if j != j_root:
            pos[j] = pos[par] + r_world[par] @ (pw[j] - pw[par])
        pts.append(pos[j])
        if np.isfinite(motion.end_sites[j]).all():
            pts.append(pos[j] + r_world[j] @ (gw[j] @ motion.end_sites[j]))
    pts_a = np.array(pts)
    src_drop = pos[j_root, 1] - pts_a[:, 1].min()
    tgt_heads = posed_heads(rig, t_ref, rig.heads[root])
    tgt_tails = tgt_heads + np.einsum("bij,bj->bi", t_ref, rig.tails - rig.heads)
    tgt_drop = tgt_heads[root, 1] - min(tgt_heads[:, 1].min(), tgt_tails[:, 1].min())
    if src_drop <= 1e-9 or tgt_drop <= 1e-9:
        raise RetargetError(f"{motion.source}: the pelvis is the lowest joint in the "
                            f"reference pose (frame {f_ref}); cannot scale the root "
                            "translation")
    units_m, detected = rmap.units_m, False
    if units_m is None:
        _, units_m = estimate_units(float(pts_a[:, 1].max() - pts_a[:, 1].min()))
        detected = True

    source_ref = s_ref.copy()
    for k in range(nb):
        if source_index[k] >= 0:
            source_ref[k] = s_ref[k] @ gw[source_index[k]]
    err, err_bone = reference_error(rig, source_index, s_ref @ src_vec[..., None],
                                    t_ref @ tgt_vec[..., None])
    return Retargeter(rig=rig, source_index=source_index, source_ref=source_ref,
                      target_ref=t_ref, scale=float(tgt_drop / src_drop), source_root=j_root,
                      dialect=rmap.name, units_m=float(units_m), units_detected=detected,
                      world_fix=w, ref_error_deg=err, ref_error_bone=err_bone)
