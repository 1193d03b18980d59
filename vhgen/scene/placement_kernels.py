"""Compiled visibility of people on the floor plan (numba), for placement's accept tests.

:func:`vhgen.scene.placement.visible_fraction` is the reference: the share of a target
disc's angular width, seen from the camera, that no nearer disc covers, over 64 bearings.
Placing a person or a tall prop asks it of every person for every candidate spot, a few
thousand small NumPy calls a frame. :func:`all_visible` answers the whole question for
one candidate in one call, with the reference's arithmetic: the same bearings (NumPy's
``linspace``: i * step + start, the last one the end itself) and the same comparisons;
each difference of bearings is wrapped by a remainder, not as ``np.angle(np.exp(1j *
x))`` (a complex exponential and an ``atan2`` a sample), which may differ by an ulp and
moves no decision unless a bearing sits on an occluder's edge (tests compare the two). Kept out of
:mod:`vhgen.scene.placement` so that importing it compiles nothing.
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
def _visible(ex, ez, discs, t, samples):
    """visible_fraction of discs[t] past every other disc (rows x, z, r)."""
    dx, dz = discs[t, 0] - ex, discs[t, 1] - ez
    tdist = math.hypot(dx, dz)
    th = math.asin(min(1.0, discs[t, 2] / max(tdist, 1e-9)))
    tc = math.atan2(dx, dz)
    # the bearings as np.linspace(-th, th, samples) spaces them, plus tc
    angles = np.empty(samples)
    start, stop = -th, th
    div = samples - 1
    step = (stop - start) / div
    for i in range(div):
        angles[i] = tc + ((i * step if step != 0 else i / div * (stop - start)) + start)
    angles[div] = tc + stop
    covered = np.zeros(samples, np.bool_)
    for o in range(discs.shape[0]):
        if o == t:
            continue
        ox, oz = discs[o, 0] - ex, discs[o, 1] - ez
        odist = math.hypot(ox, oz)
        if odist >= tdist:
            continue
        oh = math.asin(min(1.0, discs[o, 2] / max(odist, 1e-9)))
        oc = math.atan2(ox, oz)
        for i in range(samples):
            # the difference wrapped (the reference: to (-pi, pi], by atan2)
            if abs(wrap(angles[i] - oc)) <= oh:
                covered[i] = True
    hidden = 0
    for i in range(samples):
        hidden += covered[i]
    return 1.0 - hidden / samples


@numba.njit(cache=True)
def all_visible(ex, ez, discs, targets, min_visible, samples):
    """Whether each of the first ``targets`` discs (rows x, z, r of ``discs`` (N, 3))
    keeps at least ``min_visible`` of its width past all the other discs."""
    for t in range(targets):
        if not _visible(ex, ez, discs, t, samples) >= min_visible:
            return False
    return True


def warm() -> None:
    """Load (or compile) :func:`all_visible` for the types placement passes."""
    all_visible(0.0, 0.0, np.array([[0.0, 2.0, 0.3], [0.1, 1.5, 0.3]]), 1, 0.5, 64)
