"""Realism statistics of one depth frame: pure NumPy (scipy.ndimage inside one function).

Every statistic takes a depth image ``depth_mm`` (H, W) uint16 millimetres, 0 = no
measurement, and where geometry matters the focal length ``fx`` (px); it is computed the
same way on real frames and on vhgen frames. :func:`frame_stats` gathers all of them into
a :class:`FrameStats`; each field's docstring below is the statistic's definition (the
section "Real frames and realism" of docs/realism.md repeats them).

The nominal ``f b`` used only to *select* discontinuities is ``fx * NOMINAL_BASELINE_M``
(the Kinect's 7.5 cm): a jump is a discontinuity when it is at least ``MIN_JUMP_PX``
pixels of disparity at that nominal baseline.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

NOMINAL_BASELINE_M = 0.075
MIN_JUMP_PX = 3.0  # nominal disparity jump that makes a discontinuity
FLAT_PX = 3  # an edge needs this many valid pixels on each side, flat along the row
MAX_BAND_PX = 80  # a hole run wider than this beside an edge is not an edge band
SPECKLE_MAX_PX = 200  # a valid blob this small (surrounded by holes) is a speckle
PATCH_PX = 12  # planar patches: PATCH_PX x PATCH_PX tiles, all pixels valid
DEPTH_BIN_M = 0.25  # bins of the noise and quantisation curves
BORDER_QUANTILE = 5.0  # percentile of the leading invalid run that is the border band


@dataclass
class FrameStats:
    """The statistics of one frame (arrays are samples; see each helper)."""

    valid_fraction: float
    depth_m: np.ndarray  # valid depths (m), at most DEPTH_SAMPLES of them
    nearest_m: float  # 0.1th percentile of the valid depth (m); 0 when none
    farthest_m: float  # 99.9th percentile of the valid depth (m); 0 when none
    max_m: float  # the largest valid depth (m); 0 when none
    shadow_jump: np.ndarray  # 1/z_near - 1/z_far (1/m) of shadow-side edges
    shadow_width: np.ndarray  # hole run width (px) on the shadow side of those edges
    other_jump: np.ndarray  # the same on the other side of near objects
    other_width: np.ndarray
    hole_areas: np.ndarray  # px, 4-connected components of invalid pixels
    speckle_areas: np.ndarray  # px, valid components of at most SPECKLE_MAX_PX
    patch_depth_m: np.ndarray  # mean depth of each planar patch
    patch_sigma_mm: np.ndarray  # axial noise of each patch (plane-fit RMS, mm)
    patch_step_mm: np.ndarray  # quantisation step in each patch (mm; NaN if unknown)
    border_px: np.ndarray = field(default_factory=lambda: np.zeros(4))  # left right top bottom


DEPTH_SAMPLES = 20000


def valid_fraction(depth_mm: np.ndarray) -> float:
    """Fraction of pixels with a measurement (depth > 0)."""
    d = np.asarray(depth_mm)
    return float(np.count_nonzero(d)) / d.size if d.size else 0.0


def depth_samples(depth_mm: np.ndarray, n: int = DEPTH_SAMPLES) -> np.ndarray:
    """Valid depths in metres, an evenly strided subsample of at most ``n`` (float64):
    the depth histogram pools these over frames."""
    v = np.asarray(depth_mm).reshape(-1)
    v = v[v > 0]
    if v.size > n:
        v = v[:: int(np.ceil(v.size / n))]
    return v.astype(np.float64) / 1000.0


def valid_range(depth_mm: np.ndarray) -> tuple[float, float, float]:
    """(0.1th percentile, 99.9th percentile, maximum) of the valid depth in metres (zeros
    when none): the percentiles are the nearest and farthest depth the sensor delivers,
    not one stray pixel."""
    v = np.asarray(depth_mm)
    v = v[v > 0]
    if not v.size:
        return 0.0, 0.0, 0.0
    lo, hi = np.percentile(v, [0.1, 99.9])
    return float(lo) / 1000.0, float(hi) / 1000.0, float(v.max()) / 1000.0


def edge_runs(depth_mm: np.ndarray, fx: float) -> tuple[np.ndarray, ...]:
    """Hole runs beside depth discontinuities, along image rows.

    For every two valid pixels of a row with only holes between them (a run of width
    w >= 0 px, at most MAX_BAND_PX), whose inverse depths differ by a disparity of at least
    MIN_JUMP_PX at the nominal baseline, and each with FLAT_PX more valid pixels beyond it
    in the row whose disparity stays within 1 px of its own (a near-vertical edge between
    two surfaces, not a row grazing a near-horizontal edge): the jump 1/z_near - 1/z_far
    (1/m) and w. Edges whose far surface is on the left (image column smaller) are on the
    *shadow side*: a projector at +x (right of the camera, as on the Kinect) leaves a band of width
    f b (1/z_near - 1/z_far) px there. Edges with the far surface on the right are the
    *other side* (in a registered image, the band the IR camera did not see).
    Returns (shadow_jump, shadow_width, other_jump, other_width), float64 arrays.
    """
    d = np.asarray(depth_mm)
    rows, cols = np.nonzero(d)
    inv = 1000.0 / d[rows, cols].astype(np.float64)
    fbn = fx * NOMINAL_BASELINE_M
    n = len(rows)
    if n < 2 * FLAT_PX + 2:
        e = np.zeros(0)
        return e, e, e, e
    i = np.arange(FLAT_PX, n - FLAT_PX - 1)  # the pair (i, i + 1) of consecutive valid pixels
    j = i + 1
    width = cols[j] - cols[i] - 1
    a, b = inv[i], inv[j]  # left, right
    jump = np.abs(a - b)
    # both sides flat along the row for FLAT_PX more pixels: a near-vertical edge, not a
    # row grazing a near-horizontal one or a sloped surface
    flat = ((rows[i - FLAT_PX] == rows[j + FLAT_PX]) & (cols[i] - cols[i - FLAT_PX] == FLAT_PX)
            & (cols[j + FLAT_PX] - cols[j] == FLAT_PX)
            & (np.abs(inv[i - FLAT_PX] - a) * fbn < 1.0)
            & (np.abs(inv[j + FLAT_PX] - b) * fbn < 1.0))
    keep = flat & (width <= MAX_BAND_PX) & (jump * fbn >= MIN_JUMP_PX)
    shadow = keep & (a < b)  # left is farther (smaller 1/z)
    other = keep & (a > b)
    return (jump[shadow], width[shadow].astype(np.float64), jump[other],
            width[other].astype(np.float64))


def blob_areas(depth_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(hole areas, speckle areas) in px: 4-connected components of invalid pixels (every
    one, the border band included), and of valid pixels no larger than SPECKLE_MAX_PX
    (islands of measurement among holes)."""
    from scipy import ndimage

    valid = np.asarray(depth_mm) > 0
    four = ndimage.generate_binary_structure(2, 1)
    lab, n = ndimage.label(~valid, structure=four)
    holes = np.bincount(lab.reshape(-1), minlength=n + 1)[1:]
    lab, n = ndimage.label(valid, structure=four)
    areas = np.bincount(lab.reshape(-1), minlength=n + 1)[1:]
    return holes.astype(np.float64), areas[areas <= SPECKLE_MAX_PX].astype(np.float64)


def planar_patches(depth_mm: np.ndarray, fx: float,
                   patch: int = PATCH_PX) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Axial noise and quantisation step on planar patches.

    The image is cut into ``patch`` x ``patch`` tiles; a tile counts when every pixel is
    valid. Inverse depth of a plane is affine in (u, v), so 1/z = a u + b v + c is fitted
    by least squares (two passes, the second without residuals beyond 3 RMS); the tile's
    axial noise is the RMS of the depth residual z - 1/fit (mm, quantisation included,
    as a sensor delivers it). A tile is planar when its clipped fit keeps >= 90% of the
    pixels and its RMS is below 2% of its depth. The quantisation step is the median gap
    between consecutive distinct depth values of the tile (mm; NaN with fewer than three
    distinct values). Returns (mean depth m, noise mm, step mm) per planar tile.
    """
    d = np.asarray(depth_mm)
    h, w = d.shape
    th, tw = h // patch, w // patch
    t = d[:th * patch, :tw * patch].reshape(th, patch, tw, patch).swapaxes(1, 2).reshape(
        th * tw, patch * patch)
    full = (t > 0).all(1)
    t = t[full].astype(np.float64) / 1000.0
    if not len(t):
        return np.zeros(0), np.zeros(0), np.zeros(0)
    vv, uu = np.mgrid[0:patch, 0:patch].astype(np.float64)
    design = np.stack([uu.reshape(-1), vv.reshape(-1), np.ones(patch * patch)], -1)
    pinv = np.linalg.pinv(design)  # (3, P): the same design for every tile
    inv = 1.0 / t
    keep = np.ones_like(inv, bool)
    for _ in range(2):
        coef = np.einsum("kp,np->nk", pinv, inv) if keep.all() else _masked_fit(design, inv,
                                                                                keep)
        fit = coef @ design.T
        r = t - 1.0 / np.where(np.abs(fit) > 1e-9, fit, 1e-9)
        rms = np.sqrt(np.sum(np.where(keep, r * r, 0), 1) / np.maximum(keep.sum(1), 1))
        keep = np.abs(r) <= 3 * rms[:, None] + 1e-12
    zmean = t.mean(1)
    ok = (keep.mean(1) >= 0.9) & (rms < 0.02 * zmean)
    steps = np.full(len(t), np.nan)
    mm = np.rint(t * 1000.0)
    srt = np.sort(mm, 1)
    gaps = np.diff(srt, axis=1)
    for i in np.flatnonzero(ok):
        g = gaps[i][gaps[i] > 0]
        if len(g) >= 2:
            steps[i] = float(np.median(g))
    return zmean[ok], rms[ok] * 1000.0, steps[ok]


def _masked_fit(design: np.ndarray, y: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Per-row least squares of y ~ design restricted to ``keep`` (normal equations)."""
    wgt = keep.astype(np.float64)
    ata = np.einsum("np,pk,pl->nkl", wgt, design, design)
    aty = np.einsum("np,pk,np->nk", wgt, design, y)
    ata += np.eye(3) * 1e-12
    return np.linalg.solve(ata, aty[..., None])[..., 0]


def border_band(depth_mm: np.ndarray, quantile: float = BORDER_QUANTILE) -> np.ndarray:
    """Width (px) of the band without measurement along each border, (left, right, top,
    bottom) float64: per side, the ``quantile``-th percentile over rows (columns) of the
    run of invalid pixels that starts at that border, so a few rows whose scene is missing
    at the border do not widen it. A row with no valid pixel counts as the image width."""
    v = np.asarray(depth_mm) > 0

    def lead(m: np.ndarray) -> np.ndarray:
        first = np.argmax(m, 1)
        return np.where(m.any(1), first, m.shape[1]).astype(np.float64)

    sides = (lead(v), lead(v[:, ::-1]), lead(v.T), lead(v.T[:, ::-1]))
    return np.array([np.percentile(s, quantile) for s in sides])


def frame_stats(depth_mm: np.ndarray, fx: float) -> FrameStats:
    """Every statistic of one frame (see the helpers for each definition)."""
    d = np.asarray(depth_mm)
    if d.ndim != 2:
        raise ValueError(f"depth must be (H, W), got {d.shape}")
    near, far, mx = valid_range(d)
    sj, sw, oj, ow = edge_runs(d, fx)
    holes, speckles = blob_areas(d)
    pz, ps, pq = planar_patches(d, fx)
    return FrameStats(valid_fraction(d), depth_samples(d), near, far, mx, sj, sw, oj, ow, holes,
                      speckles, pz, ps, pq, border_band(d))
