"""Linear blend skinning: bone transforms from poses, and the float64 NumPy reference.

A pose on a rig is (B, 3, 3) world skinning rotations A_b (relative to rest) and the root
head position. Bone b moves a rest point x to ``A_b (x - h_b) + p_b`` where ``h_b`` is
its rest head and ``p_b`` its posed head: ``p_root`` is given, and
``p_b = p_parent + A_parent (h_b - h_parent)``.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.rotations import matrix_to_quaternion


@lru_cache(maxsize=16)
def _levels(parents: tuple[int, ...]) -> tuple[np.ndarray, ...]:
    """Bone indices grouped by depth below their root (roots excluded), shallow first."""
    depth = [0] * len(parents)
    for k, par in enumerate(parents):
        depth[k] = 0 if par < 0 else depth[par] + 1
    d = np.array(depth, dtype=np.int64)
    return tuple(np.flatnonzero(d == level) for level in range(1, int(d.max(initial=0)) + 1))


def posed_heads(rig: Rig, rotations: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Posed head positions (..., B, 3) float64 from rotations (..., B, 3, 3), root (..., 3).

    One vectorised step per depth of the tree (bones of a level only need their parents'
    heads); each head is the same sum, in the same order, as bone by bone."""
    rotations = np.asarray(rotations, np.float64)
    root = np.asarray(root, np.float64)
    parents = np.asarray(rig.parents)
    out = np.empty(rotations.shape[:-2] + (3,), dtype=np.float64)
    out[..., parents < 0, :] = root[..., None, :]
    for level in _levels(tuple(int(p) for p in parents)):
        par = parents[level]
        out[..., level, :] = out[..., par, :] + np.einsum(
            "...kij,kj->...ki", rotations[..., par, :, :], rig.heads[level] - rig.heads[par])
    return out


def matrices_from_heads(rig: Rig, rotations: np.ndarray, heads: np.ndarray) -> np.ndarray:
    """Skinning matrices (..., B, 4, 4) float64 from rotations (..., B, 3, 3) and the posed
    heads (..., B, 3) of :func:`posed_heads` (callers that need both compute heads once)."""
    rotations = np.asarray(rotations, np.float64)
    out = np.zeros(rotations.shape[:-2] + (4, 4), dtype=np.float64)
    out[..., :3, :3] = rotations
    out[..., :3, 3] = heads - np.einsum("...ij,...j->...i", rotations, rig.heads)
    out[..., 3, 3] = 1.0
    return out


def bone_matrices(rig: Rig, rotations: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Skinning matrices (..., B, 4, 4) float64: M_b = [A_b | p_b - A_b h_b]."""
    return matrices_from_heads(rig, rotations, posed_heads(rig, rotations, root))


def skin_vertices(vertices: np.ndarray, joints: np.ndarray, weights: np.ndarray,
                  matrices: np.ndarray) -> np.ndarray:
    """Linear blend skinning, the float64 reference for the vertex shader.

    vertices : (V, 3); joints : (V, K) int; weights : (V, K) summing to 1;
    matrices : (..., B, 4, 4).  Returns (..., V, 3) float64.
    """
    vertices = np.asarray(vertices, np.float64)
    weights = np.asarray(weights, np.float64)
    m = np.asarray(matrices, np.float64)
    blended = np.einsum("vk,...vkij->...vij", weights, m[..., joints, :3, :])  # (..., V, 3, 4)
    return np.einsum("...vij,vj->...vi", blended[..., :3], vertices) + blended[..., 3]


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (x, y, z, w) quaternions."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def dual_quaternions(matrices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid (..., 4, 4) transforms -> unit dual quaternions: real (..., 4), dual (..., 4),
    (x, y, z, w) order, real part with w >= 0, dual = 0.5 * t * real."""
    m = np.asarray(matrices, np.float64)
    real = matrix_to_quaternion(m[..., :3, :3])
    t = np.concatenate([m[..., :3, 3], np.zeros(m.shape[:-2] + (1,))], axis=-1)
    return real, 0.5 * _qmul(t, real)


def skin_vertices_dqs(vertices: np.ndarray, joints: np.ndarray, weights: np.ndarray,
                      matrices: np.ndarray) -> np.ndarray:
    """Dual-quaternion skinning (Kavan et al. 2008), float64 reference of the shader.

    Same arguments as :func:`skin_vertices`; matrices must be rigid. Returns (..., V, 3).
    """
    real, dual = dual_quaternions(matrices)
    r = real[..., joints, :]  # (..., V, K, 4)
    d = dual[..., joints, :]
    w = np.asarray(weights, np.float64)
    sign = np.where(np.sum(r * r[..., :1, :], axis=-1) < 0, -1.0, 1.0) * w
    br = np.sum(sign[..., None] * r, axis=-2)
    bd = np.sum(sign[..., None] * d, axis=-2)
    n = np.linalg.norm(br, axis=-1, keepdims=True)
    br, bd = br / n, bd / n
    v = np.asarray(vertices, np.float64)
    xyz, rw = br[..., :3], br[..., 3:]
    t = 2.0 * (rw * bd[..., :3] - bd[..., 3:] * xyz + np.cross(xyz, bd[..., :3]))
    return v + 2.0 * np.cross(xyz, np.cross(xyz, v) + rw * v) + t
