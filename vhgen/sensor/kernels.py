"""Compiled kernels (numba) for the spatial sensor effects. Pure functions over arrays."""

from __future__ import annotations

import numba
import numpy as np

# unsigned index type: numba adds a negative-index wraparound to every signed index
U = np.uint64


@numba.njit(cache=True, nogil=True)
def _cw_tables(d, valid, dots):  # pragma: no cover
    """Flat (H + 1) (W + 1) summed-area tables of valid dots (int32) and of their
    disparities (float64, the row's running sum added to the row above), and the raster
    indices of the valid dots."""
    h, w = d.shape
    W = U(w + 1)
    sv = np.empty((h + 1) * (w + 1), dtype=np.int32)
    ss = np.empty((h + 1) * (w + 1))
    cand = np.empty(h * w, dtype=np.int64)
    df = d.reshape(-1)
    vf = valid.reshape(-1)
    of = dots.reshape(-1)
    for x in range(w + 1):
        sv[U(x)] = 0
        ss[U(x)] = 0.0
    nc = U(0)
    for y in range(h):
        uy = U(y)
        r0 = uy * W          # SAT row y
        r1 = r0 + W          # SAT row y + 1
        p0 = uy * U(w)       # image row y
        sv[r1] = 0
        ss[r1] = 0.0
        rv = 0
        rs = 0.0
        for x in range(w):
            ux = U(x)
            p = p0 + ux
            isv = of[p] & vf[p]
            v = df[p]
            rv += 1 if isv else 0
            rs += v if isv else 0.0
            sv[r1 + ux + U(1)] = sv[r0 + ux + U(1)] + rv
            ss[r1 + ux + U(1)] = ss[r0 + ux + U(1)] + rs
            cand[nc] = y * w + x
            nc += U(1) if isv else U(0)
    return sv, ss, cand[:nc]


@numba.njit(cache=True, nogil=True)
def _cw_dot_sat(dots):  # pragma: no cover
    """Flat (H + 1) (W + 1) int32 summed-area table of all dots."""
    h, w = dots.shape
    W = U(w + 1)
    sd = np.empty((h + 1) * (w + 1), dtype=np.int32)
    of = dots.reshape(-1)
    for x in range(w + 1):
        sd[U(x)] = 0
    for y in range(h):
        r0 = U(y) * W
        r1 = r0 + W
        p0 = U(y) * U(w)
        sd[r1] = 0
        rd = 0
        for x in range(w):
            ux = U(x)
            rd += 1 if of[p0 + ux] else 0
            sd[r1 + ux + U(1)] = sd[r0 + ux + U(1)] + rd
    return sd


@numba.njit(cache=True, nogil=True)
def _cw_has_stray(valid, dots):  # pragma: no cover
    """Whether some dot falls on an invalid pixel (branch-free, one pass)."""
    vf = valid.reshape(-1)
    of = dots.reshape(-1)
    acc = False
    for i in range(vf.size):
        acc |= of[U(i)] & ~vf[U(i)]
    return acc


@numba.njit(cache=True, nogil=True)
def _cw_accept(d, valid, dots, sv, ss, sd, cand, stray, half, frac, inlier_px):  # pragma: no cover
    """Raster indices of the accepted dots, in raster order (see correlation_window)."""
    h, w = d.shape
    df = d.reshape(-1)
    vf = valid.reshape(-1)
    of = dots.reshape(-1)
    n = 2 * half + 1
    thr = np.empty(n * n)
    for j in range(-half, half + 1):
        for i in range(-half, half + 1):
            k = U((j + half) * n + i + half)
            if i == 0 and j == 0:
                thr[k] = inlier_px
            else:
                thr[k] = inlier_px * ((1.2 * i) ** 2 + (1.2 * j) ** 2)
    W = U(w + 1)
    un = U(n)
    acc = np.empty(cand.size, dtype=np.int64)
    na = 0
    for k in range(cand.size):
        c = cand[U(k)]
        y = c // w
        x = c - y * w
        if y < half or y >= h - half or x < half or x >= w - half:
            continue
        a0 = U(y - half) * W + U(x - half)   # SAT (y0, x0)
        b0 = a0 + un * W                     # SAT (y1, x0)
        n_valid = sv[b0 + un] - sv[a0 + un] - sv[b0] + sv[a0]
        if stray:
            n_dots = sd[b0 + un] - sd[a0 + un] - sd[b0] + sd[a0]
        else:
            n_dots = n_valid
        need = frac * n_dots
        if n_valid <= need:
            continue
        mean = (ss[b0 + un] - ss[a0 + un] - ss[b0] + ss[a0]) / n_valid
        top = sv[a0 + un] - sv[a0]
        inl = 0
        rb = U(y - half) * U(w) + U(x - half)
        tb = U(0)
        ra = a0
        for _ in range(n):
            row_inl = 0
            if stray:
                for i in range(n):
                    p = rb + U(i)
                    row_inl += 1 if of[p] & vf[p] & (abs(df[p] - mean) < thr[tb + U(i)]) else 0
            else:  # every dot is valid: one mask load fewer
                for i in range(n):
                    p = rb + U(i)
                    row_inl += 1 if of[p] & (abs(df[p] - mean) < thr[tb + U(i)]) else 0
            inl += row_inl
            if inl > need:
                acc[na] = c
                na += 1
                break
            ra += W
            left = n_valid - (sv[ra + un] - sv[ra] - top)
            if inl + left <= need:
                break
            rb += U(w)
            tb += un
    return acc[:na]


@numba.njit(cache=True, nogil=True)
def _cw_splat(d, acc, splat_r):  # pragma: no cover
    """Splat the accepted dots in raster order; returns (d_out, valid_out)."""
    h, w = d.shape
    out = np.zeros((h, w))
    r = int(np.floor(splat_r))
    r2max = splat_r * splat_r
    if r2max > 254.0:
        raise ValueError("correlation_window: splat radius above 15 px")
    best = np.zeros((h, w), dtype=np.uint8)
    outf = out.reshape(-1)
    bestf = best.reshape(-1)
    df = d.reshape(-1)
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
    for k in range(acc.size):
        c = acc[k]
        y = c // w
        x = c - y * w
        dc = df[c]
        if r <= y < h - r and r <= x < w - r:
            # branch-free: which splat wins is data-dependent, a branch mispredicts
            for q in range(m):
                p = U(c + of[U(q)])
                o = ow[U(q)]
                b = bestf[p]
                t = o > b
                bestf[p] = o if t else b
                outf[p] = dc if t else outf[p]
        else:
            for q in range(m):
                yy = y + oy[q]
                xx = x + ox[q]
                if 0 <= yy < h and 0 <= xx < w and ow[q] > best[yy, xx]:
                    best[yy, xx] = ow[q]
                    out[yy, xx] = dc
    return out, best > 0


@numba.njit(cache=True, nogil=True)
def correlation_window(d, valid, dots, half, frac, inlier_px, splat_r):  # pragma: no cover
    """Dot-gated correlation-window filter (after BlenSor / ICL-NUIM / render_kinect).

    d : (H, W) float64 disparity (px); valid : (H, W) bool; dots : (H, W) bool, a dot of
    the projected pattern lands on the pixel. For every valid dot pixel c at least
    ``half`` px from the border: among the dots of its (2 half + 1)^2 window, the valid ones
    must exceed ``frac`` x the window's dots; their mean m is taken, and dots with
    |d - m| * w(x, y) < inlier_px, w = 1 / ((1.2 x)^2 + (1.2 y)^2) (w(0, 0) = 1), are
    inliers, which must also exceed ``frac`` x the window's dots. An accepted dot splats
    its own disparity to every pixel within ``splat_r`` px (ValueError above
    sqrt(254) ~ 15.9 px), where the splat weight 1 / (1 + r^2) beats what the pixel
    already holds (dots splat in raster order, so on a tie the earlier dot keeps the
    pixel). Pixels no accepted dot reaches are holes. Returns (d_out, valid_out); d_out is
    0 where valid_out is False.

    The window sum of disparities is a float64 summed-area table: per row the running sum
    of d over the valid dots left to right, added to the table row above. The mean is
    (S[y1, x1] - S[y0, x1] - S[y1, x0] + S[y0, x0]) / n_valid in that order, so it is the
    same number whatever the implementation (tests/sensor/test_correlation_window.py
    holds a plain reference). Counts come from int32 tables; the table of all dots is
    built only when some dot is not valid (the shipped stage computes dots on valid
    pixels only, so there the valid-dot table serves both). The inlier scan reads the
    window a row at a time and stops after the first row at which the verdict is certain
    (it depends only on the total count). Indices are unsigned so that numba emits no
    negative-index wraparound in the inner loops.
    """
    d = np.ascontiguousarray(d)
    valid = np.ascontiguousarray(valid)
    dots = np.ascontiguousarray(dots)
    stray = _cw_has_stray(valid, dots)
    sv, ss, cand = _cw_tables(d, valid, dots)
    sd = _cw_dot_sat(dots) if stray else sv
    acc = _cw_accept(d, valid, dots, sv, ss, sd, cand, stray, half, frac, inlier_px)
    return _cw_splat(d, acc, splat_r)


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
