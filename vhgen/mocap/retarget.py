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

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.body.skinning import posed_heads
from vhgen.errors import RetargetError
from vhgen.mocap.automap import auto_map
from vhgen.mocap.bvh import Motion
from vhgen.mocap.reference import bind_framed
from vhgen.mocap.retargetmap import (
    UP_ROTATIONS,
    Retargeter,
    RetargetMap,
    load_all_maps,
    mapping_report,
    missing_essentials,
    reference_error,
    up_rotation,
)
from vhgen.mocap.units import detect_units, skeleton_height
from vhgen.rotations import min_rotation

__all__ = ["UP_ROTATIONS", "RetargetMap", "Retargeter", "build_retargeter", "detect_dialect",
           "load_all_maps", "local_rotations", "mapping_report", "missing_essentials",
           "reference_error", "up_rotation", "world_rotations"]


def detect_dialect(motion: Motion, maps: list[RetargetMap]) -> RetargetMap:
    """The shipped map that knows every joint of ``motion`` and maps most of them, if it
    maps every essential part; otherwise an automatic map (:func:`vhgen.mocap.automap.
    auto_map`, name ``auto``, with a confidence and an explanation per joint).

    Raises RetargetError naming what is missing when the skeleton is not a complete
    humanoid.
    """
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
        owners = np.flatnonzero(source_index == j)
        src_world[j] = source_ref[owners[0]] if len(owners) else (
            src_world[par] if par >= 0 else np.eye(3))
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
