"""What the frames teach: body-part forest accuracy vs data, depth, trees and sensor realism
(the synthetic study), and what each realism measure buys on a real sensor (``--real``).

    .venv/bin/python studies/forest_curves.py [--quick] [--out out/forest_study]
        [--backend egl] [--workers N]
    .venv/bin/python studies/forest_curves.py --real [--quick] [--out docs/forest_study]
        [--data DIR] [--frames 560] [--curve 560,1120,2240,4480]

The real study is described in :func:`real_study`; what follows is the synthetic one.

1. Generates (or reuses, in OUT/data) the frames: training frames from
   configs/forest/train.yaml (CMU subjects 01, 02, 05, 09, 10 and the emotional-walk clips,
   avatar seed 1101) rendered through three sensors (ideal, kinect_v1_fast, kinect_v1_full:
   same poses, bodies and cameras), and held-out test frames from configs/forest/test.yaml
   (CMU subjects 12, 16, 49, 64 - no training frame uses them - on avatars of seed 2202)
   through kinect_v1_full and ideal.
2. Accuracy (mean per-class and per-pixel, body pixels of the held-out test frames) against
   the number of training frames (log scale), against tree depth and number of trees
   (depth and trees from the largest forest: a level-wise forest cut at depth d / its first
   k trees is the forest trained with --depth d / --trees k), and the sensor ablation
   (train on each sensor, test on kinect_v1_full and on ideal frames).
3. Training time per level and per tree, inference frames/s.

Writes OUT/study.json, OUT/study.txt and OUT/curve_frames.png, curve_depth_trees.png,
ablation.png. ``--quick`` uses small frame counts and forests (minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent

# the plan of a run: frame steps and avatars of the generated stores, forest sizes, params
QUICK: dict[str, Any] = {
    "train_step": 60, "train_avatars": 2, "test_step": 90, "test_avatars": 2,
    "sizes": [8, 16, 32, 64, 128], "ablation_frames": 128,
    "params": {"trees": 2, "depth": 14, "pixels_per_image": 300, "features": 100,
               "thresholds": 15, "min_samples": 8}}
FULL: dict[str, Any] = {
    "train_step": 20, "train_avatars": 4, "test_step": 30, "test_avatars": 3,
    "sizes": [35, 70, 140, 280, 560, 1120, 2260], "ablation_frames": 560,
    "params": {"trees": 3, "depth": 20, "pixels_per_image": 300, "features": 300,
               "thresholds": 25, "min_samples": 16}}
TRAIN_SENSORS = ("ideal", "kinect_v1_fast", "kinect_v1_full")
TEST_SENSORS = ("kinect_v1_full", "ideal")


def generate(config: str, sensor: str, step: int, avatars: int, out: Path, backend: str,
             workers: int) -> str:
    """Frames of ``config`` through ``sensor`` (reused if the store is complete)."""
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job
    from vhgen.sensor.simulator import SensorConfig

    if (out / "manifest.parquet").is_file():
        return str(out)
    cfg = JobConfig.load(REPO / "configs" / "forest" / config, num_workers=workers,
                         backend=backend)
    cfg = dataclasses.replace(cfg, sensor=SensorConfig.load(sensor),
                              poses=dataclasses.replace(cfg.poses, frame_step=step),
                              avatars=dataclasses.replace(cfg.avatars, count=avatars))
    s = run_job(cfg, out, overwrite=True)
    print(f"generated {s.frames} frames -> {out} ({s.seconds:.0f} s)", flush=True)
    return str(out)


def scores(forest, test: str) -> dict:
    from vhgen.forest.data import store_info
    from vhgen.forest.evaluate import evaluate

    r = evaluate(forest, [store_info(test)])
    return {"pixel_accuracy": r["pixel_accuracy"], "mean_per_class": r["mean_per_class"],
            "test_frames": r["frames"], "frames_per_second": r["frames_per_second"]}


def plot(res: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    n = [r["frames"] for r in res["frames_curve"]]
    for key, lab in (("mean_per_class", "mean per-class"), ("pixel_accuracy", "per-pixel")):
        ax.plot(n, [r[key] for r in res["frames_curve"]], "o-", label=lab)
    ax.set_xscale("log")
    ax.set_xlabel("training frames (kinect_v1_full)")
    ax.set_ylabel("accuracy on held-out frames")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "curve_frames.png", dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
    for ax, key, lab in ((axes[0], "depth_curve", "tree depth"),
                         (axes[1], "trees_curve", "number of trees")):
        xs = [r["value"] for r in res[key]]
        ax.plot(xs, [r["mean_per_class"] for r in res[key]], "o-", label="mean per-class")
        ax.plot(xs, [r["pixel_accuracy"] for r in res[key]], "s--", label="per-pixel")
        ax.set_xlabel(lab)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("accuracy")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(out / "curve_depth_trees.png", dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 3.5))
    w = 0.38
    for j, ts in enumerate(TEST_SENSORS):
        vals = [r["test"][ts]["mean_per_class"] for r in res["ablation"]]
        ax.bar(np.arange(len(vals)) + (j - 0.5) * w, vals, w, label=f"test {ts}")
    ax.set_xticks(range(len(res["ablation"])), [r["train_sensor"] for r in res["ablation"]])
    ax.set_xlabel("training sensor")
    ax.set_ylabel("mean per-class accuracy")
    ax.legend(loc="lower center", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "ablation.png", dpi=100)
    plt.close(fig)


def table(res: dict) -> str:
    L = [f"held-out test frames ({res['frames_curve'][0]['test_frames']}): {res['held_out']}",
         "",
         "accuracy vs training frames (train kinect_v1_full, test kinect_v1_full)",
         f"{'frames':>7} {'mean/class':>10} {'pixel':>7} {'train s':>8}"]
    L += [f"{r['frames']:>7d} {r['mean_per_class']:>10.4f} {r['pixel_accuracy']:>7.4f} "
          f"{r['train_seconds']:>8.1f}" for r in res["frames_curve"]]
    for key, lab in (("depth_curve", "depth"), ("trees_curve", "trees")):
        L += ["", f"accuracy vs {lab} ({res['frames_curve'][-1]['frames']} frames)",
              f"{lab:>7} {'mean/class':>10} {'pixel':>7}"]
        L += [f"{r['value']:>7d} {r['mean_per_class']:>10.4f} {r['pixel_accuracy']:>7.4f}"
              for r in res[key]]
    L += ["", f"sensor ablation ({res['ablation'][0]['frames']} training frames): mean per-class"
          " / per-pixel", f"{'train on':<16}" + "".join(f"{'test ' + t:>26}"
                                                      for t in TEST_SENSORS)]
    for r in res["ablation"]:
        L.append(f"{r['train_sensor']:<16}" + "".join(
            f"{r['test'][t]['mean_per_class']:>17.4f} / {r['test'][t]['pixel_accuracy']:.4f}"
            for t in TEST_SENSORS))
    t = res["timing"]
    L += ["", f"training: {t['seconds_per_tree']} s per tree, mean {t['mean_level_seconds']:.2f} s"
          f" per level (largest forest, {t['samples']} samples); inference "
          f"{t['eval_frames_per_second']} frames/s (eval, all threads)",
          f"total study time {res['seconds']:.0f} s"]
    return "\n".join(L)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (minutes)")
    ap.add_argument("--real", action="store_true",
                    help="the realism study on real frames (see real_study)")
    ap.add_argument("--out", default=str(REPO / "out" / "forest_study"))
    ap.add_argument("--data", help="--real: where the generated stores go (default "
                    "OUT/real_data)")
    ap.add_argument("--frames", type=int, help="--real: training frames of each ablation "
                    "row (default 1120; 140 with --quick)")
    ap.add_argument("--curve", help="--real: training frames of the curve, comma-separated "
                    "(default 560,1120,2240,4480,8960)")
    ap.add_argument("--backend", choices=["egl", "osmesa"], default="egl")
    ap.add_argument("--workers", type=int, default=2, help="generation workers")
    args = ap.parse_args()
    if args.real:
        from forest_real import real_study

        real_study(Path(args.out), quick=args.quick, backend=args.backend,
                   workers=args.workers, data=Path(args.data) if args.data else None,
                   frames=args.frames,
                   curve=[int(c) for c in args.curve.split(",")] if args.curve else None)
        return
    from vhgen.forest.from_stores import train_forest
    from vhgen.forest.train import TrainParams
    from vhgen.forest.trees import first_trees, truncate

    t_start = time.perf_counter()
    plan = QUICK if args.quick else FULL
    out = Path(args.out)
    data = out / "data"
    data.mkdir(parents=True, exist_ok=True)
    train = {s: generate("train.yaml", s, plan["train_step"], plan["train_avatars"],
                         data / f"train_{s}.zarr", args.backend, args.workers)
             for s in TRAIN_SENSORS}
    test = {s: generate("test.yaml", s, plan["test_step"], plan["test_avatars"],
                        data / f"test_{s}.zarr", args.backend, args.workers)
            for s in TEST_SENSORS}
    params = TrainParams(seed=1, **plan["params"])
    res: dict = {"quick": args.quick, "params": dataclasses.asdict(params),
                 "held_out": "test motions CMU 12_01, 16_27, 49_06, 64_29 (subjects 12, 16, "
                             "49, 64; no training frame uses them), test avatars drawn from "
                             "seed 2202 (training: 1101)",
                 "stores": {"train": train, "test": test}, "frames_curve": []}
    from vhgen.forest.data import store_info

    n_train = store_info(train["kinect_v1_full"]).num_frames
    sizes = [s for s in plan["sizes"] if s < n_train] + [n_train]
    largest = None
    for n in sizes:
        forest = train_forest([train["kinect_v1_full"]], params, max_frames=n)
        r = {**scores(forest, test["kinect_v1_full"]), "frames": n,
             "train_seconds": forest.meta["train_seconds"]}
        res["frames_curve"].append(r)
        print(f"frames {n}: mean/class {r['mean_per_class']:.4f} pixel "
              f"{r['pixel_accuracy']:.4f} ({r['train_seconds']:.0f} s)", flush=True)
        largest = forest
    assert largest is not None
    depths = sorted({d for d in range(2, params.depth + 1, 2)} | {params.depth})
    res["depth_curve"] = [{"value": d, **scores(truncate(largest, d), test["kinect_v1_full"])}
                          for d in depths]
    res["trees_curve"] = [{"value": k, **scores(first_trees(largest, k),
                                                test["kinect_v1_full"])}
                          for k in range(1, params.trees + 1)]
    levels = [lv for t in largest.meta["trees"] for lv in t["levels"]]
    res["timing"] = {"seconds_per_tree": [t["seconds"] for t in largest.meta["trees"]],
                     "mean_level_seconds": float(np.mean([lv["seconds"] for lv in levels])),
                     "levels": largest.meta["trees"][0]["levels"],
                     "samples": levels[0]["samples"],
                     "eval_frames_per_second": res["frames_curve"][-1]["frames_per_second"]}
    res["ablation"] = []
    n_abl = min(plan["ablation_frames"], n_train)
    for s in TRAIN_SENSORS:
        forest = train_forest([train[s]], params, max_frames=n_abl)
        res["ablation"].append({"train_sensor": s, "frames": n_abl,
                                "train_seconds": forest.meta["train_seconds"],
                                "test": {t: scores(forest, test[t]) for t in TEST_SENSORS}})
        print(f"ablation train {s}: done", flush=True)
    res["seconds"] = time.perf_counter() - t_start
    res["table"] = table(res)
    (out / "study.json").write_text(json.dumps(res, indent=1))
    (out / "study.txt").write_text(res["table"] + "\n")
    plot(res, out)
    print(res["table"])
    print(f"wrote {out}/study.json, study.txt, curve_frames.png, curve_depth_trees.png, "
          "ablation.png")


if __name__ == "__main__":
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    main()
