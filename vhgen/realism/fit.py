"""`vhgen sensor fit`: a sensor config estimated from real frames of static scenes.

What the realism statistics determine is estimated; everything else is kept from a base
preset and reported. Parameters whose statistic also depends on other effects (the
noise, which the correlation window and the quantisation reshape; the band widths, which
the window's splats narrow) are fitted *through the simulator*: the candidate sensor runs
on synthetic frames with known geometry (:func:`planes_frame`, :func:`step_frame`), the
same statistic is measured on its output, and the parameter is corrected until the two
agree. So a fitted value is what makes vhgen's frames show the real statistic, not a
textbook conversion.

Estimated (each only when the frames show it; see :func:`fit_sensor`):

* intrinsics (recovered from organized clouds);
* valid range: ``range_gate.z_min_m`` lowered below the nearest real depth,
  ``z_max_m`` raised to the farthest (a room seen to 3.7 m says nothing beyond: kept);
* shadow geometry: ``baseline_m`` from the shadow-side band widths;
* registration: ``registration`` border band (the per-side band of every frame) and its
  IR-camera offset from the bands on the other side of near objects;
* quantisation: ``disparity_quantisation.step_px`` from the step / z^2 of planar patches;
* axial noise: ``axial_noise.sigma_px`` (disparity model) from the noise / z^2;
* isolated measurements: ``speckle_filter.max_area_px`` from the smallest valid blob.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.camera import Intrinsics
from vhgen.realism.stats import SPECKLE_MAX_PX, FrameStats, frame_stats
from vhgen.sensor.effects import (
    AxialNoise,
    CorrelationWindow,
    DisparityQuantisation,
    RangeGate,
    Registration,
    SpeckleFilter,
)
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.spec import EffectSpec

MIN_EDGES = 30  # band widths need this many edges with a hole
MIN_PATCHES = 30  # noise and steps need this many planar patches
MIN_JUMP_SPREAD = 0.25  # 1/m: band widths need jumps of several sizes
BORDER_MIN_PX = 2  # a border band narrower than this on every side is no registration band


@dataclass
class FitReport:
    """What was estimated (parameter -> (value, from what)) and what was kept (parameter
    -> why), and the fitted config."""

    config: SensorConfig
    fitted: dict[str, tuple[Any, str]] = field(default_factory=dict)
    kept: dict[str, str] = field(default_factory=dict)


def planes_frame(intr: Intrinsics, depths: Sequence[float] = (1.0, 1.4, 1.8, 2.2, 2.6, 3.0,
                                                               3.4, 3.8)) -> np.ndarray:
    """(H, W) float64 metres: fronto-parallel vertical strips, one per depth."""
    z = np.empty((intr.height, intr.width))
    edges = np.linspace(0, intr.width, len(depths) + 1).astype(int)
    for k, dz in enumerate(depths):
        z[:, edges[k]:edges[k + 1]] = dz
    return z


def step_frame(intr: Intrinsics, nears: Sequence[float] = (0.9, 1.3, 1.8, 2.5),
               far: float = 3.6) -> np.ndarray:
    """(H, W) float64 metres: a wall at ``far`` with one box per depth of ``nears`` side
    by side (vertical edges on both sides of each, jumps of several sizes)."""
    z = np.full((intr.height, intr.width), far)
    edges = np.linspace(0, intr.width, 2 * len(nears) + 2).astype(int)
    for k, near in enumerate(nears):
        z[intr.height // 6: -intr.height // 6, edges[2 * k + 1]:edges[2 * k + 2]] = near
    return z


def simulate_stats(cfg: SensorConfig, depth: np.ndarray, seed: int = 0) -> FrameStats:
    """Run ``cfg`` on a synthetic depth image (incidence 1, no labels) and measure it."""
    from vhgen.sensor.simulator import SensorModel

    model = SensorModel(cfg)
    out = model.simulate(depth, np.random.default_rng(seed), incidence=np.ones_like(depth),
                         projector_depth=depth if "projector_depth" in cfg.needs else None)
    return frame_stats(out.depth_mm, cfg.intrinsics.fx)


def _replace(cfg: SensorConfig, **kw: Any) -> SensorConfig:
    return dataclasses.replace(cfg, **kw)


def _set_effect(cfg: SensorConfig, spec: EffectSpec, after: Sequence[str] = ()) -> SensorConfig:
    """``cfg`` with ``spec`` replacing the effect of its name, or inserted after the last
    of ``after`` present (else last)."""
    effects = list(cfg.effects)
    for i, e in enumerate(effects):
        if e.name == spec.name:
            effects[i] = spec
            return _replace(cfg, effects=tuple(effects))
    pos = max((i + 1 for i, e in enumerate(effects) if e.name in after), default=len(effects))
    effects.insert(pos, spec)
    return _replace(cfg, effects=tuple(effects))


def _noise_coeff(st: Sequence[FrameStats]) -> float:
    z = np.concatenate([s.patch_depth_m for s in st])
    sig = np.concatenate([s.patch_sigma_mm for s in st])
    return float(np.median(sig / z ** 2)) if len(z) else float("nan")


def _step_coeff(st: Sequence[FrameStats]) -> float:
    z = np.concatenate([s.patch_depth_m for s in st])
    q = np.concatenate([s.patch_step_mm for s in st])
    ok = np.isfinite(q)
    return float(np.median(q[ok] / z[ok] ** 2)) if ok.sum() else float("nan")


def _band(st: Sequence[FrameStats], side: str) -> tuple[float, int]:
    """f*b (px m) of the edges of ``side`` that show a hole, and their count: the slope of
    the band width against the jump 1/z_near - 1/z_far (least squares with an intercept,
    refitted without residuals beyond 3 MAD), since effects that fill or widen a band by a
    few pixels whatever the jump (splats, lateral noise) move the intercept, not the
    slope. NaN with fewer than 3 edges, when the jumps do not span MIN_JUMP_SPREAD (10th
    to 90th percentile: a room seen from 1.5-3 m has jumps of one size only, whose band
    widths say nothing about the growth) or when the slope is not positive."""
    j = np.concatenate([getattr(s, f"{side}_jump") for s in st])
    w = np.concatenate([getattr(s, f"{side}_width") for s in st])
    hole = w > 0
    j, w = j[hole], w[hole]
    if len(j) < 3 or np.subtract(*np.percentile(j, [90, 10])) < MIN_JUMP_SPREAD:
        return float("nan"), int(len(j))
    keep = np.ones(len(j), bool)
    slope = float("nan")
    for _ in range(3):
        a = np.stack([j[keep], np.ones(int(keep.sum()))], -1)
        (slope, icpt), *_ = np.linalg.lstsq(a, w[keep], rcond=None)
        r = w - (slope * j + icpt)
        mad = float(np.median(np.abs(r[keep] - np.median(r[keep])))) + 1e-9
        keep = np.abs(r) <= 3 * 1.4826 * mad + 0.5
    return (float(slope) if slope > 0 else float("nan")), int(len(j))


def _calibrate(cfg: SensorConfig, target: float, measure, make, lo: float, hi: float,
               iters: int = 12) -> float:
    """Bisection of a parameter in [lo, hi] so that measure(simulated stats) = target;
    ``make(cfg, value)`` builds the candidate (the statistic grows with the value)."""
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        if measure(make(cfg, mid)) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def fit_sensor(real: Sequence[FrameStats], intr: Intrinsics, base: SensorConfig,
               name: str = "fitted") -> FitReport:
    """Estimate a sensor from the statistics of real frames of static scenes (no labels).

    ``intr``: the real camera; ``base``: the preset whose other values are kept. Returns
    the config (validated by the same checks as a loaded file) and the report."""
    cfg = _replace(base, name=name, intrinsics=intr, source=None)
    rep = FitReport(cfg)
    fx = intr.fx
    rep.fitted["intrinsics"] = ((intr.fx, intr.fy, intr.cx, intr.cy),
                                "the frames' own (recovered from the clouds, or given)")

    # valid range
    near = min(s.nearest_m for s in real if s.valid_fraction > 0)
    far = max(s.farthest_m for s in real)
    gate = cfg.effect("range_gate")
    gate = gate if isinstance(gate, RangeGate) else RangeGate()
    z_min, z_max = gate.z_min_m, gate.z_max_m
    if near < z_min:
        z_min = max(0.05, float(np.floor(near * 0.9 * 20) / 20))
        rep.fitted["range_gate.z_min_m"] = (z_min, f"nearest real depth {near:.3f} m")
    else:
        rep.kept["range_gate.z_min_m"] = (f"no real depth nearer than the base's "
                                          f"{gate.z_min_m} m (nearest {near:.2f} m)")
    if far > z_max:
        z_max = float(np.ceil(far * 2) / 2)
        rep.fitted["range_gate.z_max_m"] = (z_max, f"farthest real depth {far:.2f} m")
    else:
        rep.kept["range_gate.z_max_m"] = (f"the frames reach only {far:.2f} m (p99.9): "
                                          f"they say nothing about the base's {gate.z_max_m} m")
    cfg = _set_effect(cfg, RangeGate(z_min_m=z_min, z_max_m=z_max))

    # border band and the IR camera's occlusion (registration)
    border = np.min(np.stack([s.border_px for s in real]), 0)
    reg = cfg.effect("registration")
    if border.max() >= BORDER_MIN_PX or reg is not None:
        b = [int(np.floor(x)) for x in border]
        ob, n_other = _band(real, "other")
        offset = reg.ir_offset_m if isinstance(reg, Registration) else -0.025
        spec = Registration(ir_offset_m=offset, left_px=b[0], right_px=b[1], top_px=b[2],
                            bottom_px=b[3])
        rep.fitted["registration.*_px"] = (b, "narrowest border band over the frames "
                                              "(left, right, top, bottom)")
        cfg = _set_effect(cfg, spec, after=("disparity_quantisation",))
        if n_other >= MIN_EDGES and np.isfinite(ob):
            def make_reg(c: SensorConfig, v: float) -> SensorConfig:
                return _set_effect(c, dataclasses.replace(spec, ir_offset_m=-v))
            off = _calibrate(cfg, ob, lambda c: _band([simulate_stats(c, step_frame(intr))],
                                                      "other")[0], make_reg, 0.0, 0.2)
            cfg = make_reg(cfg, off)
            rep.fitted["registration.ir_offset_m"] = (
                -round(off, 4), f"band on the other side: width / jump slope {ob:.1f} px m "
                                f"({n_other} edges)")
        else:
            rep.kept["registration.ir_offset_m"] = (
                f"{n_other} edges with a hole on the other side of near objects, but too few "
                "or with jumps of too few sizes to measure how the band grows")
    else:
        rep.kept["registration"] = "no border band in the frames: not a registered image"

    # shadow geometry -> baseline
    sb, n_sh = _band(real, "shadow")
    if n_sh >= MIN_EDGES and np.isfinite(sb):
        def make_base(c: SensorConfig, v: float) -> SensorConfig:
            return _replace(c, baseline_m=v)
        b_fit = _calibrate(cfg, sb, lambda c: _band([simulate_stats(c, step_frame(intr))],
                                                    "shadow")[0], make_base, 0.005, 0.3)
        # keep the disparity steps and noise in depth what they were at the old baseline
        cfg = _rescale_disparity(cfg, b_fit)
        rep.fitted["baseline_m"] = (round(b_fit, 4), f"shadow band: width / jump slope "
                                                     f"{sb:.1f} px m ({n_sh} edges)")
    else:
        rep.kept["baseline_m"] = (f"{n_sh} edges with a shadow hole, but too few or with "
                                  "jumps of too few sizes to measure how the band grows")

    # quantisation step
    k_real = _step_coeff(real)
    n_patch = sum(len(s.patch_depth_m) for s in real)
    q = cfg.effect("disparity_quantisation")
    if n_patch >= MIN_PATCHES and np.isfinite(k_real) and isinstance(q, DisparityQuantisation):
        step = k_real / 1000.0 * fx * cfg.baseline_m
        cfg = _set_effect(cfg, DisparityQuantisation(step_px=round(step, 5)))
        rep.fitted["disparity_quantisation.step_px"] = (round(step, 5), f"step / z^2 = "
                                                        f"{k_real:.3f} mm/m^2")
    else:
        rep.kept["disparity_quantisation.step_px"] = "too few planar patches (or the base " \
                                                     "has no quantisation)"

    # axial noise, through the simulator
    a = cfg.effect("axial_noise")
    n_real = _noise_coeff(real)
    if n_patch >= MIN_PATCHES and isinstance(a, AxialNoise) and a.model == "disparity":
        plane = planes_frame(intr)

        def make_noise(c: SensorConfig, v: float) -> SensorConfig:
            return _set_effect(c, dataclasses.replace(a, sigma_px=v))
        sig = _calibrate(cfg, n_real, lambda c: _noise_coeff([simulate_stats(c, plane)]),
                         make_noise, 0.0, 1.0)
        cfg = make_noise(cfg, round(sig, 4))
        rep.fitted["axial_noise.sigma_px"] = (round(sig, 4), f"noise / z^2 = {n_real:.3f} "
                                                             "mm/m^2 on planar patches")
    else:
        rep.kept["axial_noise"] = "too few planar patches, or not the disparity model"

    # speckles
    sp = np.concatenate([s.speckle_areas for s in real])
    if sp.size == 0:
        cfg = _set_effect(cfg, SpeckleFilter(max_area_px=SPECKLE_MAX_PX))
        rep.fitted["speckle_filter.max_area_px"] = (SPECKLE_MAX_PX, "no valid blob of at most "
                                                    f"{SPECKLE_MAX_PX} px in the frames")
    elif sp.min() > 1:
        m = int(sp.min()) - 1
        cfg = _set_effect(cfg, SpeckleFilter(max_area_px=m))
        rep.fitted["speckle_filter.max_area_px"] = (m, f"smallest valid blob {int(sp.min())} px")
    else:
        cfg = _replace(cfg, effects=tuple(e for e in cfg.effects if e.name != "speckle_filter"))
        rep.fitted["speckle_filter"] = (None, "single valid pixels occur: no filter")

    for e in cfg.effects:
        if e.name in ("lateral_noise", "correlation_window", "dropout", "range_dropout",
                      "projector_shadow", "lens_distortion"):
            rep.kept.setdefault(e.name, "not determined by the statistics of static frames")
    rep.config = cfg
    return rep


def _rescale_disparity(cfg: SensorConfig, baseline: float) -> SensorConfig:
    """``cfg`` with a new baseline, the disparity-domain parameters scaled by the ratio so
    that quantisation steps, noise and inlier thresholds stay what they were in depth."""
    r = baseline / cfg.baseline_m
    effects = []
    for e in cfg.effects:
        if e.name == "axial_noise" and isinstance(e, AxialNoise) and e.model == "disparity":
            e = dataclasses.replace(e, sigma_px=e.sigma_px * r)
        elif isinstance(e, DisparityQuantisation):
            e = dataclasses.replace(e, step_px=e.step_px * r)
        elif isinstance(e, CorrelationWindow):
            e = dataclasses.replace(e, inlier_px=e.inlier_px * r)
        effects.append(e)
    return _replace(cfg, baseline_m=baseline, effects=tuple(effects))


def config_yaml(rep: FitReport, sources: Sequence[str], base: str) -> str:
    """The fitted config as a sensor YAML, with what was fitted and kept as comments."""
    import yaml

    cfg = rep.config
    i = cfg.intrinsics
    lines = [f"# Fitted by `vhgen sensor fit` from {len(sources)} real frames "
             f"(base preset {base}).", "# fitted:"]
    lines += [f"#   {k} = {v[0]}  ({v[1]})" for k, v in rep.fitted.items()]
    lines += ["# kept from the base:"] + [f"#   {k}: {v}" for k, v in rep.kept.items()]
    doc = {"name": cfg.name, "width": i.width, "height": i.height, "fx": i.fx, "fy": i.fy,
           "cx": i.cx, "cy": i.cy, "baseline_m": round(cfg.baseline_m, 6),
           "pattern_seed": cfg.pattern_seed, "dot_density": cfg.dot_density}
    text = yaml.safe_dump(doc, sort_keys=False)
    effects = [e.to_dict() for e in cfg.effects] + [cfg.encoding.to_dict()]

    def tidy(v: Any) -> Any:
        return round(v, 6) if isinstance(v, float) else v
    text += "effects:\n" + "".join(
        "  - " + yaml.safe_dump({n: {k: tidy(v) for k, v in p.items()}
                                for n, p in e.items()}, default_flow_style=True,
                               sort_keys=False, width=1000).strip()[1:-1] + "\n"
        for e in effects)
    return "\n".join(lines) + "\n" + text


def fit_files(real: Sequence[str], out: str | Path, *, base: str = "kinect_v1_full",
              name: str | None = None, fx: float | None = None,
              warn: Callable[[str], None] | None = None) -> FitReport:
    """``vhgen sensor fit``: read the real frames (PCD/PNG files or folders; bad files are
    one warning each), fit, write the YAML to ``out``, then load it back and run it on a
    synthetic frame (so a written file always loads and runs). ConfigError when no frame
    could be read or the frames carry no intrinsics (give ``fx`` for PNGs)."""
    from vhgen.errors import ConfigError
    from vhgen.realism.collect import real_stats

    got = real_stats(real, fx=fx) if warn is None else real_stats(real, fx=fx, warn=warn)
    if not got.stats:
        raise ConfigError(None, "REAL", f"no readable real depth frame in {', '.join(real)}")
    base_cfg = SensorConfig.load(base)
    intr = got.intrinsics
    if intr is None:  # PNGs with --fx: the base's principal point and size
        b = base_cfg.intrinsics
        intr = Intrinsics(b.width, b.height, float(got.fx or b.fx), float(got.fx or b.fy),
                          b.cx, b.cy)
    outp = Path(out)
    rep = fit_sensor(got.stats, intr, base_cfg, name=name or outp.stem)
    outp.parent.mkdir(parents=True, exist_ok=True)
    outp.write_text(config_yaml(rep, got.files, base))
    loaded = SensorConfig.load(outp)
    simulate_stats(loaded, planes_frame(loaded.intrinsics))
    rep.config = loaded
    return rep
