"""What accuracy costs in time: every sensor config against the structured-light reference
on a fixed scene suite (`vhgen bench fidelity`).

Per config and scene: ms per frame (CPU, one core; rows ``[gl]``: the GL backend on this
machine's renderer), IoU of the valid masks and of the hole
masks against the reference, and on pixels valid in both the raw-unit error
(1/8 px disparity steps): P(|dk| <= 1) and RMS. Per scene kind: fronto planes give the
depth noise sigma against the published curves (Nguyen et al. 2012, Khoshelham & Elberink
2012); step edges the shadow band width against f b (1/z_f - 1/z_b) and the edge offset
against the reference; thin rods the fraction of rod pixels measured.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.assets import resolve_asset_dir
from vhgen.mocap.clips import builtin_motion_path
from vhgen.quality.fidelity_scenes import Frame, human_frame, suite
from vhgen.sensor.simulator import SensorConfig, SensorModel

DEFAULT_CONFIGS = ("ideal", "kinect_v1_fast", "kinect_v1_full", "kinect_v1_exact_shadows")
REFERENCE = "kinect_v1_reference"


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    u = (a | b).sum()
    return float((a & b).sum() / u) if u else 1.0


def _run(model: SensorModel, fr: Frame, seed: int):
    rng = np.random.default_rng(seed)
    t = time.perf_counter()
    out = model.simulate(fr.depth, rng, labels=fr.labels, incidence=fr.incidence,
                         projector_depth=fr.projector_depth)
    return out, (time.perf_counter() - t) * 1000.0


def _shadow_and_edge(out, fr: Frame) -> tuple[float, float]:
    """Median over rows of the hole run just left of the step edge, and of the first
    column measuring the foreground."""
    widths, edges = [], []
    for r in range(40, fr.depth.shape[0] - 40, 4):
        row_v = out.valid[r]
        d = out.disparity[r]
        fg = row_v & (np.abs(d - d.max()) < 1.0) if row_v.any() else row_v
        cols = np.flatnonzero(fg)
        if len(cols) == 0:
            continue
        first = cols[0]
        edges.append(first)
        k = first - 1
        w = 0
        while k >= 0 and not row_v[k]:
            w += 1
            k -= 1
        widths.append(w)
    if not widths:
        return float("nan"), float("nan")
    return float(np.median(widths)), float(np.median(edges))


def evaluate(frames: list[Frame], configs=DEFAULT_CONFIGS, reference: str = REFERENCE,
             seed: int = 0, gl_context=None) -> dict:
    """Run every config and the reference on every frame; return the metrics. With a
    ``gl_context``, every config the GL backend runs also as GL passes on it (entries
    ``<config> [gl]``)."""
    ref_model = SensorModel(SensorConfig.load(reference))
    models: dict[str, Any] = {c: SensorModel(SensorConfig.load(c)) for c in configs}
    if gl_context is not None:
        from vhgen.errors import ConfigError
        from vhgen.render.sensor_gl import GLSensorModel

        for c in configs:
            try:
                cfg = SensorConfig.load(c).with_backend("gl")
            except ConfigError:
                continue  # an effect without a GL pass: the CPU row only
            models[f"{c} [gl]"] = GLSensorModel(gl_context, cfg)
    configs = tuple(models)
    f_b = ref_model.cfg.intrinsics.fx * ref_model.cfg.baseline_m
    for m in models.values():  # compile numba kernels outside the timings
        m.simulate(frames[0].depth, np.random.default_rng(0), labels=frames[0].labels,
                   incidence=frames[0].incidence, projector_depth=frames[0].projector_depth)
    results: dict[str, Any] = {"reference": reference, "configs": {},
                               "scenes": [fr.name for fr in frames]}
    ref_out = {}
    ref_ms = []
    for k, fr in enumerate(frames):
        ref_out[fr.name], ms = _run(ref_model, fr, seed + k)
        ref_ms.append(ms)
    results["reference_ms"] = float(np.median(ref_ms))
    for name in [*configs, reference]:
        model = ref_model if name == reference else models[name]
        per_scene = []
        for k, fr in enumerate(frames):
            out, ms = (ref_out[fr.name], ref_ms[k]) if name == reference else \
                _run(model, fr, seed + k)
            ref = ref_out[fr.name]
            both = out.valid & ref.valid
            dk = 8.0 * (out.disparity[both] - ref.disparity[both])
            row = {"scene": fr.name, "kind": fr.kind, "ms": ms,
                   "valid_iou": _iou(out.valid, ref.valid),
                   "hole_iou": _iou(~out.valid, ~ref.valid),
                   "p_raw_within_1": float(np.mean(np.abs(dk) <= 1.0)) if dk.size else None,
                   "rms_raw": float(np.sqrt(np.mean(dk * dk))) if dk.size else None,
                   "valid_fraction": float(out.valid.mean()), "holes": out.holes}
            if fr.kind == "plane":
                z = fr.info["z"]
                zz = f_b / out.disparity[out.valid]
                row["sigma_z_mm"] = float(np.std(zz - z) * 1000)
                row["bias_z_mm"] = float(np.mean(zz - z) * 1000)
                row["nguyen_sigma_mm"] = (0.0012 + 0.0019 * (z - 0.4) ** 2) * 1000
                row["khoshelham_sigma_mm"] = 1.425e-3 * z * z * 1000
            if fr.kind == "step":
                w, e = _shadow_and_edge(out, fr)
                _, e_ref = _shadow_and_edge(ref, fr)
                row["shadow_px"] = w
                row["shadow_expected_px"] = fr.info["shadow_px"]
                row["edge_offset_px"] = e - e_ref
            if fr.kind == "rods":
                rec = {}
                for j, wpx in enumerate(fr.info["widths_px"]):
                    rod = fr.labels == 2 + j
                    near = out.valid & (np.abs(out.disparity - f_b / 2.0) < 1.0)
                    rec[str(wpx)] = float((near & rod).sum() / max(rod.sum(), 1))
                row["rod_recall"] = rec
            per_scene.append(row)
        results["configs"][name] = {"scenes": per_scene, "summary": _summary(per_scene)}
    return results


def _summary(rows: list[dict]) -> dict:
    def mean(key, kind=None):
        vals = [r[key] for r in rows if r.get(key) is not None and (kind is None or
                                                                     r["kind"] == kind)]
        vals = [v for v in vals if not (isinstance(v, float) and np.isnan(v))]
        return float(np.mean(vals)) if vals else None

    rods = [r["rod_recall"] for r in rows if "rod_recall" in r]
    shadow_err = [abs(r["shadow_px"] - r["shadow_expected_px"]) for r in rows
                  if "shadow_px" in r and not np.isnan(r["shadow_px"])]
    sig = [r["sigma_z_mm"] / r["nguyen_sigma_mm"] for r in rows if "sigma_z_mm" in r]
    return {"ms_per_frame": float(np.median([r["ms"] for r in rows])),
            "valid_iou": mean("valid_iou"), "hole_iou": mean("hole_iou"),
            "p_raw_within_1": mean("p_raw_within_1"), "rms_raw": mean("rms_raw"),
            "shadow_width_error_px": float(np.mean(shadow_err)) if shadow_err else None,
            "edge_offset_px": mean("edge_offset_px"),
            "sigma_over_nguyen": float(np.median(sig)) if sig else None,
            "rod_recall": rods[0] if rods else None}


def table(results: dict) -> str:
    head = (f"{'config':30s} {'ms/frame':>9s} {'valid IoU':>9s} {'hole IoU':>9s} "
            f"{'P|dk|<=1':>9s} {'RMS dk':>7s} {'shadow err':>10s} {'edge off':>8s} "
            f"{'sigma/Ng':>8s} {'rods 2/4/8/15 px':>18s}")
    lines = [f"fidelity against {results['reference']} "
             f"({results['reference_ms'] / 1000:.1f} s/frame), {len(results['scenes'])} "
             "scenes; dk in raw units (1/8 px)", head]

    def f(v, fmt):
        return format(v, fmt) if v is not None else "-"

    for name, r in results["configs"].items():
        s = r["summary"]
        rods = s["rod_recall"] or {}
        rodtxt = "/".join(f"{rods.get(k, float('nan')):.2f}" for k in ("2", "4", "8", "15"))
        lines.append(f"{name:30s} {s['ms_per_frame']:9.1f} {f(s['valid_iou'], '9.3f')} "
                     f"{f(s['hole_iou'], '9.3f')} {f(s['p_raw_within_1'], '9.3f')} "
                     f"{f(s['rms_raw'], '7.2f')} {f(s['shadow_width_error_px'], '10.1f')} "
                     f"{f(s['edge_offset_px'], '8.1f')} {f(s['sigma_over_nguyen'], '8.2f')} "
                     f"{rodtxt:>18s}")
    return "\n".join(lines)


def plot(results: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for name, r in results["configs"].items():
        s = r["summary"]
        for ax, key, label in ((axes[0], "valid_iou", "1 - valid-mask IoU"),
                               (axes[1], "rms_raw", "RMS raw error (1/8 px)")):
            if s[key] is None:
                continue
            y = 1 - s[key] if key == "valid_iou" else s[key]
            ax.scatter(s["ms_per_frame"], y, s=40)
            ax.annotate(name, (s["ms_per_frame"], y), fontsize=8, xytext=(4, 4),
                        textcoords="offset points")
            ax.set_xscale("log")
            ax.set_xlabel("ms per 640x480 frame (CPU, one core)")
            ax.set_ylabel(label)
    fig.suptitle(f"Sensor configs against {results['reference']}: error against time")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def bench_fidelity(out_dir: str | Path, *, quick: bool = False, configs=DEFAULT_CONFIGS,
                   human: bool = True, backend: str = "egl", motion: str | None = None,
                   asset_dir=None, gl_sensor: bool = False) -> dict:
    """Build the scene suite, evaluate, and write table.txt, fidelity.json, fidelity.png.
    ``gl_sensor``: every config also with ``sensor.backend: gl`` (rows ``[gl]``; on this
    machine's GL renderer)."""
    ref_cfg = SensorConfig.load(REFERENCE)
    intr, b = ref_cfg.intrinsics, ref_cfg.baseline_m
    frames = suite(intr, b, quick=quick)
    ctx = None
    if human or gl_sensor:
        from vhgen.render.context import create_context  # GL for the human scene, GL rows

        ctx = create_context(backend)
    try:
        if human:
            frames.append(human_frame(ctx, intr, b, resolve_asset_dir(asset_dir),
                                      motion or builtin_motion_path()))
        results = evaluate(frames, configs, gl_context=ctx if gl_sensor else None)
    finally:
        if ctx is not None:
            ctx.release()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "fidelity.json").write_text(json.dumps(results, indent=1))
    txt = table(results)
    (out / "table.txt").write_text(txt + "\n")
    plot(results, out / "fidelity.png")
    results["table"] = txt
    return results
