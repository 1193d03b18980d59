"""Poses bent forward at the hips: people picking something up, tying a shoe, looking
under a table. Few motion-capture corpora hold them (the shared CMU corpus's training
clips: 0.2-0.3% of the people whose highest joint is under 1 m), and a person detector
trained without them finds such people half as often as standing ones (issue 27).

A bend to theta degrees turns the pelvis and what rides on it (the spine, neck, head and
shoulders) about the level axis through the root across the pelvis until the trunk (hips
to neck) leans theta from upright, so that the head moves the way the pelvis faces; a
pose that leans that far already, or is not upright (a trunk leaning over 60 degrees
either way: a handstand, a cartwheel; a pelvis on its side), is left as it is. The legs
and the arms keep their world rotations: the legs stand as they stood and the arms hang
as they hung (a person who bends over lets the arms fall, not swing up with the chest).
The root then moves by what the bend moved the ankles, so the feet stay where they were
and the clip's grounding holds.

Pure NumPy on the world-rotation poses of :mod:`vhgen.pipeline.poses` (float64).
"""

from __future__ import annotations

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.body.skinning import posed_heads
from vhgen.errors import VhgenError
from vhgen.rotations import axis_angle_matrix

#: bones whose subtrees keep their world rotations: the legs and the arms
KEEP = ("LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm")
#: the ankles, which the bend must not move
FEET = ("LeftFoot", "RightFoot")
#: a trunk leaning further than this (degrees, either way) is not bent
UPRIGHT_DEG = 60.0
#: the random stream of the bends (a job's other streams use other words)
BEND_STREAM = 0xBE4D


def kept_bones(rig: Rig) -> np.ndarray:
    """(B,) bool: the bones of the subtrees of :data:`KEEP` (which the bend leaves)."""
    missing = [n for n in (*KEEP, *FEET) if n not in rig.names]
    if missing:
        raise VhgenError(f"poses.bend needs the MakeHuman CMU MB rig's bones; this rig lacks "
                         f"{', '.join(missing)}")
    keep = np.zeros(len(rig.names), bool)
    for b, parent in enumerate(rig.parents):  # parents before children
        keep[b] = rig.names[b] in KEEP or (parent >= 0 and keep[parent])
    return keep


def bend_forward(rig: Rig, rotations: np.ndarray, roots: np.ndarray,
                 degrees: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses (N, B, 3, 3) world rotations and (N, 3) roots bent forward until the trunk
    (hips to neck) leans ``degrees`` (N,) from upright (0: unchanged; a pose leaning that
    far already stays); returns the new rotations and roots (float64) and the turn each
    pose got, degrees (see the module docstring)."""
    rot = np.array(rotations, np.float64)
    root = np.array(roots, np.float64)
    deg = np.asarray(degrees, np.float64)
    keep = kept_bones(rig)
    heads = posed_heads(rig, rot, root)
    li, ri = rig.index("LeftUpLeg"), rig.index("RightUpLeg")
    # the axis across the pelvis (the Hips bone turns the rest pose's hip-to-hip line; the
    # posed hip joints also follow the CMU rig's own LHipJoint/RHipJoint bones, which can
    # turn them 60 degrees off the pelvis), level, pointing to the person's left: a
    # positive turn about it takes "up" towards the way the person faces (left = up x
    # forward)
    left = rot[:, rig.index("Hips")] @ (rig.heads[li] - rig.heads[ri])
    left[:, 1] = 0.0
    norm = np.linalg.norm(left, axis=1, keepdims=True)
    level = norm[:, 0] > 1e-3  # else the hips are one above the other: lying on a side
    left = np.where(level[:, None], left / np.maximum(norm, 1e-3), [1.0, 0.0, 0.0])
    # the trunk's lean now (hips to neck, in the plane of the bend): bend to ``degrees``
    # from upright, not by it, so a pose that leans already does not fold over
    forward = np.cross(left, [0.0, 1.0, 0.0])
    trunk = heads[:, rig.index("Neck")] - heads[:, rig.index("Hips")]
    lean = np.arctan2((trunk * forward).sum(1), trunk[:, 1])
    # only people standing up: a trunk leaning over 60 degrees either way (a handstand,
    # a cartwheel, lying down) stays as it is
    upright = level & (np.abs(lean) < np.deg2rad(UPRIGHT_DEG))
    turn = np.where((deg > 0) & upright, np.maximum(np.deg2rad(deg) - lean, 0.0), 0.0)
    r = axis_angle_matrix(left, turn)
    out = rot.copy()
    out[:, ~keep] = np.einsum("nij,nbjk->nbik", r, rot[:, ~keep])
    feet = [rig.index(n) for n in FEET]
    moved = posed_heads(rig, out, root)[:, feet] - heads[:, feet]
    return out, root - moved.mean(1), np.rad2deg(turn)


def choose_bends(num_poses: int, share: float, degrees: tuple[float, float],
                 seed: int) -> np.ndarray:
    """(num_poses,) float64: the bend of each pose in degrees, 0 for the poses left as
    they are; a ``share`` of them drawn uniformly in ``degrees``, from the job's seed."""
    rng = np.random.default_rng([seed, BEND_STREAM])
    chosen = rng.random(num_poses) < share
    angle = rng.uniform(degrees[0], degrees[1], num_poses)
    return np.where(chosen, angle, 0.0)
