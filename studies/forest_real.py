"""The proof on real frames: what each realism measure buys, measured on a real sensor.

Run through ``studies/forest_curves.py --real [--quick] [--out DIR] [--data DIR]
[--frames N] [--curve N,N,...]`` (the results in ``docs/forest_study/real_*`` come from
``--frames 560 --curve 280,560,1120``). Steps:

1. Frames for each generator setting (:data:`SETTINGS`), from the recommended training
   configs (``configs/forest/people_room.yaml``: clothed people in cluttered rooms,
   ``people_real.yaml``: people composited into three of the shared real captures)
   with each realism measure switched off in turn down to the *baseline* (the old 4 m
   sensor, a bare room with furniture, bare bodies, one person), then on one at a time,
   then all together. Every setting gets the same number of frames; its generator's
   frames per second (two local workers) is recorded.
2. One forest per setting, all with the same settings (:data:`PARAMS`), trained on a
   seeded random subset of that size.
3. Each forest on the real *check* frames, never used to build anything: ``person.pcd``
   (its person mask: ``docs/forest_study/real_masks/person.png``) and ``capture0004``,
   ``capture0005`` (nobody in them): person IoU, recall, precision and the share of
   background called a body part, the forest alone and with the segmentation stage
   (``forest label/eval --segment``); and on held-out synthetic frames
   (``people_test.yaml``: other motions and avatars) its mean per-class accuracy.
4. For the best setting, the curve of the real-frame metrics against training frames.
   Its largest forest is the recommended one (exported with ``forest export --format pcl``).

Writes DIR/real_study.json, real_study.txt, real_ablation.png, real_curve.png and the
check frames' sheets of the recommended forest (real_sheet.png, real_sheet_segment.png);
the generated stores go to ``--data`` (default DIR/real_data) and are reused by a rerun.
A store is reused by its setting's name, so after a change to the generator (a new
clutter kind, a sensor preset) delete the stores it affects (or use a fresh ``--data``);
a forest is reused only if it was trained on the very stores there now (its cache key
holds their manifests' digests).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared"
CHECK_PEOPLE = [SHARED / "real" / "person.pcd"]
CHECK_NOBODY = [SHARED / "real" / "capture0004.pcd", SHARED / "real" / "capture0005.pcd"]
MASKS = REPO / "docs" / "forest_study" / "real_masks"

# the old state of each measure: the 4 m sensor, a room with furniture only, bare bodies,
# one person
BASELINE_PATCH: dict[str, Any] = {"sensor": "openni_525_gate4m",
                                  "scene": {"clutter": None, "people": [1, 1]},
                                  "avatars": {"outfit": None}}
# setting -> list of (base config, patch, share of the frames)
SETTINGS: dict[str, list[tuple[str, dict, float]]] = {
    "baseline": [("people_room", BASELINE_PATCH, 1.0)],
    "+ fitted sensor": [("people_room", {**BASELINE_PATCH, "sensor": "openni_525"}, 1.0)],
    "+ clutter": [("people_room", {**BASELINE_PATCH, "scene": {"people": [1, 1]}}, 1.0)],
    "+ real backgrounds": [("people_real", {"sensor": "openni_525_gate4m",
                                            "scene": {"people": [1, 1]},
                                            "avatars": {"outfit": None}}, 1.0)],
    "+ clothing": [("people_room", {"sensor": "openni_525_gate4m",
                                    "scene": {"clutter": None, "people": [1, 1]}}, 1.0)],
    "+ 1-3 people": [("people_room", {**BASELINE_PATCH, "scene": {"clutter": None}}, 1.0)],
    "all": [("people_room", {}, 0.5), ("people_real", {}, 0.5)],
}
BEST = "all"
# Frames are poses x avatars of the whole plan (frame_step, avatars: a job's plan is
# avatar-major, so a cut plan would hold fewer avatars); a setting of two configs takes
# half from each. The ablation trains on `frames` of each setting (all of them), the curve
# on seeded random subsets of the best setting's `curve_step` stores.
QUICK: dict[str, Any] = {
    "frames": 140, "frame_step": 80, "avatars": 1, "curve_step": 40, "curve_avatars": 2,
    "curve": [70, 140, 280], "test_step": 40, "test_frames": 48,
    "params": {"trees": 2, "depth": 14, "pixels_per_image": 300, "features": 100,
               "thresholds": 15, "min_samples": 8, "background_share": 0.5}}
FULL: dict[str, Any] = {
    "frames": 1120, "frame_step": 40, "avatars": 4, "curve_step": 10, "curve_avatars": 4,
    "curve": [560, 1120, 2240, 4480, 8960], "test_step": 10, "test_frames": 240,
    "params": {"trees": 3, "depth": 20, "pixels_per_image": 300, "features": 300,
               "thresholds": 25, "min_samples": 16, "background_share": 0.5}}


def _merge(base: dict, patch: dict) -> dict:
    """``base`` with ``patch`` applied: nested mappings merged, None removes a key."""
    out = copy.deepcopy(base)
    for k, v in patch.items():
        if v is None:
            out.pop(k, None)
        elif isinstance(v, dict) and isinstance(out.get(k), dict) and v:
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def config(name: str, patch: dict, out: Path, frame_step: int, avatars: int | None = None
           ) -> Path:
    """A config file: ``configs/forest/<name>.yaml`` with ``patch`` applied, its paths made
    absolute, written to ``out``."""
    src = REPO / "configs" / "forest" / f"{name}.yaml"
    d = _merge(yaml.safe_load(src.read_text()), patch)
    d["motions"] = [str((src.parent / m).resolve()) for m in d["motions"]]
    bgs = d.get("scene", {}).get("backgrounds")
    if bgs:
        d["scene"]["backgrounds"] = [str((src.parent / b).resolve()) for b in bgs]
    d["poses"]["frame_step"] = frame_step
    if avatars is not None:
        d["avatars"]["count"] = avatars
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(yaml.safe_dump(d, sort_keys=False))
    return out


def generate(cfg_path: Path, store: Path, frames: int | None, backend: str, workers: int
             ) -> dict:
    """Frames of a config (reused if the store is complete); its frame rate."""
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    info = store.with_suffix(".json")
    if (store / "manifest.parquet").is_file() and info.is_file():
        return json.loads(info.read_text())
    cfg = JobConfig.load(cfg_path, num_workers=workers, backend=backend)
    s = run_job(cfg, store, overwrite=True, max_frames=frames)
    res = {"store": str(store), "frames": s.frames, "seconds": s.seconds,
           "frames_per_second": s.frames / s.render_seconds,
           "worker_ms_per_frame": 1000 * s.steady_seconds_per_frame,
           "valid_fraction": s.valid_fraction}
    info.write_text(json.dumps(res))
    print(f"generated {s.frames} frames -> {store} ({s.seconds:.0f} s, "
          f"{res['frames_per_second']:.1f} frames/s)", flush=True)
    return res


def real_scores(forest: Any, out_dir: Path | None = None) -> dict:
    """The forest on the check frames, alone and with the segmentation stage."""
    from vhgen.forest.commands import labeller
    from vhgen.forest.realeval import evaluate_real, load_real_frames

    frames = load_real_frames(CHECK_PEOPLE, CHECK_NOBODY, MASKS)
    res = {}
    for segment in (False, True):
        r = evaluate_real(labeller(forest, segment), frames, out_dir=None)
        if out_dir is not None:
            from vhgen.forest.realeval import real_sheet

            shown = [(f, labeller(forest, segment)(f.frame)) for f in frames]
            real_sheet(shown, forest.meta.get("label_colors"), forest.num_classes,
                       out_dir / ("real_sheet_segment.png" if segment else "real_sheet.png"))
        res["segment" if segment else "forest"] = {
            k: r[k] for k in ("person_iou", "person_recall", "person_precision",
                              "background_called", "background_called_nobody",
                              "background_called_people")}
    return res


def synthetic_score(forest: Any, test: str) -> float:
    from vhgen.forest.data import store_info
    from vhgen.forest.evaluate import evaluate

    return float(evaluate(forest, [store_info(test)])["mean_per_class"])


def _forest(stores: list[str], params: Any, n: int, cache: Path) -> Any:
    """The forest of ``n`` frames of ``stores`` (a seeded subset), trained once: kept in
    ``cache`` and loaded by a rerun (the same stores, frames and settings give the same
    forest)."""
    import hashlib

    from vhgen.forest.from_stores import train_forest
    from vhgen.forest.trees import Forest

    digests = [hashlib.sha1((Path(s) / "manifest.parquet").read_bytes()).hexdigest()
               for s in stores]
    key = hashlib.sha1(json.dumps([stores, digests, n, dataclasses.asdict(params)]
                                  ).encode()).hexdigest()[:12]
    path = cache / f"forest_{n}_{key}.npz"
    if path.is_file():
        return Forest.load(path)
    forest = train_forest(stores, params, max_frames=n)
    cache.mkdir(parents=True, exist_ok=True)
    forest.save(path)
    return forest


def _write(res: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "real_study.json").write_text(json.dumps(res, indent=1))


def real_study(out: Path, *, quick: bool, backend: str, workers: int,
               data: Path | None = None, frames: int | None = None,
               curve: list[int] | None = None) -> dict:
    """Steps 1-4 of the module docstring; returns and writes the results. ``data``: where
    the generated stores go (default OUT/real_data; kept and reused by a rerun)."""
    from vhgen.forest.train import TrainParams

    t0 = time.perf_counter()
    plan = dict(QUICK if quick else FULL)
    plan.update({k: v for k, v in (("frames", frames), ("curve", curve)) if v})
    data = data if data is not None else out / "real_data"
    params = TrainParams(seed=1, **plan["params"])
    n = plan["frames"]
    test_cfg = config("people_test", {}, data / "configs" / "test.yaml", plan["test_step"])
    test = generate(test_cfg, data / "test.zarr", plan["test_frames"], backend, workers)
    res: dict[str, Any] = {"quick": quick, "params": dataclasses.asdict(params),
                           "check_frames": {"people": [p.name for p in CHECK_PEOPLE],
                                            "nobody": [p.name for p in CHECK_NOBODY]},
                           "built_with": ["capture0001.pcd", "capture0002.pcd",
                                          "capture0003.pcd"],
                           "frames": n, "ablation": []}
    stores_of: dict[str, list[str]] = {}
    for name, parts in SETTINGS.items():
        stores, rates = [], []
        for k, (base, patch, share) in enumerate(parts):
            # the best setting's stores also make the curve: more poses of each avatar
            step, avatars = ((plan["curve_step"], plan["curve_avatars"]) if name == BEST
                             else (plan["frame_step"], max(1, round(plan["avatars"] * share))))
            cfg = config(base, patch, data / "configs" / f"{_slug(name)}_{k}.yaml", step,
                         avatars)
            g = generate(cfg, data / f"{_slug(name)}_{k}.zarr", None, backend, workers)
            stores.append(g["store"])
            rates.append(g)
        stores_of[name] = stores
        forest = _forest(stores, params, n, data / "forests")
        n_used = forest.meta["frames"]
        row = {"setting": name, "frames": n_used, "train_seconds": forest.meta["train_seconds"],
               "generator_frames_per_second": float(np.mean([r["frames_per_second"]
                                                             for r in rates])),
               "worker_ms_per_frame": float(np.mean([r["worker_ms_per_frame"]
                                                     for r in rates])),
               "synthetic_mean_per_class": synthetic_score(forest, test["store"]),
               "real": real_scores(forest)}
        res["ablation"].append(row)
        _write(res, out)
        print(_row(row), flush=True)
    res["curve"] = []
    largest = None
    for m in plan["curve"]:
        forest = _forest(stores_of[BEST], params, m, data / "forests")
        row = {"frames": m, "train_seconds": forest.meta["train_seconds"],
               "synthetic_mean_per_class": synthetic_score(forest, test["store"]),
               "real": real_scores(forest)}
        res["curve"].append(row)
        _write(res, out)
        print(f"curve {m}: " + _row({**row, "setting": BEST}), flush=True)
        largest = forest
    assert largest is not None
    largest.save(out / "recommended_forest.npz")
    real_scores(largest, out)
    res["seconds"] = time.perf_counter() - t0
    res["table"] = table(res)
    out.mkdir(parents=True, exist_ok=True)
    (out / "real_study.json").write_text(json.dumps(res, indent=1))
    (out / "real_study.txt").write_text(res["table"] + "\n")
    plot(res, out)
    print(res["table"])
    return res


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name).strip("_") or "x"


def _row(r: dict) -> str:
    f, s = r["real"]["forest"], r["real"]["segment"]
    return (f"{r['setting']:<20} IoU {f['person_iou']:.3f} / {s['person_iou']:.3f}  "
            f"bg {f['background_called']:.3f} / {s['background_called']:.3f}  "
            f"synthetic {r['synthetic_mean_per_class']:.3f}")


def table(res: dict) -> str:
    """The study as text: the ablation, then the curve."""
    def cols(r: dict) -> str:
        f, s = r["real"]["forest"], r["real"]["segment"]
        return (f"{f['person_iou']:>6.3f} {f['background_called']:>6.3f} "
                f"{s['person_iou']:>6.3f} {s['person_recall']:>6.3f} "
                f"{s['background_called']:>6.3f} {r['synthetic_mean_per_class']:>9.3f}")

    head = (f"{'IoU':>6} {'bg':>6} {'IoU':>6} {'recall':>6} {'bg':>6} {'synthetic':>9}")
    L = [f"check frames: with a person {', '.join(res['check_frames']['people'])}; with "
         f"nobody {', '.join(res['check_frames']['nobody'])} (real backgrounds built from "
         f"{', '.join(res['built_with'])} only)",
         f"forest: {res['params']['trees']} trees, depth {res['params']['depth']}, "
         f"{res['params']['pixels_per_image']} pixels per image, {res['params']['features']}"
         f" features x {res['params']['thresholds']} thresholds",
         "", f"ablation, {res['frames']} training frames each: real check frames (forest | "
         "forest + segmentation), synthetic held-out mean per-class accuracy, generator",
         f"{'setting':<20} {'forest':^13} {'forest + segmentation':^20} {'':>9} "
         f"{'frames/s':>9} {'ms/frame':>9}",
         f"{'':<20} {head}"]
    for r in res["ablation"]:
        L.append(f"{r['setting']:<20} {cols(r)} {r['generator_frames_per_second']:>9.1f} "
                 f"{r['worker_ms_per_frame']:>9.1f}")
    L += ["", f"curve ({BEST}): real check frames against training frames",
          f"{'frames':<20} {head} {'train s':>9}"]
    for r in res["curve"]:
        L.append(f"{r['frames']:<20d} {cols(r)} {r['train_seconds']:>9.0f}")
    L += ["", f"total study time {res['seconds']:.0f} s"]
    return "\n".join(L)


def plot(res: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [r["setting"] for r in res["ablation"]]
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    w = 0.38
    for ax, key, lab in ((axes[0], "person_iou", "person IoU (real)"),
                         (axes[1], "background_called", "background called a body part")):
        for j, stage in enumerate(("forest", "segment")):
            ax.bar(np.arange(len(names)) + (j - 0.5) * w,
                   [r["real"][stage][key] for r in res["ablation"]], w,
                   label="forest" if stage == "forest" else "forest + segmentation")
        ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(lab)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "real_ablation.png", dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    n = [r["frames"] for r in res["curve"]]
    for stage, style in (("forest", "o--"), ("segment", "o-")):
        lab = "forest" if stage == "forest" else "forest + segmentation"
        ax.plot(n, [r["real"][stage]["person_iou"] for r in res["curve"]], style,
                label=f"person IoU, {lab}")
        ax.plot(n, [r["real"][stage]["background_called"] for r in res["curve"]],
                style.replace("o", "s"), label=f"background called, {lab}")
    ax.set_xscale("log")
    ax.set_xlabel(f"training frames ({BEST})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "real_curve.png", dpi=100)
    plt.close(fig)
