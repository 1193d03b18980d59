"""The compiled correlation window equals a plain reference, bit for bit.

The reference below follows the docstring of ``sensor_kernels.correlation_window`` literally:
pure Python/NumPy, no early exits, float weights instead of ranks, the whole window
scanned. Only the float64 window sum is taken from a summed-area table built in the
documented order (row running sum, added to the row above), since that order is part of
the spec: a different summation order would give a different mean in the last bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from vhgen.sensor.sensor_kernels import correlation_window


def accepted_dots(d: np.ndarray, valid: np.ndarray, dots: np.ndarray, half: int,
                  frac: float, inlier_px: float) -> list[tuple[int, int]]:
    """(y, x) of the dots whose window passes, in raster order."""
    h, w = d.shape
    vd = valid & dots
    ss = np.zeros((h + 1, w + 1))
    for y in range(h):
        rs = 0.0
        for x in range(w):
            if vd[y, x]:
                rs += d[y, x]
            ss[y + 1, x + 1] = ss[y, x + 1] + rs
    accepted = []
    for y in range(half, h - half):
        for x in range(half, w - half):
            if not vd[y, x]:
                continue
            y0, y1, x0, x1 = y - half, y + half + 1, x - half, x + half + 1
            n_dots = int(dots[y0:y1, x0:x1].sum())
            n_valid = int(vd[y0:y1, x0:x1].sum())
            if n_valid <= frac * n_dots:
                continue
            mean = (ss[y1, x1] - ss[y0, x1] - ss[y1, x0] + ss[y0, x0]) / n_valid
            inliers = 0
            for j in range(-half, half + 1):
                for i in range(-half, half + 1):
                    wgt = 1.0 if i == 0 and j == 0 else 1.0 / ((1.2 * i) ** 2 + (1.2 * j) ** 2)
                    # |d - m| w < inlier_px, written as the kernel's exact threshold form
                    thr = inlier_px if i == 0 and j == 0 else inlier_px / wgt
                    if vd[y + j, x + i] and abs(d[y + j, x + i] - mean) < thr:
                        inliers += 1
            if inliers > frac * n_dots:
                accepted.append((y, x))
    return accepted


def reference(d: np.ndarray, valid: np.ndarray, dots: np.ndarray, half: int, frac: float,
              inlier_px: float, splat_r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(disparity, valid, source): source is the flat index of the dot each pixel took
    its disparity from, the pixel's own where no dot reached it."""
    h, w = d.shape
    accepted = accepted_dots(d, valid, dots, half, frac, inlier_px)
    out = np.zeros((h, w))
    weight = np.zeros((h, w))
    source = np.arange(h * w).reshape(h, w)
    r = math.floor(splat_r)
    for y, x in accepted:  # raster order
        for j in range(-r, r + 1):
            for i in range(-r, r + 1):
                yy, xx = y + j, x + i
                if i * i + j * j <= splat_r * splat_r and 0 <= yy < h and 0 <= xx < w:
                    wt = 1.0 / (1.0 + i * i + j * j)
                    if wt > weight[yy, xx]:
                        weight[yy, xx] = wt
                        out[yy, xx] = d[y, x]
                        source[yy, xx] = y * w + x
    return out, weight > 0, source.reshape(-1)


def scene(rng: np.random.Generator, h: int, w: int, p_valid: float, p_dot: float,
          stray: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A tilted plane with a step and noise (so windows both pass and fail), random
    valid and dot masks; ``stray`` lets dots fall outside valid."""
    yy, xx = np.mgrid[0:h, 0:w]
    d = 20.0 + 0.03 * xx - 0.02 * yy + np.where(xx > w // 2, 1.5, 0.0)
    d = d + rng.normal(0.0, 0.05, (h, w))
    d[rng.random((h, w)) < 0.05] += rng.normal(0.0, 3.0)  # outliers
    valid = rng.random((h, w)) < p_valid
    dots = rng.random((h, w)) < p_dot
    if not stray:
        dots &= valid
    d[~valid] = rng.choice([0.0, np.nan, np.inf, -5.0], size=int((~valid).sum()))
    return d, valid, dots


def check(d: np.ndarray, valid: np.ndarray, dots: np.ndarray, half: int, frac: float,
          inlier_px: float, splat_r: float) -> tuple[np.ndarray, np.ndarray]:
    got_d, got_v, got_s = correlation_window(d, valid, dots, half, frac, inlier_px, splat_r,
                                             True)
    ref_d, ref_v, ref_s = reference(d, valid, dots, half, frac, inlier_px, splat_r)
    assert got_v.dtype == np.bool_ and got_d.dtype == np.float64
    np.testing.assert_array_equal(got_v, ref_v)
    assert got_d.tobytes() == ref_d.tobytes()  # bit-identical, including signed zeros
    np.testing.assert_array_equal(got_s, ref_s)  # the dot each pixel took, ties included
    # without the sources asked for: the same image, no index array
    no_d, no_v, no_s = correlation_window(d, valid, dots, half, frac, inlier_px, splat_r)
    assert no_d.tobytes() == got_d.tobytes() and (no_v == got_v).all() and no_s.size == 0
    return got_d, got_v


@pytest.mark.parametrize("stray", [False, True])
@pytest.mark.parametrize("half", [0, 1, 2, 4])
@pytest.mark.parametrize("seed", range(4))
def test_equals_reference_on_random_masks(stray: bool, half: int, seed: int) -> None:
    rng = np.random.default_rng(1000 * seed + 10 * half + stray)
    h, w = int(rng.integers(12, 30)), int(rng.integers(12, 40))
    d, valid, dots = scene(rng, h, w, p_valid=rng.uniform(0.4, 1.0),
                           p_dot=rng.uniform(0.15, 0.6), stray=stray)
    if stray:
        assert (dots & ~valid).any()
    check(d, valid, dots, half, 2 / 3, 0.1, 3.1)
    # the scene is meant to give both verdicts (a 1 x 1 window accepts every valid dot)
    inner = (valid & dots)[half:h - half, half:w - half].sum()
    n_acc = len(accepted_dots(d, valid, dots, half, 2 / 3, 0.1))
    assert 0 < n_acc and (n_acc < inner or half == 0)


@pytest.mark.parametrize("splat_r", [-2.0, -0.5, 0.0, 0.5, 1.0, 1.4142, 1.5, 2.0, 2.9, 3.0,
                                     3.1, 4.2, 15.9])
def test_splat_radius_edges(splat_r: float) -> None:
    rng = np.random.default_rng(7)
    d, valid, dots = scene(rng, 24, 31, p_valid=0.9, p_dot=0.3, stray=True)
    check(d, valid, dots, 2, 2 / 3, 0.1, splat_r)


def test_splat_radius_above_limit_is_an_error() -> None:
    rng = np.random.default_rng(8)
    d, valid, dots = scene(rng, 40, 40, p_valid=1.0, p_dot=0.3, stray=False)
    with pytest.raises(ValueError, match="splat radius"):
        correlation_window(d, valid, dots, 2, 2 / 3, 0.1, 16.0)


def test_dots_on_the_border_and_tiny_images() -> None:
    rng = np.random.default_rng(9)
    # every pixel a valid dot on a plane: all interior dots accepted; border dots never
    # start a window but their splats (and the border-clipped splats) must match
    h, w = 11, 13
    d = 20.0 + 0.01 * np.arange(w)[None, :] + np.zeros((h, 1))
    full = np.ones((h, w), dtype=bool)
    _, ok = check(d, full, full, 4, 2 / 3, 0.1, 3.1)
    # centres y 4..6, x 4..8 all pass; a pixel is reached iff it lies within 3.1 px of
    # that block of centres
    yy, xx = np.mgrid[0:h, 0:w]
    gy = np.clip(yy, 4, 6) - yy
    gx = np.clip(xx, 4, 8) - xx
    np.testing.assert_array_equal(ok, gy**2 + gx**2 <= 3.1**2)
    # images smaller than the window: no dot is far enough from the border
    for h, w in [(1, 1), (3, 5), (8, 8), (8, 20), (20, 8)]:
        d, valid, dots = scene(rng, h, w, 1.0, 0.5, stray=False)
        out, ok = check(d, valid, dots, 4, 2 / 3, 0.1, 3.1)
        assert not ok.any() and not out.any()


def test_ties_go_to_the_earlier_dot_and_frac_edges() -> None:
    rng = np.random.default_rng(11)
    # two dot values on alternating columns: equal-distance splats tie constantly
    h, w = 20, 24
    d = np.where(np.arange(w)[None, :] % 2 == 0, 20.0, 20.05) + np.zeros((h, 1))
    valid = np.ones((h, w), dtype=bool)
    dots = np.zeros((h, w), dtype=bool)
    dots[::2, ::3] = True
    dots[1::4, 1::5] = True
    for frac in [0.0, 0.5, 2 / 3, 0.99, 1.0]:
        for inlier_px in [0.0, 0.03, 0.1, 10.0]:
            check(d, valid, dots, 3, frac, inlier_px, 2.5)
    d2, valid2, dots2 = scene(rng, 25, 25, 0.7, 0.4, stray=True)
    for frac in [0.0, 0.3, 1.0]:
        check(d2, valid2, dots2, 2, frac, 0.1, 3.1)


def test_non_contiguous_inputs() -> None:
    rng = np.random.default_rng(12)
    d, valid, dots = scene(rng, 30, 44, 0.8, 0.3, stray=True)
    check(d[:, ::2], valid[:, ::2], dots[:, ::2], 2, 2 / 3, 0.1, 3.1)
    check(d.T, valid.T, dots.T, 2, 2 / 3, 0.1, 3.1)


@pytest.mark.parametrize(("h", "w", "half", "splat_r", "stray"), [
    (100, 17, 2, 3.1, False), (70, 23, 4, 15.9, True), (65, 12, 1, 0.0, False),
    (97, 30, 3, 2.0, True), (33, 9, 1, 1.0, False)])
def test_tall_images_cross_the_row_buffers(h: int, w: int, half: int, splat_r: float,
                                           stray: bool) -> None:
    # the kernel streams rows through a ring of tables and a 32-row splat buffer
    rng = np.random.default_rng(h * w)
    d, valid, dots = scene(rng, h, w, 0.8, 0.3, stray=stray)
    check(d, valid, dots, half, 2 / 3, 0.1, splat_r)


@pytest.mark.parametrize("row", [0, 1, 2, 20, 21, 38, 39])
def test_first_dot_off_valid_late_in_the_image(row: int) -> None:
    # the table of all dots starts at the first row with such a dot (rows are built in
    # pairs, so both parities matter)
    rng = np.random.default_rng(row)
    d, valid, dots = scene(rng, 40, 21, 0.85, 0.35, stray=False)
    x = int(rng.integers(0, 21))
    valid[row, x] = False
    dots[row, x] = True
    check(d, valid, dots, 2, 2 / 3, 0.1, 3.1)
    check(d, valid, dots, 4, 0.5, 0.2, 1.5)
