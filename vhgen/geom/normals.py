"""Surface normals of a masked patch of depth points, and what they say about its shape
(float64, pure NumPy/SciPy).

A person's surface is rounded; the person-sized things a depth people detector mistakes
for people are mostly built of flat pieces: the seat and back of a chair, a door, a
bookcase's front, a table top. :func:`surface_shares` measures that on one candidate.
Normals come from the points smoothed over a patch of ``scale_m`` (a box filter of that
many pixels at the patch's median depth, :data:`SCALE_M`, at least 3) and central differences as far
apart: a fixed size in metres, so that near and far things are measured alike, and wide
enough that the sensor's quantisation steps at 4 m (about 5 cm of depth) are averaged
over 7 pixels.
"""

from __future__ import annotations

import math

import numpy as np

# the three shares' angles: within 15 deg of the patch's dominant normal; a surface facing
# sideways (normal within 20 deg of level) or up/down (within 20 deg of vertical)
FLAT_COS = math.cos(math.radians(15.0))
UPRIGHT_SIN = math.sin(math.radians(20.0))
LEVEL_COS = math.cos(math.radians(20.0))
# the patch the normals are measured over: 5 cm, 7 px at 4 m (openni_525)
SCALE_M = 0.05


def patch_normals(points: np.ndarray, mask: np.ndarray, fx: float, scale_m: float = SCALE_M
                  ) -> np.ndarray:
    """Unit normals (K, 3) float64 of the pixels of ``mask`` (H, W) bool whose smoothing
    patch and both difference partners lie in it, for camera points ``points`` (H, W, 3)
    metres seen at focal length ``fx`` px; oriented towards the camera (n.z < 0)."""
    from scipy import ndimage

    mask = np.asarray(mask, bool)
    if mask.sum() < 9:
        return np.zeros((0, 3))
    z = float(np.median(points[..., 2][mask]))
    k = max(3, int(round(scale_m * fx / max(z, 1e-6))))
    m = mask.astype(np.float64)
    den = ndimage.uniform_filter(m, k, mode="constant")
    sm = np.stack([ndimage.uniform_filter(points[..., i] * m, k, mode="constant")
                   for i in range(3)], -1) / np.maximum(den, 1e-12)[..., None]
    full = mask & (den > 1.0 - 1e-9)  # the whole patch inside the mask
    h = k // 2 + 1
    if full.shape[0] <= 2 * h or full.shape[1] <= 2 * h:
        return np.zeros((0, 3))
    # the pixels h or more from the border whose patch and both partners lie in the mask
    inner = (full[h:-h, h:-h] & full[h:-h, 2 * h:] & full[h:-h, :-2 * h]
             & full[2 * h:, h:-h] & full[:-2 * h, h:-h])
    dx = sm[h:-h, 2 * h:] - sm[h:-h, :-2 * h]
    dy = sm[2 * h:, h:-h] - sm[:-2 * h, h:-h]
    n = np.cross(dx[inner], dy[inner])
    length = np.linalg.norm(n, axis=1)
    n = n[length > 0] / length[length > 0, None]
    return np.where(n[:, 2:3] > 0, -n, n)


def surface_shares(normals: np.ndarray, up: np.ndarray, pixels: int
                   ) -> tuple[float, float, float, float]:
    """Of ``normals`` (K, 3) of a patch of ``pixels`` pixels: the share of its pixels
    that have one (their patch lies in it: low for thin and ragged things, such as a
    plant's leaves or a coat stand's pole), the share within 15 deg of their dominant direction (the
    principal axis of their second moments: a flat piece), the share facing sideways
    (within 20 deg of level: upright surfaces) and the share facing up or down (within 20
    deg of ``up``: level surfaces); the last three are 0 for fewer than 10 normals."""
    measured = len(normals) / max(pixels, 1)
    if len(normals) < 10:
        return measured, 0.0, 0.0, 0.0
    dom = np.linalg.eigh(normals.T @ normals)[1][:, -1]
    c_up = np.abs(normals @ np.asarray(up, np.float64))
    return (measured, float((np.abs(normals @ dom) >= FLAT_COS).mean()),
            float((c_up <= UPRIGHT_SIN).mean()), float((c_up >= LEVEL_COS).mean()))
