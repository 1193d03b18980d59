"""Sensor model speed: ms per 640x480 frame for every sensor config, on one core.

    .venv/bin/python benchmarks/bench_sensor.py [--repeats 30] [--backend egl]
                                                [--backends cpu,gl]

Frames: a posed human alone (the dataset's usual frame), the same human in front of a
wall at 3.5 m (every pixel valid: the worst case), and an all-valid step edge. Each
config runs ``--repeats`` times per frame; the table shows the median (and the 90th
percentile). Side by side on the same frame: the dot-gated 9x9 correlation window as a
straightforward NumPy loop in the style of the public ICL-NUIM simkinect filter (one
Python iteration per dot pixel, NumPy on each 9x9 window) against vhgen's compiled kernel.
Run with NUMBA_NUM_THREADS=1; the kernels are single-threaded anyway. Rows marked [gl]
time ``sensor.backend: gl`` (the compute passes of vhgen.render.sensor_gl, read back) on
the context's renderer: on llvmpipe that is the CPU again (LP_NUM_THREADS=1, as in the
frame path's workers); GPU timings need a GPU node (docs/performance.md).
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

import numpy as np

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
# llvmpipe as the frame path's workers run it (one thread each); a GPU runs the GL rows
os.environ.setdefault("LP_NUM_THREADS", "1")


def icl_style_window(disp: np.ndarray, dots: np.ndarray, invalid: float = 0.0,
                     frac: float = 1 / 1.5, inlier: float = 0.1, size: int = 9) -> np.ndarray:
    """The obvious NumPy implementation of the dot-gated window (the baseline)."""
    c = size // 2
    yy, xx = np.mgrid[-c:c + 1, -c:c + 1].astype(np.float64)
    r2 = xx ** 2 + yy ** 2
    vals = r2 * 1.2 ** 2
    vals[vals == 0] = 1
    weights = 1 / vals
    fill = np.where(r2 > 3.1 ** 2, -1.0, 1 / (1 + r2))
    out = np.full_like(disp, invalid)
    best = np.zeros_like(disp)
    h, w = disp.shape
    for r in range(h - size):
        for q in range(w - size):
            if not dots[r + c, q + c] or disp[r + c, q + c] == invalid:
                continue
            win = disp[r:r + size, q:q + size]
            dwin = dots[r:r + size, q:q + size]
            ok = (win != invalid) & dwin
            n_dots = dwin.sum()
            if ok.sum() <= n_dots * frac:
                continue
            mean = win[ok].mean()
            inl = ok & (np.abs(win - mean) * weights < inlier)
            if inl.sum() <= n_dots * frac:
                continue
            bw = best[r:r + size, q:q + size]
            ow = out[r:r + size, q:q + size]
            sub = bw < fill
            bw[sub] = fill[sub]
            ow[sub] = win[c, c]
    return out


def main() -> None:
    from vhgen.assets import resolve_asset_dir
    from vhgen.errors import ConfigError
    from vhgen.mocap.clips import builtin_motion_path
    from vhgen.quality.fidelity_scenes import human_frame, suite
    from vhgen.render.context import create_context
    from vhgen.render.sensor_gl import GLSensorModel
    from vhgen.sensor.sensor_kernels import correlation_window, dots_from_pattern
    from vhgen.sensor.simulator import PATTERN_PAD, SensorConfig, SensorModel
    from vhgen.yamlio import configs_dir

    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--backend", default="egl")
    ap.add_argument("--backends", default="cpu,gl",
                    help="sensor backends to time: cpu, gl or cpu,gl")
    args = ap.parse_args()
    ref = SensorConfig.load("kinect_v1_full")
    intr, b = ref.intrinsics, ref.baseline_m
    ctx = create_context(args.backend)
    asset = resolve_asset_dir()
    frames = [human_frame(ctx, intr, b, asset, builtin_motion_path(), wall=None),
              human_frame(ctx, intr, b, asset, builtin_motion_path(), wall=3.5),
              next(f for f in suite(intr, b, quick=True) if f.kind == "step")]
    names = sorted(p.stem for p in (configs_dir() / "sensors").glob("*.yaml")
                   if p.stem != "kinect_v1_reference")
    print(f"\nsensor speed, ms per {intr.width}x{intr.height} frame, one core, median "
          f"(p90) of {args.repeats}; [gl]: the GL passes on {ctx.info['GL_RENDERER']}, "
          "LP_NUM_THREADS=" + os.environ.get("LP_NUM_THREADS", "-"))
    print(f"{'config':34s}" + "".join(f"{fr.name:>24s}" for fr in frames))
    rows: list[tuple[str, Any]] = []
    for name in names:
        cfg = SensorConfig.load(name)
        if "cpu" in args.backends.split(","):
            rows.append((name, SensorModel(cfg)))
        if "gl" in args.backends.split(","):
            try:
                gl_cfg = cfg.with_backend("gl")
            except ConfigError as e:
                print(f"{name + ' [gl]':34s}  no GL pass: {e.field}")
                continue
            rows.append((f"{name} [gl]", GLSensorModel(ctx, gl_cfg)))
    for name, m in rows:
        cells = []
        for fr in frames:
            kw = dict(labels=fr.labels, incidence=fr.incidence,
                      projector_depth=fr.projector_depth)
            m.simulate(fr.depth, np.random.default_rng(0), **kw)  # compile, warm caches
            ts = []
            for i in range(args.repeats):
                t = time.perf_counter()
                m.simulate(fr.depth, np.random.default_rng(i), **kw)
                ts.append((time.perf_counter() - t) * 1000)
            cells.append(f"{np.median(ts):8.1f} ({np.percentile(ts, 90):5.1f})")
        print(f"{name:34s}" + "".join(f"{c:>24s}" for c in cells))

    fr = frames[1]
    fb = intr.fx * b
    valid = fr.depth > 0
    d = np.where(valid, fb / np.where(valid, fr.depth, 1), 0.0)
    m = SensorModel(ref)
    dots = dots_from_pattern(d, valid, m.pattern, PATTERN_PAD)
    correlation_window(d, valid, dots, 4, 1 / 1.5, 0.1, 3.1)
    ts = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        correlation_window(d, valid, dots, 4, 1 / 1.5, 0.1, 3.1)
        ts.append(time.perf_counter() - t)
    t = time.perf_counter()
    base = icl_style_window(d, dots)
    t_base = time.perf_counter() - t
    ours, ok, _ = correlation_window(d, valid, dots, 4, 1 / 1.5, 0.1, 3.1)
    agree = np.mean((base > 0) == ok)
    print(f"\ndot-gated 9x9 window on '{fr.name}' ({int(dots.sum())} dots):")
    print(f"  straightforward NumPy (ICL-NUIM style) {t_base * 1000:9.1f} ms")
    print(f"  vhgen numba kernel                     {np.median(ts) * 1000:9.2f} ms")
    print(f"  speed-up {t_base / np.median(ts):.0f}x; valid masks agree on {agree:.4f} of "
          "pixels")


if __name__ == "__main__":
    main()
