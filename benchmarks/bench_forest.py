"""Forest inference speed: frames/s on a 640x480 frame with a person, on one core.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_forest.py [--repeats 50]
        [--backend egl] [--forest out/forest.npz]

The frame is a posed MakeHuman body rendered at 2.5 m (GL, as in bench_sensor.py), depth in
millimetres. Forests:

* ``complete d20``: 3 trees of depth 20 with every path 20 nodes long (random features and
  thresholds, 2^20 leaves per tree): the worst case of Shotton's 3 x 20 setting, and the
  shape of PCL's shipped trees (complete, padded);
* ``--forest FILE``: any trained forest, with its mean path length on this frame. The
  numbers in docs/performance.md use a 3 x depth-20 forest trained on 600 generated
  frames (Shotton's depth and tree count, the forest study's sampling; about 2 minutes on
  2 cores)::

      vhgen generate configs/forest/train.yaml --max-frames 600 --out out/bench_train.zarr
      vhgen forest train out/bench_train.zarr --out out/bench_forest.npz \
          --pixels-per-image 300 --features 300 --thresholds 25 --min-samples 16 --seed 1

The single-frame kernel is serial; the table shows the median wall time over ``--repeats``
runs, its 90th percentile, and the median CPU time of the thread (what the frame costs on
one core when the machine is shared; frames/s from both).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

os.environ.setdefault("NUMBA_NUM_THREADS", "1")


def complete_forest(trees: int, depth: int, num_classes: int, seed: int):
    """Random complete trees (children of i at 2i+1, 2i+2 within each tree)."""
    from vhgen.forest.features import draw_offsets
    from vhgen.forest.trees import Forest

    rng = np.random.default_rng(seed)
    n = 2 ** (depth + 1) - 1
    inner = 2**depth - 1
    parts = []
    for t in range(trees):
        idx = np.arange(n)
        left = np.where(idx < inner, 2 * idx + 1 + t * n, -1).astype(np.int32)
        counts = np.zeros((n, num_classes), np.uint8)
        counts[np.arange(inner, n), rng.integers(1, num_classes, n - inner)] = 1
        parts.append((draw_offsets(rng, n, 130), rng.integers(-300, 301, n).astype(np.int32),
                      left, np.floor(np.log2(idx + 1)).astype(np.int16), counts))
    cat = [np.concatenate([p[i] for p in parts]) for i in range(5)]
    return Forest(offsets=cat[0], thresh=cat[1], left=cat[2], depth=cat[3], counts=cat[4],
                  roots=np.arange(trees, dtype=np.int64) * n,
                  meta={"label_names": [f"p{k}" for k in range(1, num_classes)]})


def mean_path(forest, depth_mm: np.ndarray) -> float:
    """Mean number of split nodes visited per body pixel and tree (Python, small sample)."""
    from vhgen.forest.features import feature_at, prepare_depth

    d = prepare_depth(depth_mm)
    ys, xs = np.nonzero(depth_mm > 0)
    pick = np.random.default_rng(0).choice(len(ys), min(300, len(ys)), replace=False)
    steps = 0
    for t in range(forest.num_trees):
        for i in pick:
            node = int(forest.roots[t])
            while forest.left[node] >= 0:
                o = forest.offsets[node]
                f = feature_at.py_func(d, int(xs[i]), int(ys[i]), *map(int, o))
                node = int(forest.left[node]) + (1 if f > forest.thresh[node] else 0)
                steps += 1
    return steps / (forest.num_trees * len(pick))


def main() -> None:
    from vhgen.assets import resolve_asset_dir
    from vhgen.forest.trees import Forest, Predictor
    from vhgen.mocap.clips import builtin_motion_path
    from vhgen.quality.fidelity_scenes import human_frame
    from vhgen.render.context import create_context
    from vhgen.sensor.simulator import SensorConfig

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument("--backend", default="egl")
    ap.add_argument("--forest", help="also time this trained forest (.npz)")
    args = ap.parse_args()
    ref = SensorConfig.load("kinect_v1_full")
    ctx = create_context(args.backend)
    fr = human_frame(ctx, ref.intrinsics, ref.baseline_m, resolve_asset_dir(),
                     builtin_motion_path(), wall=None)
    depth = np.where(fr.depth > 0, np.round(fr.depth * 1000), 0).astype(np.uint16)
    body = int((depth > 0).sum())
    forests = [("complete d20 x3", complete_forest(3, 20, 26, seed=0))]
    if args.forest:
        forests.append((os.path.basename(args.forest), Forest.load(args.forest)))
    import numba

    print(f"frame 640x480, {body} body pixels; numba threads {numba.get_num_threads()}")
    print(f"{'forest':<22} {'trees':>5} {'nodes':>8} {'max depth':>9} {'path':>6} {'ms/frame':>9} "
          f"{'p90 ms':>7} {'cpu ms':>7} {'frames/s':>9} {'cpu f/s':>8}")
    for name, forest in forests:
        pred = Predictor(forest)
        pred.predict(depth)  # compile / warm caches
        times, cpu = [], []
        for _ in range(args.repeats):
            t0, c0 = time.perf_counter(), time.thread_time()
            pred.predict(depth)
            times.append(time.perf_counter() - t0)
            cpu.append(time.thread_time() - c0)
        med, p90 = np.median(times) * 1e3, np.percentile(times, 90) * 1e3
        cmed = np.median(cpu) * 1e3
        print(f"{name:<22} {forest.num_trees:>5d} {len(forest.left):>8d} "
              f"{int(forest.depth.max()):>9d} "
              f"{mean_path(forest, depth):>6.1f} {med:>9.2f} {p90:>7.2f} {cmed:>7.2f} "
              f"{1e3 / med:>9.1f} {1e3 / cmed:>8.1f}")


if __name__ == "__main__":
    main()
