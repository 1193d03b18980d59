"""Linear blend skinning: bone transforms from poses, and the float64 NumPy reference.

A pose on a rig is (B, 3, 3) world skinning rotations A_b (relative to rest) and the root
head position. Bone b moves a rest point x to ``A_b (x - h_b) + p_b`` where ``h_b`` is
its rest head and ``p_b`` its posed head: ``p_root`` is given, and
``p_b = p_parent + A_parent (h_b - h_parent)``.
"""

from __future__ import annotations

import numpy as np

from vhgen.body.mesh import Rig


def posed_heads(rig: Rig, rotations: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Posed head positions (..., B, 3) float64 from rotations (..., B, 3, 3), root (..., 3)."""
    rotations = np.asarray(rotations, np.float64)
    root = np.asarray(root, np.float64)
    out = np.empty(rotations.shape[:-2] + (3,), dtype=np.float64)
    for k, par in enumerate(rig.parents):
        if par < 0:
            out[..., k, :] = root
        else:
            out[..., k, :] = out[..., par, :] + np.einsum(
                "...ij,j->...i", rotations[..., par, :, :], rig.heads[k] - rig.heads[par])
    return out


def bone_matrices(rig: Rig, rotations: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Skinning matrices (..., B, 4, 4) float64: M_b = [A_b | p_b - A_b h_b]."""
    rotations = np.asarray(rotations, np.float64)
    heads = posed_heads(rig, rotations, root)
    out = np.zeros(rotations.shape[:-2] + (4, 4), dtype=np.float64)
    out[..., :3, :3] = rotations
    out[..., :3, 3] = heads - np.einsum("...ij,...j->...i", rotations, rig.heads)
    out[..., 3, 3] = 1.0
    return out


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
