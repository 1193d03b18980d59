"""Compiled linear blend skinning for CPU-side geometry queries (floor contact and the
footprints used for placement). Kept out of :mod:`vhgen.body.skinning` so that
``import vhgen`` compiles and imports no numba code; the float64 reference stays
:func:`vhgen.body.skinning.skin_vertices`."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _lbs(vertices, joints, weights, matrices, out):
    for v in range(vertices.shape[0]):
        x, y, z = vertices[v, 0], vertices[v, 1], vertices[v, 2]
        ox = oy = oz = 0.0
        for k in range(joints.shape[1]):
            w = weights[v, k]
            if w == 0.0:
                continue
            m = matrices[joints[v, k]]
            ox += w * (m[0, 0] * x + m[0, 1] * y + m[0, 2] * z + m[0, 3])
            oy += w * (m[1, 0] * x + m[1, 1] * y + m[1, 2] * z + m[1, 3])
            oz += w * (m[2, 0] * x + m[2, 1] * y + m[2, 2] * z + m[2, 3])
        out[v, 0] = ox
        out[v, 1] = oy
        out[v, 2] = oz


def skin_points(vertices: np.ndarray, joints: np.ndarray, weights: np.ndarray,
                matrices: np.ndarray) -> np.ndarray:
    """Linear blend skinning of one pose, compiled: same arguments and result as
    :func:`vhgen.body.skinning.skin_vertices` for a single (B, 4, 4) set of matrices
    (float64; equal to it up to rounding, sum over bones of transformed points instead of
    the transform of blended matrices).

    vertices : (V, 3); joints : (V, K) int; weights : (V, K); matrices : (B, 4, 4).
    Returns (V, 3) float64.
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    m = np.ascontiguousarray(matrices, dtype=np.float64)
    if m.ndim != 3 or m.shape[1:] != (4, 4):
        raise ValueError(f"matrices must be (B, 4, 4), got {m.shape}")
    out = np.empty((v.shape[0], 3), np.float64)
    _lbs(v, np.ascontiguousarray(joints, dtype=np.int64),
         np.ascontiguousarray(weights, dtype=np.float64), m, out)
    return out


@numba.njit(cache=True)
def _footprint(points):
    lo_y = np.inf
    x0 = z0 = np.inf
    x1 = z1 = -np.inf
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        lo_y = min(lo_y, y)
        x0 = min(x0, x)
        x1 = max(x1, x)
        z0 = min(z0, z)
        z1 = max(z1, z)
    cx, cz = (x0 + x1) / 2, (z0 + z1) / 2
    r2 = 0.0
    for i in range(points.shape[0]):
        dx, dz = points[i, 0] - cx, points[i, 2] - cz
        r2 = max(r2, dx * dx + dz * dz)
    return lo_y, cx, cz, np.sqrt(r2)


def footprint(points: np.ndarray) -> tuple[float, float, float, float]:
    """Of (V, 3) float64 points (y up): the lowest y, and the circle about the centre of
    their x/z bounding box that holds them all: (lowest_y, centre_x, centre_z, radius)."""
    p = np.ascontiguousarray(points, dtype=np.float64)
    if len(p) == 0:
        raise ValueError("footprint of no points")
    lo, cx, cz, r = _footprint(p)
    return float(lo), float(cx), float(cz), float(r)
