"""Compiled kernels (numba) for the spatial sensor effects. Pure functions over arrays."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def correlation_window(d, valid, dots, half, frac, inlier_px, splat_r):  # pragma: no cover
    """Dot-gated correlation-window filter (after BlenSor / ICL-NUIM / render_kinect).

    d : (H, W) float64 disparity (px); valid : (H, W) bool; dots : (H, W) bool, a dot of
    the projected pattern lands on the pixel. For every valid dot pixel c at least
    ``half`` px from the border: among the dots of its (2 half + 1)^2 window, the valid ones
    must exceed ``frac`` x the window's dots; their mean m is taken, and dots with
    |d - m| * w(x, y) < inlier_px, w = 1 / ((1.2 x)^2 + (1.2 y)^2) (w(0, 0) = 1), are
    inliers, which must also exceed ``frac`` x the window's dots. An accepted dot splats its
    own disparity to every pixel within ``splat_r`` px, where the splat weight 1 / (1 + r^2)
    beats what the pixel already holds. Pixels no accepted dot reaches are holes.
    Returns (d_out, valid_out).
    """
    h, w = d.shape
    out = np.zeros((h, w))
    best = np.zeros((h, w))
    r = int(np.floor(splat_r))
    r2max = splat_r * splat_r
    for y in range(half, h - half):
        for x in range(half, w - half):
            if not (dots[y, x] and valid[y, x]):
                continue
            n_dots = 0
            n_valid = 0
            s = 0.0
            for j in range(-half, half + 1):
                for i in range(-half, half + 1):
                    if dots[y + j, x + i]:
                        n_dots += 1
                        if valid[y + j, x + i]:
                            n_valid += 1
                            s += d[y + j, x + i]
            if n_valid <= frac * n_dots:
                continue
            mean = s / n_valid
            inl = 0
            for j in range(-half, half + 1):
                for i in range(-half, half + 1):
                    if dots[y + j, x + i] and valid[y + j, x + i]:
                        if i == 0 and j == 0:
                            wt = 1.0
                        else:
                            wt = 1.0 / ((1.2 * i) ** 2 + (1.2 * j) ** 2)
                        if abs(d[y + j, x + i] - mean) * wt < inlier_px:
                            inl += 1
            if inl <= frac * n_dots:
                continue
            dc = d[y, x]
            for j in range(-r, r + 1):
                yy = y + j
                if yy < 0 or yy >= h:
                    continue
                for i in range(-r, r + 1):
                    xx = x + i
                    rr = i * i + j * j
                    if xx < 0 or xx >= w or rr > r2max:
                        continue
                    wt = 1.0 / (1.0 + rr)
                    if wt > best[yy, xx]:
                        best[yy, xx] = wt
                        out[yy, xx] = dc
    return out, best > 0.0


@numba.njit(cache=True, nogil=True)
def screen_space_shadow(d, valid, projector_right):  # pragma: no cover
    """Projector shadows from disparity alone (rectified rig, projector at +-x).

    A pixel u of a row sees the projector ray through u_p = u - d(u). With the projector at
    +x, it is shadowed iff some pixel to its right on the row has a smaller u_p (a nearer
    surface blocks the projector's line of sight): a reverse running minimum per row.
    Occluders outside the image are missed (documented limitation).
    """
    h, w = d.shape
    out = np.zeros((h, w), dtype=np.bool_)
    for y in range(h):
        if projector_right:
            run = np.inf
            for x in range(w - 1, -1, -1):
                if valid[y, x]:
                    up = x - d[y, x]
                    if up > run:
                        out[y, x] = True
                    else:
                        run = up
        else:
            run = -np.inf
            for x in range(w):
                if valid[y, x]:
                    up = x + d[y, x]
                    if up < run:
                        out[y, x] = True
                    else:
                        run = up
    return out
