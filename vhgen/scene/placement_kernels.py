"""Compiled visibility of people on the floor plan (numba), for placement's accept tests.

:func:`vhgen.scene.placement.visible_fraction` is the reference: the share of a target
disc's angular width, seen from the camera, that no nearer disc covers, over 64 bearings.
Placing a person or a tall prop asks it of every person for every candidate spot, a few
thousand small NumPy calls a frame. :func:`all_visible` answers the whole question for
one candidate in one call, with the reference's arithmetic: the same bearings (NumPy's
``linspace``: i * step + start, the last one the end itself) and the same comparisons;
each difference of bearings is wrapped by a remainder, not as ``np.angle(np.exp(1j *
x))`` (a complex exponential and an ``atan2`` a sample), which may differ by an ulp and
moves no decision unless a bearing sits on an occluder's edge (tests compare the two).
:func:`visible_with` does the same for :func:`vhgen.scene.solids.visible_fraction_with`
(discs and convex polygons in front of a target), which a shared layout asks of every
person for every spot it tries. Kept out of :mod:`vhgen.scene.placement` so that
importing it compiles nothing.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def wrap(a):
    """An angle (radians) wrapped to [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


@numba.njit(cache=True)
def _bearings(tc, th, samples):
    """tc + np.linspace(-th, th, samples), with NumPy's arithmetic."""
    angles = np.empty(samples)
    start, stop = -th, th
    div = samples - 1
    step = (stop - start) / div
    for i in range(div):
        angles[i] = tc + ((i * step if step != 0 else i / div * (stop - start)) + start)
    angles[div] = tc + stop
    return angles


@numba.njit(cache=True)
def _cover_discs(ex, ez, tdist, angles, discs, skip, covered):
    """Mark the bearings that a disc nearer than the target (rows x, z, r; not row
    ``skip``) covers."""
    for o in range(discs.shape[0]):
        if o == skip:
            continue
        ox, oz = discs[o, 0] - ex, discs[o, 1] - ez
        odist = math.hypot(ox, oz)
        if odist >= tdist:
            continue
        oh = math.asin(min(1.0, discs[o, 2] / max(odist, 1e-9)))
        oc = math.atan2(ox, oz)
        for i in range(angles.shape[0]):
            # the difference wrapped (the reference: to (-pi, pi], by atan2)
            if abs(wrap(angles[i] - oc)) <= oh:
                covered[i] = True


@numba.njit(cache=True)
def _share(covered):
    hidden = 0
    for i in range(covered.shape[0]):
        hidden += covered[i]
    return 1.0 - hidden / covered.shape[0]


@numba.njit(cache=True)
def _visible(ex, ez, discs, t, samples):
    """visible_fraction of discs[t] past every other disc (rows x, z, r)."""
    dx, dz = discs[t, 0] - ex, discs[t, 1] - ez
    tdist = math.hypot(dx, dz)
    th = math.asin(min(1.0, discs[t, 2] / max(tdist, 1e-9)))
    tc = math.atan2(dx, dz)
    angles = _bearings(tc, th, samples)
    covered = np.zeros(samples, np.bool_)
    _cover_discs(ex, ez, tdist, angles, discs, t, covered)
    return _share(covered)


@numba.njit(cache=True)
def _nearest(ex, ez, verts, a0, a1):
    """:func:`vhgen.scene.solids.nearest_distance` from (ex, ez) to the convex polygon
    verts[a0:a1]."""
    best = np.inf
    n = a1 - a0
    for k in range(n):
        ax, az = verts[a0 + k, 0], verts[a0 + k, 1]
        bx, bz = verts[a0 + (k + 1) % n, 0], verts[a0 + (k + 1) % n, 1]
        abx, abz = bx - ax, bz - az
        t = ((ex - ax) * abx + (ez - az) * abz) / max(abx * abx + abz * abz, 1e-18)
        t = min(max(t, 0.0), 1.0)
        best = min(best, math.hypot(ax + t * abx - ex, az + t * abz - ez))
    return best


@numba.njit(cache=True)
def visible_with(ex, ez, tx, tz, tr, discs, verts, starts, samples):
    """:func:`vhgen.scene.solids.visible_fraction_with` (the reference) in one call: the
    share of the target disc (tx, tz, tr) seen from (ex, ez) past the discs (N, 3) and
    the convex polygons ``verts[starts[p]:starts[p + 1]]`` nearer than its centre."""
    dx, dz = tx - ex, tz - ez
    tdist = math.hypot(dx, dz)
    tc = math.atan2(dx, dz)
    th = math.asin(min(1.0, tr / max(tdist, 1e-9)))
    angles = _bearings(tc, th, samples)
    covered = np.zeros(samples, np.bool_)
    _cover_discs(ex, ez, tdist, angles, discs, -1, covered)
    for p in range(starts.shape[0] - 1):
        a0, a1 = starts[p], starts[p + 1]
        if _nearest(ex, ez, verts, a0, a1) >= tdist:
            continue
        # solids.angular_span: the bearings about the polygon's own centre
        cx, cz = 0.0, 0.0
        for k in range(a0, a1):
            cx += verts[k, 0] - ex
            cz += verts[k, 1] - ez
        mid = math.atan2(cx / (a1 - a0), cz / (a1 - a0))
        lo, hi = np.inf, -np.inf
        for k in range(a0, a1):
            a = wrap(math.atan2(verts[k, 0] - ex, verts[k, 1] - ez) - mid)
            lo, hi = min(lo, a), max(hi, a)
        rel = wrap(mid - tc)
        lo, hi = rel + lo, rel + hi
        for i in range(samples):
            r = angles[i] - tc
            if lo <= r <= hi:
                covered[i] = True
    return _share(covered)


@numba.njit(cache=True)
def all_visible(ex, ez, discs, targets, min_visible, samples):
    """Whether each of the first ``targets`` discs (rows x, z, r of ``discs`` (N, 3))
    keeps at least ``min_visible`` of its width past all the other discs."""
    for t in range(targets):
        if not _visible(ex, ez, discs, t, samples) >= min_visible:
            return False
    return True


def warm() -> None:
    """Load (or compile) :func:`all_visible` and :func:`visible_with` for the types
    placement passes."""
    all_visible(0.0, 0.0, np.array([[0.0, 2.0, 0.3], [0.1, 1.5, 0.3]]), 1, 0.5, 64)
    visible_with(0.0, 0.0, 0.0, 2.0, 0.3, np.array([[0.1, 1.5, 0.3]]),
                 np.array([[0.0, 1.0], [0.2, 1.0], [0.2, 1.2]]), np.array([0, 3]), 64)
