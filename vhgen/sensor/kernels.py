"""Compiled kernels (numba) for the spatial sensor effects. Pure functions over arrays."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, fastmath=True)
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
    Window counts and sums come from summed-area tables (O(1) per pixel); the inliers are
    counted a window row at a time, branch-free inside the row (the row is contiguous, so
    the compiler vectorises it), and the scan stops after the first row at which the
    verdict is certain. The verdict depends only on the total inlier count, so the order
    of the count does not change it. Returns (d_out, valid_out); d_out is 0 where
    valid_out is False.
    """
    h, w = d.shape
    # summed-area tables of dots, valid dots and their disparities
    sd = np.zeros((h + 1, w + 1), dtype=np.int32)
    sv = np.zeros((h + 1, w + 1), dtype=np.int32)
    ss = np.zeros((h + 1, w + 1))
    dv = np.zeros((h, w), dtype=np.bool_)  # a valid dot
    for y in range(h):
        rd = 0
        rv = 0
        rs = 0.0
        for x in range(w):
            if dots[y, x]:
                rd += 1
                if valid[y, x]:
                    dv[y, x] = True
                    rv += 1
                    rs += d[y, x]
            sd[y + 1, x + 1] = sd[y, x + 1] + rd
            sv[y + 1, x + 1] = sv[y, x + 1] + rv
            ss[y + 1, x + 1] = ss[y, x + 1] + rs
    n = 2 * half + 1
    thr = np.empty((n, n))  # |d - m| < thr[j, i]  <=>  |d - m| * w(i, j) < inlier_px
    for j in range(-half, half + 1):
        for i in range(-half, half + 1):
            if i == 0 and j == 0:
                thr[j + half, i + half] = inlier_px
            else:
                thr[j + half, i + half] = inlier_px * ((1.2 * i) ** 2 + (1.2 * j) ** 2)
    out = np.zeros((h, w))
    r = int(np.floor(splat_r))
    r2max = splat_r * splat_r
    if r2max > 254.0:
        raise ValueError("correlation_window: splat radius above 15 px")
    # The splat weight 1 / (1 + r^2) falls strictly with the integer r^2, so the pixel
    # keeps the splat of smallest r^2: stored as the rank 255 - r^2 (0 = no splat yet),
    # uint8, so the whole array stays in cache, instead of the float64 weight.
    best = np.zeros((h, w), dtype=np.uint8)
    outf = out.reshape(-1)
    bestf = best.reshape(-1)
    # splat footprint: offsets within the radius and their ranks
    m = 0
    for j in range(-r, r + 1):
        for i in range(-r, r + 1):
            if i * i + j * j <= r2max:
                m += 1
    oy = np.empty(m, dtype=np.int64)
    ox = np.empty(m, dtype=np.int64)
    of = np.empty(m, dtype=np.int64)
    ow = np.empty(m, dtype=np.uint8)
    m = 0
    for j in range(-r, r + 1):
        for i in range(-r, r + 1):
            if i * i + j * j <= r2max:
                oy[m] = j
                ox[m] = i
                of[m] = j * w + i
                ow[m] = 255 - (i * i + j * j)
                m += 1
    for y in range(half, h - half):
        y0 = y - half
        y1 = y + half + 1
        for x in range(half, w - half):
            if not dv[y, x]:
                continue
            x0 = x - half
            x1 = x + half + 1
            n_dots = sd[y1, x1] - sd[y0, x1] - sd[y1, x0] + sd[y0, x0]
            n_valid = sv[y1, x1] - sv[y0, x1] - sv[y1, x0] + sv[y0, x0]
            need = frac * n_dots
            if n_valid <= need:
                continue
            mean = (ss[y1, x1] - ss[y0, x1] - ss[y1, x0] + ss[y0, x0]) / n_valid
            inl = 0
            left = n_valid
            accepted = False
            for j in range(n):
                yy = y0 + j
                row_dots = 0
                row_inl = 0
                for i in range(n):
                    is_dot = dv[yy, x0 + i]
                    inlier = abs(d[yy, x0 + i] - mean) < thr[j, i]
                    row_dots += 1 if is_dot else 0
                    row_inl += 1 if is_dot and inlier else 0
                inl += row_inl
                left -= row_dots
                if inl > need:
                    accepted = True
                    break
                if inl + left <= need:
                    break
            if not accepted:
                continue
            dc = d[y, x]
            c = y * w + x
            if r <= y < h - r and r <= x < w - r:
                for k in range(m):
                    p = c + of[k]
                    if ow[k] > bestf[p]:
                        bestf[p] = ow[k]
                        outf[p] = dc
            else:
                for k in range(m):
                    yy = y + oy[k]
                    xx = x + ox[k]
                    if 0 <= yy < h and 0 <= xx < w and ow[k] > best[yy, xx]:
                        best[yy, xx] = ow[k]
                        out[yy, xx] = dc
    return out, best > 0


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


@numba.njit(cache=True, nogil=True)
def invert_inplace(a, valid, fb):  # pragma: no cover
    """a <- fb / a where valid, 0 elsewhere (depth <-> disparity), in place. Branch-free
    (selects, so the loop vectorises): its cost does not grow with the valid pixels."""
    f = a.reshape(-1)
    v = valid.reshape(-1)
    for i in range(f.size):
        ok = v[i]
        q = fb / (f[i] if ok else 1.0)
        f[i] = q if ok else 0.0


@numba.njit(cache=True, nogil=True)
def add_noise_sigma_inplace(a, valid, draws, table, sigma):  # pragma: no cover
    """a += sigma[i] * N(0, 1) where valid (per-pixel sigma)."""
    f = a.reshape(-1)
    v = valid.reshape(-1)
    s = sigma.reshape(-1)
    for i in range(f.size):
        if v[i]:
            f[i] += s[i] * table[draws[i]]


@numba.njit(cache=True, nogil=True)
def quantise_inplace(d, valid, step):  # pragma: no cover
    """d <- floor(d / step + 0.5) * step where valid; pixels ending at d <= 0 turn invalid.
    Returns the bool mask of those pixels. Branch-free, like :func:`invert_inplace`."""
    f = d.reshape(-1)
    v = valid.reshape(-1)
    lost = np.empty(f.size, dtype=np.bool_)
    for i in range(f.size):
        ok = v[i]
        x = f[i]
        q = np.floor(x / step + 0.5) * step
        drop = ok & (q <= 0.0)
        lost[i] = drop
        v[i] = ok & (q > 0.0)
        f[i] = 0.0 if drop else (q if ok else x)
    return lost.reshape(d.shape)


@numba.njit(cache=True, nogil=True)
def lateral_indices(draws, table, sigma, h, w):  # pragma: no cover
    """Flat source index of every pixel displaced by (sigma * N, sigma * N), nearest pixel,
    clamped to the image (sigma scalar or (H, W)); ``draws`` uint32, one per pixel, whose
    low and high 16 bits index the inverse-CDF table for x and y."""
    out = np.empty(h * w, dtype=np.int64)
    sflat = sigma.reshape(-1)
    per_pixel = sflat.size == h * w
    for y in range(h):
        for x in range(w):
            i = y * w + x
            s = sflat[i] if per_pixel else sflat[0]
            xx = int(np.floor(x + s * table[draws[i] & 0xFFFF] + 0.5))
            yy = int(np.floor(y + s * table[draws[i] >> 16] + 0.5))
            xx = min(max(xx, 0), w - 1)
            yy = min(max(yy, 0), h - 1)
            out[i] = yy * w + xx
    return out


@numba.njit(cache=True, nogil=True)
def incidence_cos(normals, rays_unit):  # pragma: no cover
    """|n . ray| per pixel (normals (H, W, 3), unit rays (H, W, 3))."""
    h, w, _ = normals.shape
    out = np.empty((h, w))
    for y in range(h):
        for x in range(w):
            s = 0.0
            for c in range(3):
                s += normals[y, x, c] * rays_unit[y, x, c]
            out[y, x] = abs(s)
    return out


@numba.njit(cache=True, nogil=True)
def dots_from_pattern(d, valid, pattern, pad):  # pragma: no cover
    """Pixels a projector dot lands on: pattern[v, round(u - d) + pad] (rectified rig)."""
    h, w = d.shape
    pw = pattern.shape[1]
    out = np.zeros((h, w), dtype=np.bool_)
    for y in range(h):
        for x in range(w):
            if valid[y, x]:
                up = int(np.floor(x - d[y, x] + 0.5)) + pad
                if 0 <= up < pw:
                    out[y, x] = pattern[y, up]
    return out


@numba.njit(cache=True, nogil=True)
def gather_state(idx, z, valid, normals, labels):  # pragma: no cover
    """z, valid, normals, labels re-sampled at flat source indices ``idx`` (normals and
    labels may be empty arrays when absent). One loop per array: a fused loop over all
    four ran 3x slower (it does not vectorise)."""
    h, w = z.shape
    zf = z.reshape(-1)
    vf = valid.reshape(-1)
    z2 = np.empty(h * w)
    v2 = np.empty(h * w, dtype=np.bool_)
    for i in range(h * w):
        z2[i] = zf[idx[i]]
    for i in range(h * w):
        v2[i] = vf[idx[i]]
    nf = normals.reshape(-1, 3)
    n2 = nf
    if normals.size == h * w * 3:
        n2 = np.empty((h * w, 3), dtype=normals.dtype)
        for i in range(h * w):
            k = idx[i]
            n2[i, 0] = nf[k, 0]
            n2[i, 1] = nf[k, 1]
            n2[i, 2] = nf[k, 2]
    lf = labels.reshape(-1)
    l2 = lf
    if labels.size == h * w:
        l2 = np.empty(h * w, dtype=labels.dtype)
        for i in range(h * w):
            l2[i] = lf[idx[i]]
    return z2.reshape(h, w), v2.reshape(h, w), n2, l2


@numba.njit(cache=True, nogil=True)
def encode_raw11(d, ok, d_off):  # pragma: no cover
    """k_d = round_half_up(d_off - 8 d), 2047 where invalid or outside 0..2046."""
    h, w = d.shape
    out = np.full((h, w), 2047, dtype=np.uint16)
    for y in range(h):
        for x in range(w):
            if ok[y, x]:
                k = np.floor(d_off - 8.0 * d[y, x] + 0.5)
                if 0.0 <= k <= 2046.0:
                    out[y, x] = np.uint16(k)
    return out


@numba.njit(cache=True, nogil=True)
def sanitise(depth):  # pragma: no cover
    """Planar depth -> (float64 copy with 0 where no hit, hit mask); NaN, inf, <= 0 = no hit."""
    h, w = depth.shape
    z = np.zeros((h, w))
    hit = np.zeros((h, w), dtype=np.bool_)
    for y in range(h):
        for x in range(w):
            v = np.float64(depth[y, x])
            if v > 0.0 and v < np.inf:
                z[y, x] = v
                hit[y, x] = True
    return z, hit


@numba.njit(cache=True, nogil=True)
def finish(a, valid, fb, is_disparity):  # pragma: no cover
    """One pass to the outputs: uint16 mm (rounded half up, 0 = none, > 65.535 m invalid),
    the final valid mask and the disparity (0 where invalid), from depth or disparity."""
    h, w = a.shape
    mm_out = np.zeros((h, w), dtype=np.uint16)
    ok = np.zeros((h, w), dtype=np.bool_)
    disp = np.zeros((h, w))
    for y in range(h):
        for x in range(w):
            if valid[y, x]:
                v = a[y, x]
                z = fb / v if is_disparity else v
                mm = np.floor(z * 1000.0 + 0.5)
                if 1.0 <= mm <= 65535.0:
                    mm_out[y, x] = np.uint16(mm)
                    ok[y, x] = True
                    disp[y, x] = v if is_disparity else fb / v
    return mm_out, ok, disp


@numba.njit(cache=True, nogil=True)
def remove_pixels(mask, valid, arr, hole):  # pragma: no cover
    """One pass: pixels in ``mask`` that are still valid become invalid, get 0 in ``arr`` and
    are marked in ``hole``. Returns how many were removed."""
    m = mask.reshape(-1)
    v = valid.reshape(-1)
    a = arr.reshape(-1)
    hl = hole.reshape(-1)
    n = 0
    for i in range(m.size):
        if m[i] and v[i]:
            v[i] = False
            a[i] = 0.0
            hl[i] = True
            n += 1
    return n


@numba.njit(cache=True, nogil=True)
def dropout_inplace(z, valid, normals, rays_unit, ray_norm, cos_min, r_max,
                    hole):  # pragma: no cover
    """Grazing (|cos| < cos_min) or too far for the albedo (range > r_max) valid pixels
    become invalid, get 0 in ``z`` and are marked in ``hole``, in one pass. Returns how
    many were removed."""
    h, w = z.shape
    n = 0
    for y in range(h):
        for x in range(w):
            if valid[y, x]:
                c = abs(normals[y, x, 0] * rays_unit[y, x, 0] + normals[y, x, 1] *
                        rays_unit[y, x, 1] + normals[y, x, 2] * rays_unit[y, x, 2])
                if c < cos_min or z[y, x] * ray_norm[y, x] > r_max:
                    valid[y, x] = False
                    z[y, x] = 0.0
                    hole[y, x] = True
                    n += 1
    return n


@numba.njit(cache=True, nogil=True)
def gate_inplace(z, valid, z_min, z_max, hole):  # pragma: no cover
    """Range gating in one pass: valid pixels outside [z_min, z_max] become holes."""
    zf = z.reshape(-1)
    v = valid.reshape(-1)
    hl = hole.reshape(-1)
    n = 0
    for i in range(zf.size):
        if v[i] and (zf[i] < z_min or zf[i] > z_max):
            v[i] = False
            zf[i] = 0.0
            hl[i] = True
            n += 1
    return n


@numba.njit(cache=True, nogil=True)
def add_noise_drop_inplace(a, valid, draws, table, sigma, hole):  # pragma: no cover
    """a += sigma * N(0, 1) where valid; pixels pushed to a <= 0 become holes (one pass)."""
    f = a.reshape(-1)
    v = valid.reshape(-1)
    hl = hole.reshape(-1)
    n = 0
    for i in range(f.size):
        if v[i]:
            x = f[i] + sigma * table[draws[i]]
            if x <= 0.0:
                v[i] = False
                f[i] = 0.0
                hl[i] = True
                n += 1
            else:
                f[i] = x
    return n
