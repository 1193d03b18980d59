"""Coordinates on the body surface that garments are cut by, and mesh helpers they share.

A :class:`BodyChart` is computed once per mesh topology on the *unshaped* base mesh (like
the labels), so a garment covers the same triangles on every avatar: a sleeve of length
0.5 ends at the same triangle row above the elbow of a child and of a heavy man.

Per body vertex (rest pose, metres, Y up, subject facing +Z, own left at +X):

* ``region``: the body region of its dominant bone (:data:`REGIONS`);
* ``arm_t``: along the arm, the arc length of the closest point of the polyline
  shoulder -> elbow -> wrist -> fingertip over the shoulder-wrist length (0 shoulder,
  ~0.5 elbow, 1 wrist; beyond 1 on the hand; negative towards the collarbone); NaN off
  the arms;
* ``leg_t``: the same along hip joint -> knee -> ankle -> toe (1 = ankle); NaN off the
  legs;
* ``height``: (y - hip joint height) / (neck base height - hip joint height): 0 at the
  hip joints, 1 at the base of the neck, for every vertex;
* ``neck_t``: (y - neck base) / (head joint - neck base) (0 at the base of the neck, 1 at
  the skull's base);
* ``head_h``: (y - head joint) / (top of the head - head joint) (0 at the skull's base, 1
  at the crown), and ``head_angle``: the direction from the head's vertical axis in
  radians, 0 straight ahead, +-pi at the back (hairlines are drawn in these).

Triangle values are the means over their three vertices, the region is the triangle's
dominant bone's (as for labels), so garment edges follow triangle rows and stay crisp.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from vhgen.body.mesh import Rig

# body regions; L/R are the subject's own sides
HEAD, NECK, TORSO, ARM_L, ARM_R, HAND_L, HAND_R, LEG_L, LEG_R, FOOT_L, FOOT_R = range(11)
REGIONS = ("head", "neck", "torso", "arm_l", "arm_r", "hand_l", "hand_r", "leg_l", "leg_r",
           "foot_l", "foot_r")

# the cmu_mb rig's bones by region (bones not listed count as torso)
_REGION_BONES = {
    HEAD: ("Head",), NECK: ("Neck", "Neck1"),
    ARM_L: ("LeftArm", "LeftForeArm"), ARM_R: ("RightArm", "RightForeArm"),
    HAND_L: ("LeftHand", "LThumb", "LeftFingerBase", "LeftHandFinger1"),
    HAND_R: ("RightHand", "RThumb", "RightFingerBase", "RightHandFinger1"),
    LEG_L: ("LeftUpLeg", "LeftLeg"), LEG_R: ("RightUpLeg", "RightLeg"),
    FOOT_L: ("LeftFoot", "LeftToeBase"), FOOT_R: ("RightFoot", "RightToeBase"),
}
# polylines of the limbs: bone heads, then the last bone's tail
ARM_CHAIN = {"l": ("LeftArm", "LeftForeArm", "LeftHand", "LeftHandFinger1"),
             "r": ("RightArm", "RightForeArm", "RightHand", "RightHandFinger1")}
LEG_CHAIN = {"l": ("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"),
             "r": ("RightUpLeg", "RightLeg", "RightFoot", "RightToeBase")}


@dataclass(frozen=True, eq=False)
class BodyChart:
    """Per-vertex (V,) and per-triangle (T,) coordinates of the body mesh (see module)."""

    region: np.ndarray
    arm_t: np.ndarray
    leg_t: np.ndarray
    height: np.ndarray
    neck_t: np.ndarray
    head_h: np.ndarray
    head_angle: np.ndarray
    front: np.ndarray  # (V,) bool: rest normal points forward (z > 0.25)
    x: np.ndarray  # (V,) rest x (the subject's own left is > 0)
    face_region: np.ndarray
    face_arm_t: np.ndarray
    face_leg_t: np.ndarray
    face_height: np.ndarray
    face_neck_t: np.ndarray
    face_head_h: np.ndarray
    face_head_angle: np.ndarray
    face_front: np.ndarray
    face_x: np.ndarray
    mean_ring: Any  # (V, V) scipy CSR: the mean of each vertex and its neighbours


def polyline_t(points: np.ndarray, nodes: np.ndarray, unit: float) -> np.ndarray:
    """Arc length (N,) of the closest point of the polyline ``nodes`` (K, 3) to each of
    ``points`` (N, 3), over ``unit``; the first segment extends backwards, so points
    before the start get negative values."""
    p = np.asarray(points, np.float64)
    best = np.full(len(p), np.inf)
    out = np.zeros(len(p))
    start = 0.0
    for k in range(len(nodes) - 1):
        a, b = nodes[k], nodes[k + 1]
        ab = b - a
        length = float(np.linalg.norm(ab))
        if length < 1e-12:
            continue
        s = (p - a) @ ab / length ** 2
        s = np.minimum(s, 1.0) if k == 0 else np.clip(s, 0.0, 1.0)
        if k == len(nodes) - 2:
            s = np.maximum(s, 0.0) if k > 0 else s
        d = np.linalg.norm(p - (a + s[:, None] * ab), axis=1)
        better = d < best
        best[better] = d[better]
        out[better] = start + s[better] * length
        start += length
    return out / unit


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) float64 unit area-weighted vertex normals (outward for counter-clockwise
    triangles); a vertex of no triangle gets +Y."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    idx = f.reshape(-1)
    per = np.repeat(fn, 3, axis=0)
    n = np.column_stack([np.bincount(idx, per[:, k], minlength=len(v)) for k in range(3)])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-15, n / np.maximum(length, 1e-15), [0.0, 1.0, 0.0])


def adjacency(faces: np.ndarray, num_vertices: int):
    """The mean-of-the-one-ring operator: a sparse (V, V) matrix whose row v averages v
    and its neighbours by triangle edges (scipy CSR)."""
    from scipy.sparse import csr_matrix

    f = np.asarray(faces, np.int64)
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0],
                        np.arange(num_vertices)])
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2],
                        np.arange(num_vertices)])
    code = np.unique(a * num_vertices + b)
    a, b = code // num_vertices, code % num_vertices
    count = np.bincount(a, minlength=num_vertices).astype(np.float64)
    return csr_matrix((1.0 / count[a], (a, b)), shape=(num_vertices, num_vertices))


def smooth(values: np.ndarray, mean_operator, iterations: int,
           mask: np.ndarray | None = None) -> np.ndarray:
    """Uniform Laplacian smoothing of per-vertex ``values`` (V, ...): each iteration
    replaces a value by the mean of itself and its neighbours' (:func:`adjacency`), only
    where ``mask`` is true if given."""
    out = np.array(values, dtype=np.float64)
    keep = None if mask is None else mask.reshape((-1,) + (1,) * (out.ndim - 1))
    for _ in range(iterations):
        mean = mean_operator @ out
        out = mean if keep is None else np.where(keep, mean, out)
    return out


def build_chart(rig: Rig, vertices: np.ndarray, faces: np.ndarray,
                dense_weights: np.ndarray) -> BodyChart:
    """The chart of the body mesh: ``vertices`` (V, 3) rest positions of the unshaped
    body, ``faces`` (T, 3) into them, ``dense_weights`` (V, B) MPFB2 weights."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    bone_region = np.full(len(rig.names), TORSO, np.int8)
    for reg, names in _REGION_BONES.items():
        for n in names:
            bone_region[rig.index(n)] = reg
    region = bone_region[np.argmax(dense_weights, axis=1)]
    face_region = bone_region[np.argmax(dense_weights[f].sum(axis=1), axis=1)]
    arm_t = np.full(len(v), np.nan)
    leg_t = np.full(len(v), np.nan)
    for side, (limb_l, limb_r) in (("l", (ARM_L, HAND_L)), ("r", (ARM_R, HAND_R))):
        names = ARM_CHAIN[side]
        nodes = np.vstack([rig.heads[[rig.index(n) for n in names]],
                           rig.tails[rig.index(names[-1])]])
        unit = float(np.linalg.norm(np.diff(nodes[:3], axis=0), axis=1).sum())
        m = np.isin(region, (limb_l, limb_r))
        arm_t[m] = polyline_t(v[m], nodes, unit)
    for side, (limb, foot) in (("l", (LEG_L, FOOT_L)), ("r", (LEG_R, FOOT_R))):
        names = LEG_CHAIN[side]
        nodes = np.vstack([rig.heads[[rig.index(n) for n in names]],
                           rig.tails[rig.index(names[-1])]])
        unit = float(np.linalg.norm(np.diff(nodes[:3], axis=0), axis=1).sum())
        m = np.isin(region, (limb, foot))
        leg_t[m] = polyline_t(v[m], nodes, unit)
    hip_y = float(rig.heads[rig.index("LeftUpLeg"), 1])
    neck_y = float(rig.heads[rig.index("Neck"), 1])
    head_y = float(rig.heads[rig.index("Head"), 1])
    height = (v[:, 1] - hip_y) / (neck_y - hip_y)
    neck_t = (v[:, 1] - neck_y) / (head_y - neck_y)
    head = v[region == HEAD]
    head_h = (v[:, 1] - head_y) / (head[:, 1].max() - head_y)
    head_z = 0.5 * (head[:, 2].min() + head[:, 2].max())
    head_angle = np.arctan2(v[:, 0], v[:, 2] - head_z)
    normals = vertex_normals(v, f)
    front = normals[:, 2] > 0.25

    def per_face(a: np.ndarray) -> np.ndarray:
        return a[f].mean(axis=1)

    centroid = v[f].mean(axis=1)
    out = BodyChart(region, arm_t, leg_t, height, neck_t, head_h, head_angle, front,
                    v[:, 0].copy(), face_region, per_face(arm_t), per_face(leg_t),
                    per_face(height), per_face(neck_t), per_face(head_h),
                    np.arctan2(centroid[:, 0], centroid[:, 2] - head_z),
                    front[f].sum(axis=1) >= 2, per_face(v[:, 0]), adjacency(f, len(v)))
    for a in (out.region, out.arm_t, out.leg_t, out.height, out.neck_t, out.head_h,
              out.head_angle, out.front, out.x, out.face_region, out.face_arm_t,
              out.face_leg_t, out.face_height, out.face_neck_t, out.face_head_h,
              out.face_head_angle, out.face_front, out.face_x):
        a.setflags(write=False)
    return out
