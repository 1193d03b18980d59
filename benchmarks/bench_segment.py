"""The segmentation stage's time per frame, step by step, on frames of a store.

    .venv/bin/python benchmarks/bench_segment.py STORE [--forest FOREST.npz]
        [--frames 40]

STORE: any store with people, e.g. the held-out groups of the forest's recipe
(``vhgen generate configs/forest/people_test.yaml --out out/people_test.zarr``). The
labels the stage reads are the forest's (``--forest``, its trees' labels, not timed) or,
without one, the store's own rendered parts (the steps' work is the same). Per frame and
on one core: cutting it into candidates (planes, clusters, heads:
``Segmenter.candidates``), then describing them for the person stage
(``Segmenter.describe``) with and without the surface normals
(``vhgen.geom.normals``), the two alternated frame by frame so that a noisy machine
weighs on both alike. Prints a table of the mean and median milliseconds.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("store")
    ap.add_argument("--forest", default=None)
    ap.add_argument("--frames", type=int, default=40)
    args = ap.parse_args()

    import vhgen.forest.segment as segment
    from vhgen.forest.data import store_info
    from vhgen.store.zarr_store import open_store, read_frames

    info = store_info(args.store)
    n = min(args.frames, info.num_frames)
    got = read_frames(open_store(args.store), ("depth", "labels"), np.arange(n, dtype=np.int64),
                      info.frames_per_shard)
    labels, heights = got["labels"], None
    if args.forest:
        from vhgen.forest.trees import Forest, predictors_at_focal

        forest = Forest.load(args.forest)
        labels = predictors_at_focal(forest)(info.fx, info.fy).predict(got["depth"])
        heights = forest.person_stage.part_heights if forest.person_stage else None
    seg = segment.Segmenter()
    measured = segment.patch_normals

    def no_normals(points: np.ndarray, mask: np.ndarray, fx: float) -> np.ndarray:
        return np.zeros((0, 3))

    times: dict[str, list[float]] = {"candidates": [], "describe": [],
                                     "describe, no surface normals": []}
    for i in range(n):
        t0 = time.perf_counter()
        cand = seg.candidates(got["depth"][i], info.intrinsics, labels[i])
        times["candidates"].append(time.perf_counter() - t0)
        order = [("describe", measured), ("describe, no surface normals", no_normals)]
        for name, normals in order if i % 2 == 0 else order[::-1]:
            segment.patch_normals = normals
            t0 = time.perf_counter()
            seg.describe(cand, got["depth"][i], info.intrinsics, labels[i],
                         part_heights=heights)
            times[name].append(time.perf_counter() - t0)
        segment.patch_normals = measured
    print(f"{args.store}: {n} frames, labels from "
          f"{args.forest or 'the store (rendered parts)'}")
    print(f"{'step':32s} {'mean ms':>8s} {'median ms':>10s}")
    for name, t in times.items():
        ms = 1000.0 * np.asarray(t)
        print(f"{name:32s} {ms.mean():8.1f} {np.median(ms):10.1f}")


if __name__ == "__main__":
    main()
