"""Compiled screening of an item's placement candidates (numba): the first that fits.

:func:`vhgen.scene.clutter.place._first_fit_reference` screens an item's candidates as
NumPy arrays, every test on every candidate, some 150-230 small array operations an
item whose cost is their calls, not their data. :func:`first_fit` runs the same tests
candidate by candidate, in drawing order, and stops at the first that passes every one,
so most candidates are never looked at. The tests and their order are the reference's
(see :mod:`vhgen.scene.clutter.place`):

1. each footprint inside the room lies inside it (``least`` from every wall) and its
   nearest point at least ``min_range`` from the camera;
2. at least ``visible_share`` of the bearings of the item's inside footprints lie inside
   the camera's horizontal view;
3. each footprint is apart from every obstacle whose height range it shares and whose
   box, widened by the obstacle's gap, it overlaps (the separating-axis test);
4. where the item has footprints that hide people and there are people: every person
   keeps ``min_visible`` of their width in view; only the first ``tries`` candidates
   that pass tests 1-3 are tried.

The footprints turned onto a candidate are the reference's values bit for bit (the same
products and sums, no fused multiply-adds); sums over corners and ``atan2`` may differ
from NumPy's by an ulp, which moves no decision unless a value lies within an ulp of its
threshold (the tests compare the two on thousands of items). Kept out of ``place`` so
that importing the scene modules compiles no numba code until clutter is placed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from vhgen.scene.placement_kernels import wrap as _wrap

# the most values NumPy sums with one set of eight running sums (its PW_BLOCKSIZE); a
# frame's wall cells (4 x WALL_CELLS) must not exceed it
PAIRWISE_MAX = 128


@numba.njit(cache=True)
def _distance(ex, ez, poly, n):
    """The distance from (ex, ez) to the convex polygon poly[:n] (0 inside)."""
    best = math.inf
    pos = True
    neg = True
    for i in range(n):
        ax, az = poly[i, 0], poly[i, 1]
        j = i + 1 if i + 1 < n else 0
        abx, abz = poly[j, 0] - ax, poly[j, 1] - az
        eax, eaz = ex - ax, ez - az
        t = (eax * abx + eaz * abz) / max(abx * abx + abz * abz, 1e-18)
        t = min(max(t, 0.0), 1.0)
        qx = ax + t * abx - ex
        qz = az + t * abz - ez
        best = min(best, math.sqrt(qx * qx + qz * qz))
        cross = abx * eaz - abz * eax
        pos = pos and cross >= 0
        neg = neg and cross <= 0
    return 0.0 if pos or neg else best


@numba.njit(cache=True)
def _extent(poly, n, bx, bz):
    """The least and greatest projection of poly[:n] on (bx, bz)."""
    lo = math.inf
    hi = -math.inf
    for i in range(n):
        v = poly[i, 0] * bx + poly[i, 1] * bz
        lo = min(lo, v)
        hi = max(hi, v)
    return lo, hi


@numba.njit(cache=True)
def _separated(a, na, b, b_normals, gap):
    """Polygon a[:na] at least ``gap`` from polygon b (its DISC_SIDES corners, padded) of
    unit edge normals ``b_normals`` (zero: a repeated corner) along one of both
    polygons' edge normals."""
    nb = b.shape[0]
    for i in range(na + nb):
        if i < na:
            j = i + 1 if i + 1 < na else 0
            nx = a[j, 1] - a[i, 1]
            nz = -(a[j, 0] - a[i, 0])
            length = max(math.sqrt(nx * nx + nz * nz), 1e-12)
            ax, az = nx / length, nz / length
        else:
            ax, az = b_normals[i - na, 0], b_normals[i - na, 1]
        if ax == 0 and az == 0:
            continue
        lo_a, hi_a = _extent(a, na, ax, az)
        lo_b, hi_b = _extent(b, nb, ax, az)
        if lo_a - hi_b >= gap or lo_b - hi_a >= gap:
            return True
    return False


@numba.njit(cache=True)
def _keeps_people(turned, npts, tall, ranges, ex, ez, samples, dist, covered, min_visible):
    """Every person keeps ``min_visible`` of their width past what hides them already
    (``covered``) and the candidate's tall footprints."""
    people, m = covered.shape
    cover = covered.copy()
    for j in range(turned.shape[0]):
        if not tall[j]:
            continue
        n = npts[j]
        sx = 0.0
        sz = 0.0
        for i in range(n):
            sx += turned[j, i, 0] - ex
            sz += turned[j, i, 1] - ez
        mid = math.atan2(sx / n, sz / n)
        lo = math.inf
        hi = -math.inf
        for i in range(n):
            a = _wrap(math.atan2(turned[j, i, 0] - ex, turned[j, i, 1] - ez) - mid)
            lo = min(lo, a)
            hi = max(hi, a)
        for p in range(people):
            if not ranges[j] < dist[p]:
                continue
            for s in range(m):
                rel = _wrap(samples[p, s] - mid)
                if rel >= lo and rel <= hi:
                    cover[p, s] = True
    for p in range(people):
        hidden = 0
        for s in range(m):
            hidden += cover[p, s]
        if not 1.0 - hidden / m >= min_visible:
            return False
    return True


@numba.njit(cache=True)
def first_fit(cos, sin, origin, least, pts, npts, y0, y1, inside, tall, planes, eye, base,
              half_fov, min_range, visible_share, tries, ob_polys, ob_normals, ob_boxes,
              ob_heights, ob_gaps, samples, dist, covered, min_visible, ranges):
    """The index of the first candidate that passes every test (module docstring), or -1.

    cos, sin (K,): of the candidates' yaws; origin (K, 2); least (K,): the clearance each
    must keep from the walls; pts (S, P, 2) the item's footprints in its own frame, the
    first npts[j] corners of each; y0, y1, inside, tall (S,): their heights, whether each
    must lie inside the room and whether it hides people; planes (3, 4): [x, z, 1] @
    planes is the signed distance to each wall; eye (2,), base (the bearing the camera
    looks along), half_fov; the obstacles' padded polygons (M, Q, 2), edge normals
    (M, Q, 2), boxes (M, 4), heights (M, 2) and gaps (M,); the people's bearing samples
    (N, B), distances (N,) and which samples are hidden already (N, B). ``ranges`` (S,)
    receives the chosen candidate's distance of each inside footprint from the camera.
    """
    k_all = cos.shape[0]
    s_all = pts.shape[0]
    ex, ez = eye[0], eye[1]
    turned = np.empty((s_all, pts.shape[1], 2))
    near = np.empty(s_all)
    check_people = samples.shape[0] > 0 and tall.any()
    passed = 0
    for k in range(k_all):
        c, s = cos[k], sin[k]
        ox, oz = origin[k, 0], origin[k, 1]
        for j in range(s_all):
            for i in range(npts[j]):
                x, z = pts[j, i, 0], pts[j, i, 1]
                turned[j, i, 0] = c * x + s * z + ox
                turned[j, i, 1] = -s * x + c * z + oz
        # 1. inside the room, clear of the walls, far enough from the camera
        ok = True
        for j in range(s_all):
            if not inside[j]:
                continue
            clear = math.inf
            for i in range(npts[j]):
                for w in range(planes.shape[1]):
                    clear = min(clear, turned[j, i, 0] * planes[0, w]
                                + turned[j, i, 1] * planes[1, w] + planes[2, w])
            near[j] = _distance(ex, ez, turned[j], npts[j])
            if not (clear >= least[k] and near[j] >= min_range):
                ok = False
                break
        if not ok:
            continue
        # 2. enough of its bearings in the horizontal view
        sx = 0.0
        sz = 0.0
        count = 0
        for j in range(s_all):
            if inside[j]:
                for i in range(npts[j]):
                    sx += turned[j, i, 0] - ex
                    sz += turned[j, i, 1] - ez
                    count += 1
        mid = _wrap(math.atan2(sx / count, sz / count) - base)
        lo = math.inf
        hi = -math.inf
        for j in range(s_all):
            if inside[j]:
                for i in range(npts[j]):
                    b = _wrap(math.atan2(turned[j, i, 0] - ex, turned[j, i, 1] - ez) - base)
                    rel = _wrap(b - mid)
                    lo = min(lo, rel)
                    hi = max(hi, rel)
        lo, hi = mid + lo, mid + hi
        seen = min(hi, half_fov) - max(lo, -half_fov)
        if not seen >= visible_share * max(hi - lo, 1e-9):
            continue
        # 3. apart from every obstacle
        for j in range(s_all):
            n = npts[j]
            lox = loz = math.inf
            hix = hiz = -math.inf
            for i in range(n):
                lox = min(lox, turned[j, i, 0])
                hix = max(hix, turned[j, i, 0])
                loz = min(loz, turned[j, i, 1])
                hiz = max(hiz, turned[j, i, 1])
            for m in range(ob_polys.shape[0]):
                if not (ob_heights[m, 0] < y1[j] and ob_heights[m, 1] > y0[j]):
                    continue
                g = ob_gaps[m]
                if (lox < ob_boxes[m, 2] + g and ob_boxes[m, 0] < hix + g
                        and loz < ob_boxes[m, 3] + g and ob_boxes[m, 1] < hiz + g
                        and not _separated(turned[j], n, ob_polys[m], ob_normals[m], g)):
                    ok = False
                    break
            if not ok:
                break
        if not ok:
            continue
        # 4. the people stay visible: the first ``tries`` candidates left
        if check_people:
            passed += 1
            if passed > tries:
                return -1
            if not _keeps_people(turned, npts, tall, near, ex, ez, samples, dist, covered,
                                 min_visible):
                continue
        for j in range(s_all):
            ranges[j] = near[j] if inside[j] else 0.0
        return k
    return -1


@numba.njit(cache=True)
def _pairwise_sum(a):
    """NumPy's float64 sum of ``a`` (at most :data:`PAIRWISE_MAX` values: its pairwise
    summation keeps eight running sums up to that many), bit for bit."""
    n = a.shape[0]
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return res
    r = np.empty(8)
    for j in range(8):
        r[j] = a[j]
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += a[i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[i]
        i += 1
    return res


@numba.njit(cache=True)
def _right_of(cdf, v):
    """np.searchsorted(cdf, v, side="right") for a non-decreasing cdf."""
    lo, hi = 0, cdf.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if cdf[mid] <= v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def _wall_cdf(width, depth, y0, y1, seen_weight, cells, wall_n, wall_off, wall_e,
              wall_start, ob_polys, ob_heights, ob_gaps, cdf):
    """The reference's ``_Frame.wall_cdf`` into ``cdf`` (4 * C,); False when no wall cell
    is free (the reference's None)."""
    walls, c_all = seen_weight.shape
    weight = seen_weight.copy()
    for w in range(walls):
        for m in range(ob_polys.shape[0]):
            if not (ob_heights[m, 0] < y1 and ob_heights[m, 1] > y0):
                continue
            g = ob_gaps[m]
            near = math.inf
            a_lo = math.inf
            a_hi = -math.inf
            for i in range(ob_polys.shape[1]):
                x, z = ob_polys[m, i, 0], ob_polys[m, i, 1]
                near = min(near, x * wall_n[w, 0] + z * wall_n[w, 1] - wall_off[w])
                along = x * wall_e[w, 0] + z * wall_e[w, 1] - wall_start[w]
                a_lo = min(a_lo, along)
                a_hi = max(a_hi, along)
            if not near < depth + g:
                continue
            s0, s1 = a_lo - g, a_hi + g
            for c in range(c_all):
                if s0 < cells[w, c + 1] + width / 2 and s1 > cells[w, c] - width / 2:
                    weight[w, c] = 0.0
    flat = weight.ravel()
    total = _pairwise_sum(flat)
    if total <= 0:
        return False
    run = 0.0
    for i in range(flat.shape[0]):
        run += flat[i]
        cdf[i] = run / total
    return True


@numba.njit(cache=True)
def candidates(u, mode_cdf, mode_places, x0, x1, depth, y0, y1, centre, fyaw, fcos, fsin,
               bsin, bcos, seen_weight, cells, lengths, wall_a, wall_e, wall_n, wall_off,
               wall_start, wall_yaw, wall_sign, wall_flush, eye, ob_polys, ob_heights,
               ob_gaps, corner_gap, min_range, reach, nowhere, corner_mode, floor_mode,
               yaw, origin, mode, wall, ok):
    """The reference's ``_candidates`` into yaw (K,), origin (K, 2), mode, wall (K,)
    int64 and ok (K,) bool, bit for bit: the same products, sums and comparisons in the
    same order. u (K, 5): the draws; the floor spots' sines and cosines come in computed
    by NumPy (fyaw, fcos, fsin: the headings u[:, 4] * 2 pi and theirs; bsin, bcos: of
    the bearings); the item's extent along the wall x0..x1, its depth from the wall and
    heights y0..y1, its footprints' centre (2,); the frame's walls, cells and obstacles.
    """
    walls, c_all = seen_weight.shape
    cdf = np.empty(walls * c_all)
    free = _wall_cdf(x1 - x0, depth, y0, y1, seen_weight, cells, wall_n, wall_off, wall_e,
                     wall_start, ob_polys, ob_heights, ob_gaps, cdf)
    if not free:  # no free wall in view: only floor spots can work
        flat = seen_weight.ravel()
        total = _pairwise_sum(flat)
        run = 0.0
        for i in range(flat.shape[0]):
            run += flat[i]
            cdf[i] = run / total
    for k in range(u.shape[0]):
        mode[k] = min(_right_of(mode_cdf, u[k, 0]), mode_cdf.shape[0] - 1)
        place = mode_places[mode[k]]
        if not free and place != floor_mode:
            place = nowhere
        cell = min(_right_of(cdf, u[k, 1]), walls * c_all - 1)
        w = cell // c_all
        cell = cell % c_all
        length = lengths[w]
        spot = (cell + u[k, 2]) / c_all * length
        sign = wall_sign[w]
        off0, off1 = sign * x0, sign * x1
        lo_off, hi_off = min(off0, off1), max(off0, off1)
        s_lo = corner_gap - lo_off
        s_hi = length - corner_gap - hi_off
        s = min(max(spot - (lo_off + hi_off) / 2, s_lo), s_hi)
        if place == corner_mode:
            s = s_lo if spot < length / 2 else s_hi
        yaw[k] = wall_yaw[w]
        origin[k, 0] = wall_a[w, 0] + s * wall_e[w, 0] + wall_flush[w, 0]
        origin[k, 1] = wall_a[w, 1] + s * wall_e[w, 1] + wall_flush[w, 1]
        wall[k] = w
        ok[k] = s_hi >= s_lo and place != nowhere
        if place == floor_mode:
            dist = min_range + u[k, 3] * (reach - min_range)
            c, s = fcos[k], fsin[k]
            origin[k, 0] = eye[0] + dist * bsin[k] - (c * centre[0] + s * centre[1])
            origin[k, 1] = eye[1] + dist * bcos[k] - (-s * centre[0] + c * centre[1])
            yaw[k] = fyaw[k]
            wall[k] = -1
            ok[k] = True


def warm() -> None:
    """Load (or compile) :func:`candidates` and :func:`first_fit` for the argument types
    placement passes (the item's footprint table read-only, everything else writable), so
    that a worker does it in its set-up, not in its first frame."""
    def frozen(a: np.ndarray) -> np.ndarray:
        a.setflags(write=False)
        return a

    k, one, two, walls = 2, np.zeros(2), np.zeros((2, 2)), np.ones((4, 2))
    no_polys, no_heights, no_gaps = np.zeros((0, 8, 2)), np.zeros((0, 2)), np.zeros(0)
    candidates(np.full((k, 5), 0.5), np.ones(1), np.zeros(1, np.int64), 0.0, 0.5, 0.3,
               0.0, 1.0, np.zeros(2), one, one, one, one, one, np.ones((4, 32)),
               np.ones((4, 33)), np.ones(4), walls, walls, walls, np.zeros(4), np.zeros(4),
               np.zeros(4), np.ones(4), walls, np.zeros(2), no_polys, no_heights, no_gaps,
               0.01, 1.0, 7.0, -1, 1, 2, np.empty(k), np.empty((k, 2)),
               np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k, bool))
    first_fit(one, one, two, one, frozen(np.zeros((1, 4, 2))), frozen(np.full(1, 4)),
              frozen(np.zeros(1)), frozen(np.ones(1)), frozen(np.ones(1, bool)),
              np.zeros(1, bool), np.zeros((3, 4)), np.zeros(2), 0.0, 1.0, 1.0, 0.3, 30,
              no_polys, np.zeros((0, 8, 2)), np.zeros((0, 4)), no_heights, no_gaps,
              np.zeros((0, 64)), np.zeros(0), np.zeros((0, 64), bool), 0.5, np.zeros(1))
