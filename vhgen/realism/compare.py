"""Real frames against vhgen frames: every statistic of :mod:`vhgen.realism.stats` pooled
over each set of frames, summarised, and one distance per statistic.

Distances (smaller = closer to the real sensor):

* **Wasserstein-1** (earth mover's distance, in the statistic's own unit) between the two
  sets of samples, for every statistic that is a distribution: it grows with both a shift
  and a change of shape, needs no bins and is defined for five frames as for five
  thousand. The Kolmogorov-Smirnov statistic is not used: it saturates at 1 as soon as
  the two sets do not overlap (a valid fraction of 0.55 and of 0.20 against 0.80 both give
  1), so it cannot say which of two presets is closer.
* **mean relative difference** |sim - real| / real over the depth bins both sets cover,
  for the axial-noise curve (a curve against depth, not one distribution);
* **mean absolute difference** (px) over the four sides, for the border band.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vhgen.realism.stats import DEPTH_BIN_M, FrameStats

MIN_PATCHES = 5  # a depth bin of the noise curve needs this many planar patches per side


def wasserstein(a: np.ndarray, b: np.ndarray) -> float:
    """Wasserstein-1 distance between two sets of samples (NaN if either is empty)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if not a.size or not b.size:
        return float("nan")
    from scipy.stats import wasserstein_distance

    return float(wasserstein_distance(a, b))


def noise_curve(stats: Sequence[FrameStats]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(bin centres m, median axial noise mm, patches per bin) over DEPTH_BIN_M bins."""
    z = np.concatenate([s.patch_depth_m for s in stats]) if stats else np.zeros(0)
    sig = np.concatenate([s.patch_sigma_mm for s in stats]) if stats else np.zeros(0)
    if not z.size:
        return np.zeros(0), np.zeros(0), np.zeros(0, int)
    k = np.floor(z / DEPTH_BIN_M).astype(int)
    bins = np.unique(k)
    med = np.array([np.median(sig[k == b]) for b in bins])
    cnt = np.array([int(np.sum(k == b)) for b in bins])
    return (bins + 0.5) * DEPTH_BIN_M, med, cnt


def curve_distance(real: Sequence[FrameStats], sim: Sequence[FrameStats]) -> float:
    """Mean relative difference of the noise curves over the depth bins where both hold at
    least MIN_PATCHES planar patches (NaN when none is shared)."""
    zr, sr, nr = noise_curve(real)
    zs, ss, ns = noise_curve(sim)
    a = {round(z, 4): s for z, s, n in zip(zr, sr, nr, strict=True) if n >= MIN_PATCHES}
    b = {round(z, 4): s for z, s, n in zip(zs, ss, ns, strict=True) if n >= MIN_PATCHES}
    common = sorted(set(a) & set(b))
    if not common:
        return float("nan")
    return float(np.mean([abs(b[z] - a[z]) / a[z] for z in common if a[z] > 0]))


def _cat(stats: Sequence[FrameStats], f: Callable[[FrameStats], Any]) -> np.ndarray:
    parts = [np.atleast_1d(np.asarray(f(s), np.float64)) for s in stats]
    return np.concatenate(parts) if parts else np.zeros(0)


def _ratio(jump: np.ndarray, width: np.ndarray) -> np.ndarray:
    return width / np.maximum(jump, 1e-12)


@dataclass(frozen=True)
class Statistic:
    """One compared statistic: how to get its samples, summarise them and measure them."""

    key: str
    title: str
    unit: str
    distance: str  # "W1", "relative" or "abs"
    samples: Callable[[FrameStats], Any]
    summary: Callable[[np.ndarray], float]
    doc: str


def _median(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else float("nan")


def _mean(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(np.mean(a)) if a.size else float("nan")


STATISTICS: tuple[Statistic, ...] = (
    Statistic("valid_fraction", "valid-pixel fraction", "", "W1",
              lambda s: s.valid_fraction, _mean,
              "fraction of pixels with a measurement, per frame (summary: mean)"),
    Statistic("depth", "depth of valid pixels", "m", "W1", lambda s: s.depth_m, _median,
              "valid depths pooled over the frames (summary: median)"),
    Statistic("nearest", "nearest depth (p0.1)", "m", "W1", lambda s: s.nearest_m, _mean,
              "0.1th percentile of each frame's valid depth (summary: mean)"),
    Statistic("farthest", "farthest depth (p99.9)", "m", "W1", lambda s: s.farthest_m, _mean,
              "99.9th percentile of each frame's valid depth (summary: mean)"),
    Statistic("shadow_band", "shadow band f*b", "px m", "W1",
              lambda s: _ratio(s.shadow_jump, s.shadow_width), _median,
              "hole width beside an edge with the far surface on the left, divided by "
              "1/z_near - 1/z_far: f b of the projector shadow (summary: median)"),
    Statistic("other_band", "band on the other side f*b", "px m", "W1",
              lambda s: _ratio(s.other_jump, s.other_width), _median,
              "the same on the other side of near objects (holes along silhouettes; in a "
              "registered image the IR camera's occlusion) (summary: median)"),
    Statistic("edge_holes", "edges with a hole", "", "W1",
              lambda s: np.concatenate([s.shadow_width > 0, s.other_width > 0]), _mean,
              "per edge of either side, 1 if a hole separates the two surfaces (summary: "
              "fraction of edges)"),
    Statistic("hole_blobs", "hole blob size", "log10 px", "W1",
              lambda s: np.log10(np.maximum(s.hole_areas, 1)), _median,
              "log10 area of every 4-connected hole component (summary: median)"),
    Statistic("holes_per_frame", "hole blobs per frame", "", "W1",
              lambda s: len(s.hole_areas), _mean, "number of hole components per frame"),
    Statistic("speckles", "speckles per frame", "", "W1", lambda s: len(s.speckle_areas),
              _mean, "valid islands of at most 200 px per frame (summary: mean)"),
    Statistic("axial_noise", "axial noise vs depth", "rel.", "relative",
              lambda s: s.patch_sigma_mm, _median,
              "RMS of the plane-fit residual of 12x12 planar patches (mm), median per "
              "0.25 m depth bin; distance: mean relative difference over shared bins "
              "(summary: median over patches, mm)"),
    Statistic("noise_coeff", "axial noise / z^2", "mm/m^2", "W1",
              lambda s: s.patch_sigma_mm / np.maximum(s.patch_depth_m, 1e-6) ** 2, _median,
              "patch noise divided by z^2 (disparity noise gives a constant) (summary: "
              "median)"),
    Statistic("quant_step", "quantisation step / z^2", "mm/m^2", "W1",
              lambda s: s.patch_step_mm / np.maximum(s.patch_depth_m, 1e-6) ** 2, _median,
              "median gap between distinct depth values of a planar patch divided by z^2 "
              "(disparity steps give a constant: 1000 step_px / (f b)) (summary: median)"),
    Statistic("border_band", "border band L/R/T/B", "px", "abs",
              lambda s: s.border_px, _mean,
              "5th percentile over rows (columns) of the invalid run starting at each "
              "border; distance: mean |difference| of the per-side means (summary: mean "
              "over sides)"),
)


def _border(stats: Sequence[FrameStats]) -> np.ndarray:
    if not stats:
        return np.full(4, np.nan)
    return np.mean(np.stack([s.border_px for s in stats]), 0)


def compare(real: Sequence[FrameStats], sim: Sequence[FrameStats]) -> dict[str, Any]:
    """Summary of each statistic on both sets and the distance between them:
    ``{key: {title, unit, distance_kind, real, sim, distance, doc}}`` (JSON-ready)."""
    out: dict[str, Any] = {}
    for st in STATISTICS:
        a, b = _cat(real, st.samples), _cat(sim, st.samples)
        if st.distance == "W1":
            dist = wasserstein(a, b)
        elif st.distance == "relative":
            dist = curve_distance(real, sim)
        else:
            dist = float(np.mean(np.abs(_border(sim) - _border(real))))
        entry: dict[str, Any] = {"title": st.title, "unit": st.unit,
                                 "distance_kind": st.distance, "real": st.summary(a),
                                 "sim": st.summary(b), "distance": dist, "doc": st.doc}
        if st.key == "border_band":
            entry["real_sides"] = _border(real).tolist()
            entry["sim_sides"] = _border(sim).tolist()
        out[st.key] = entry
    return out


def _fmt(x: float) -> str:
    if x is None or not np.isfinite(x):
        return "-"
    return f"{x:.3g}"


def table(real_name: str, results: dict[str, dict[str, Any]]) -> str:
    """Side-by-side text table: one row per statistic, the real summary, then per vhgen
    set its summary and its distance to the real frames."""
    names = list(results)
    head = ["statistic", "unit", real_name] + [c for n in names for c in (n, "dist")]
    rows = [head]
    first = results[names[0]] if names else {}
    for key, entry in first.items():
        unit = entry["unit"]
        if entry["distance_kind"] == "relative":
            unit = "mm (dist rel.)"
        row = [entry["title"], unit, _fmt(entry["real"])]
        for n in names:
            e = results[n][key]
            row += [_fmt(e["sim"]), _fmt(e["distance"])]
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.ljust(w) if i < 2 else c.rjust(w)
                               for i, (c, w) in enumerate(zip(r, widths, strict=True)))
                     for r in rows)
