"""Compiled kernels (numba) for the spatial sensor effects. Pure functions over arrays."""

from __future__ import annotations

import numba
import numpy as np

# unsigned index type: numba adds a negative-index wraparound to every signed index
U = np.uint64


@numba.njit(cache=True, nogil=True)
def _cw_mask_row(db, vf, of, p0, w, mrow, brow):  # pragma: no cover
    """Image row at flat offset p0: mrow = valid dot (0/1), brow = the bits of d where a
    valid dot, of +0.0 elsewhere. Branch-free; a bit mask, so NaN or inf off the dots
    never enters, and s + 0.0 == s, so summing brow is the skip-the-rest sum. Returns
    whether a dot falls on an invalid pixel."""
    st = np.uint8(0)
    for x in range(w):
        p = p0 + U(x)
        m = of[p] & vf[p]
        st |= of[p] & ~vf[p]
        mrow[U(x)] = m
        brow[U(x)] = db[p] & (U(0) - U(m))
    return st != 0


@numba.njit(cache=True, nogil=True)
def _cw_col_add(sv, ss, r0, r1, w):  # pragma: no cover
    """Table row at r1 (the row's running sums) += table row at r0 (the row above)."""
    for x in range(1, w + 1):
        ux = U(x)
        sv[r1 + ux] += sv[r0 + ux]
        ss[r1 + ux] = ss[r0 + ux] + ss[r1 + ux]


@numba.njit(cache=True, nogil=True)
def _cw_dot_row(of, p0, w, sd, r0, r1):  # pragma: no cover
    """All-dot table row at r1 from the row at r0 and the image row at flat offset p0."""
    sd[r1] = 0
    rd = np.int32(0)
    for x in range(w):
        ux = U(x)
        rd += np.int32(of[p0 + ux])
        sd[r1 + ux + U(1)] = sd[r0 + ux + U(1)] + rd


@numba.njit(cache=True, nogil=True)
def _cw_sat_row(db, vf, of, stray, y, w, sv, ss, sd, r0, r1, mrow, brow, frow):  # pragma: no cover
    """Summed-area table row y + 1 (flat offset r1) from row y (offset r0) and image row y:
    valid dots (int32 sv), their disparities (float64 ss) and, once ``stray`` (some dot
    off the valid pixels so far), all dots (int32 sd). ss is the row's running sum left
    to right added to the row above. Returns the updated ``stray``."""
    p0 = U(y) * U(w)
    if _cw_mask_row(db, vf, of, p0, w, mrow, brow) and not stray:
        # first dot off the valid pixels: above it the dot table equals the valid-dot one
        sd[:] = sv
        stray = True
    sv[r1] = 0
    ss[r1] = 0.0
    rv = np.int32(0)
    rs = 0.0
    for x in range(w):
        ux = U(x)
        rv += np.int32(mrow[ux])
        rs += frow[ux]
        sv[r1 + ux + U(1)] = rv
        ss[r1 + ux + U(1)] = rs
    _cw_col_add(sv, ss, r0, r1, w)
    if stray:
        _cw_dot_row(of, p0, w, sd, r0, r1)
    return stray


@numba.njit(cache=True, nogil=True)
def _cw_sat_pair(db, vf, of, stray, y, w, sv, ss, sd, r0, r1, r2, mrow, brow, frow,
                 mrow2, brow2, frow2):  # pragma: no cover
    """Summed-area table rows y + 1 and y + 2 (offsets r1, r2) as _cw_sat_row does, the
    two running sums interleaved: they are independent, so their float-add latencies
    overlap (the order of each row's own sum is unchanged)."""
    p0 = U(y) * U(w)
    p1 = p0 + U(w)
    st0 = _cw_mask_row(db, vf, of, p0, w, mrow, brow)
    st1 = _cw_mask_row(db, vf, of, p1, w, mrow2, brow2)
    if (st0 or st1) and not stray:
        sd[:] = sv  # as in _cw_sat_row
        stray = True
    sv[r1] = 0
    ss[r1] = 0.0
    sv[r2] = 0
    ss[r2] = 0.0
    rv = np.int32(0)
    rs = 0.0
    rv2 = np.int32(0)
    rs2 = 0.0
    for x in range(w):
        ux = U(x)
        rv += np.int32(mrow[ux])
        rs += frow[ux]
        rv2 += np.int32(mrow2[ux])
        rs2 += frow2[ux]
        sv[r1 + ux + U(1)] = rv
        ss[r1 + ux + U(1)] = rs
        sv[r2 + ux + U(1)] = rv2
        ss[r2 + ux + U(1)] = rs2
    _cw_col_add(sv, ss, r0, r1, w)
    _cw_col_add(sv, ss, r1, r2, w)
    if stray:
        _cw_dot_row(of, p0, w, sd, r0, r1)
        _cw_dot_row(of, p1, w, sd, r1, r2)
    return stray


@numba.njit(cache=True, nogil=True)
def _cw_finish_row(yf, b, w, big, na, key, lo, hi, dacc, sacc, outf, okf,
                   srcf):  # pragma: no cover
    """Write image row yf from splat-key buffer row b (only its touched x range); a
    non-empty ``srcf`` gets the flat index of each splatted pixel's dot."""
    base = U(b * w)
    p0 = U(yf) * U(w)
    mask = (U(1) << U(40)) - U(1)
    ub = U(big)
    una = U(na)
    want = srcf.size > 0
    for x in range(lo[b], hi[b] + 1):
        kk = key[base + U(x)]
        # low bits = big - (index of the dot in dacc); no splat: key 0 -> dacc[na] = 0
        i = min(ub - (kk & mask), una)
        outf[p0 + U(x)] = dacc[i]
        okf[p0 + U(x)] = np.uint8(kk != U(0))
        if want and kk != U(0):
            srcf[p0 + U(x)] = sacc[i]


def correlation_window(d: np.ndarray, valid: np.ndarray, dots: np.ndarray, half: int,
                       frac: float, inlier_px: float, splat_r: float,
                       want_source: bool = False
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernel :func:`_correlation_window` on C-ordered copies of the images (no
    copy when they already are): numba compiles a kernel once per array layout, ~12 s
    each on this machine, and a strided view or a transpose would be another layout."""
    return _correlation_window(np.ascontiguousarray(d), np.ascontiguousarray(valid),
                               np.ascontiguousarray(dots), half, frac, inlier_px, splat_r,
                               want_source)


@numba.njit(cache=True, nogil=True)
def _correlation_window(d, valid, dots, half, frac, inlier_px, splat_r,
                        want_source=False):  # pragma: no cover
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
    pixel). Pixels no accepted dot reaches are holes. Returns (d_out, valid_out, source);
    d_out is 0 where valid_out is False; with ``want_source``, source is the flat (raster)
    index of the dot whose disparity each pixel took (a pixel no dot reached: its own), so
    that what the sensor reports at a pixel can carry that dot's ids and incidence (empty
    without).

    The window sum of disparities is a float64 summed-area table: per row the running sum
    of d over the valid dots left to right, added to the table row above. The mean is
    (S[y1, x1] - S[y0, x1] - S[y1, x0] + S[y0, x0]) / n_valid in that order, so it is the
    same number whatever the implementation (tests/sensor/test_correlation_window.py
    holds a plain reference). Counts come from int32 tables; the table of all dots is
    built only from the first row with a dot off the valid pixels (above it, it equals
    the valid-dot table; the shipped stage computes dots on valid pixels only). The
    inlier scan reads the window a row at a time and stops once the verdict is certain
    (it depends only on the total count, so when to check is free). A pixel keeps the
    largest splat key (255 - r^2) << 40 | (H W - k), k the dot's position in raster
    order: the max is order-free and branch-free and picks what raster-order
    strict-greater updates keep. The rows stream: the tables live in a ring of
    2 half + 3 rows and the keys in a buffer of 32 + 2 floor(splat_r) rows, so nothing
    image-sized is allocated but the outputs (fresh pages cost a page fault each, once a
    third of the time). Indices are unsigned so that numba emits no negative-index
    wraparound in the inner loops.
    """
    h, w = d.shape
    r = int(np.floor(splat_r))
    r2max = splat_r * splat_r
    if r2max > 254.0:
        raise ValueError("correlation_window: splat radius above sqrt(254) px (15.9)")
    stray = False  # set on the first dot off the valid pixels
    df = d.reshape(-1)
    db = df.view(np.uint64)
    vf = valid.reshape(-1).view(np.uint8)
    of = dots.reshape(-1).view(np.uint8)
    n = 2 * half + 1
    un = U(n)
    thr = np.empty(n * n)
    for j in range(-half, half + 1):
        for i in range(-half, half + 1):
            t = U((j + half) * n + i + half)
            if i == 0 and j == 0:
                thr[t] = inlier_px
            else:
                thr[t] = inlier_px * ((1.2 * i) ** 2 + (1.2 * j) ** 2)
    # summed-area tables: a ring of rows, n + 1 are all that a window needs
    R = n + 2  # rows are built in pairs, so one may be built ahead
    W = U(w + 1)
    sv = np.zeros(R * (w + 1), dtype=np.int32)
    ss = np.zeros(R * (w + 1))
    sd = np.zeros(R * (w + 1), dtype=np.int32)
    mrow = np.empty(w, dtype=np.uint8)
    brow = np.empty(w, dtype=np.uint64)
    frow = brow.view(np.float64)
    mrow2 = np.empty(w, dtype=np.uint8)
    brow2 = np.empty(w, dtype=np.uint64)
    frow2 = brow2.view(np.float64)
    cx = np.empty(w, dtype=np.int64)
    # splat footprint: offsets (flat in the key buffer, width w) and rank << 40
    m = 0
    for j in range(-r, r + 1):
        for i in range(-r, r + 1):
            if i * i + j * j <= r2max:
                m += 1
    oy = np.empty(m, dtype=np.int64)
    ox = np.empty(m, dtype=np.int64)
    ofs = np.empty(m, dtype=np.int64)
    rk = np.empty(m, dtype=np.uint64)
    m = 0
    for j in range(-r, r + 1):
        for i in range(-r, r + 1):
            if i * i + j * j <= r2max:
                oy[m] = j
                ox[m] = i
                ofs[m] = j * w + i
                rk[m] = U(255 - (i * i + j * j)) << U(40)
                m += 1
    r = max(r, 0)  # splat_r < 0: no footprint, and the buffer geometry of r = 0
    # splat keys for image rows boff .. boff + BR - 1, B rows written out at a time
    B = 32
    BR = B + 2 * r
    key = np.zeros(BR * w, dtype=np.uint64)
    lo = np.full(BR, w, dtype=np.int64)
    hi = np.full(BR, -1, dtype=np.int64)
    boff = -r
    # disparities of the accepted dots, then a 0 that a key of 0 (no splat) points to
    dacc = np.empty(4096)
    dacc[0] = 0.0
    sacc = np.empty(4096, dtype=np.int64)  # the dots' flat indices, beside dacc
    big = h * w  # above any dot count
    na = 0
    out = np.zeros((h, w))
    ok = np.zeros((h, w), dtype=np.bool_)
    outf = out.reshape(-1)
    okf = ok.reshape(-1).view(np.uint8)
    src = np.arange(h * w) if want_source else np.empty(0, dtype=np.int64)
    built = 0  # SAT rows 0 .. built are in the ring
    for y in range(h):
        while built < min(y + half + 1, h):
            r0 = U(built % R) * W
            r1 = U((built + 1) % R) * W
            if built + 2 <= h:
                r2 = U((built + 2) % R) * W
                stray = _cw_sat_pair(db, vf, of, stray, built, w, sv, ss, sd, r0, r1, r2,
                                     mrow, brow, frow, mrow2, brow2, frow2)
                built += 2
            else:
                stray = _cw_sat_row(db, vf, of, stray, built, w, sv, ss, sd, r0, r1, mrow, brow,
                                    frow)
                built += 1
        if half <= y < h - half:
            p0 = U(y) * U(w)
            nc = 0
            for x in range(half, w - half):
                p = p0 + U(x)
                cx[nc] = x
                nc += np.int64(of[p] & vf[p])
            if na + nc + 1 > dacc.size:  # room for every candidate of the row
                grown = np.empty(max(2 * dacc.size, na + nc + 1))
                grown[:na + 1] = dacc[:na + 1]
                dacc = grown
                grown_s = np.empty(grown.size, dtype=np.int64)
                grown_s[:na] = sacc[:na]
                sacc = grown_s
            s0 = (y - half) % R
            a_row = U(s0) * W
            b_row = U((y + half + 1) % R) * W
            xmin = w
            xmax = -1
            for k in range(nc):
                x = cx[k]
                a0 = a_row + U(x - half)
                b0 = b_row + U(x - half)
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
                accepted = False
                # the verdict depends only on the total, so checking it after every row
                # is only for speed; before the middle row it rarely is certain
                for j in range(n):
                    row_inl = 0
                    if stray:
                        for i in range(n):
                            p = rb + U(i)
                            inlier = abs(df[p] - mean) < thr[tb + U(i)]
                            row_inl += 1 if of[p] & vf[p] & inlier else 0
                    else:
                        for i in range(n):
                            p = rb + U(i)
                            inlier = abs(df[p] - mean) < thr[tb + U(i)]
                            row_inl += np.int64(of[p] & np.uint8(inlier))
                    inl += row_inl
                    rb += U(w)
                    tb += un
                    if j < half:
                        continue
                    if inl > need:
                        accepted = True
                        break
                    sj = s0 + j + 1
                    sj = sj - R if sj >= R else sj
                    ra = U(sj) * W + U(x - half)
                    left = n_valid - (sv[ra + un] - sv[ra] - top)
                    if inl + left <= need:
                        break
                if not accepted:
                    continue
                dacc[na] = df[p0 + U(x)]
                sacc[na] = np.int64(p0 + U(x))
                low = U(big - na)
                na += 1
                dacc[na] = 0.0
                xmin = min(xmin, x)
                xmax = max(xmax, x)
                if r <= y < h - r and r <= x < w - r:
                    pc = (y - boff) * w + x
                    for q in range(m):
                        pq = U(pc + ofs[U(q)])
                        key[pq] = max(key[pq], rk[U(q)] | low)
                else:
                    for q in range(m):
                        yy = y + oy[q]
                        xx = x + ox[q]
                        if 0 <= yy < h and 0 <= xx < w:
                            pq = U((yy - boff) * w + xx)
                            key[pq] = max(key[pq], rk[U(q)] | low)
            if xmin <= xmax:
                for yy in range(y - r - boff, y + r + 1 - boff):
                    lo[yy] = min(lo[yy], max(xmin - r, 0))
                    hi[yy] = max(hi[yy], min(xmax + r, w - 1))
        # rows up to y - r can get no more splats: write out a block, shift the buffer
        if y - r == boff + B - 1:
            for b in range(B):
                if boff + b >= 0:
                    _cw_finish_row(boff + b, b, w, big, na, key, lo, hi, dacc, sacc, outf, okf,
                                   src)
            key[:2 * r * w] = key[B * w:]
            key[2 * r * w:] = 0
            lo[:2 * r] = lo[B:]
            hi[:2 * r] = hi[B:]
            lo[2 * r:] = w
            hi[2 * r:] = -1
            boff += B
    for yf in range(max(boff, 0), h):
        _cw_finish_row(yf, yf - boff, w, big, na, key, lo, hi, dacc, sacc, outf, okf, src)
    return out, ok, src


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
def gather_state(idx, z, valid, incidence, labels):  # pragma: no cover
    """z, valid, incidence, labels re-sampled at flat source indices ``idx`` (incidence
    and labels may be empty arrays when absent). One loop per array: a fused loop over all
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
    return (z2.reshape(h, w), v2.reshape(h, w), gather_if_present(idx, incidence, h * w),
            gather_if_present(idx, labels, h * w))


@numba.njit(cache=True, nogil=True)
def gather_if_present(idx, a, n):  # pragma: no cover
    """a (n values, any shape) re-sampled at ``idx``, flat; an absent (empty) ``a`` is
    returned as it is."""
    af = a.reshape(-1)
    if a.size != n:
        return af
    out = np.empty(n, dtype=a.dtype)
    for i in range(n):
        out[i] = af[idx[i]]
    return out


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
def dropout_inplace(z, valid, incidence, ray_norm, cos_min, r_max, hole):  # pragma: no cover
    """Grazing (incidence |cos| < cos_min) or too far for the albedo (range > r_max) valid
    pixels become invalid, get 0 in ``z`` and are marked in ``hole``, in one pass. Returns
    how many were removed."""
    h, w = z.shape
    n = 0
    for y in range(h):
        for x in range(w):
            if valid[y, x]:
                if incidence[y, x] < cos_min or z[y, x] * ray_norm[y, x] > r_max:
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
