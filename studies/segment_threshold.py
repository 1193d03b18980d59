"""How the segmentation stage's ``min_body_fraction`` trades people kept against clutter
passed, on build data: synthetic frames of the forest's own stores it was not trained on.

    python studies/segment_threshold.py FOREST.npz [--frames 60] [--seed 0]
        [--fractions 0.5,0.6,0.7,0.8,0.9]

Draws ``--frames`` frames (seeded) of the stores the forest names in its metadata, leaving
out the frames it trained on (the same seeded subset as ``forest train --max-frames``),
labels them with the forest and cuts them into the stage's clusters. Clusters that pass
the size and extent tests are *person* clusters when most of their pixels are body
pixels in the rendered truth, else *other* clusters. For each fraction: the share of the
person clusters' pixels kept (the cluster called a person) and of the other clusters'
pixels passed. Never run on real check frames: the threshold must not be chosen on them.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main() -> None:
    from vhgen.camera import Intrinsics
    from vhgen.forest.data import read_frames, select_frames, store_info
    from vhgen.forest.segment import Segmenter
    from vhgen.forest.trees import Forest, Predictor
    from vhgen.store.zarr_store import read_attrs

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("forest")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fractions", default="0.5,0.6,0.7,0.8,0.9")
    args = ap.parse_args()
    fractions = [float(x) for x in args.fractions.split(",")]
    t0 = time.perf_counter()
    forest = Forest.load(args.forest)
    infos = [store_info(s) for s in forest.meta["stores"]]
    trained = {g for _, _, g in select_frames(infos, int(forest.meta["frames"]),
                                              int(forest.meta["params"]["seed"]))}
    every = select_frames(infos, None, 0)
    rest = [f for f in every if f[2] not in trained]
    rng = np.random.default_rng(args.seed)
    pick = sorted(rng.choice(len(rest), size=min(args.frames, len(rest)), replace=False))
    frames = [rest[i] for i in pick]
    predictor, seg = Predictor(forest), Segmenter()
    kept = np.zeros(len(fractions))
    passed = np.zeros(len(fractions))
    person_px = other_px = 0
    for frame in frames:
        depth, labels = read_frames([frame])
        depth, truth = depth[0], labels[0]
        intr = read_attrs(frame[0])["sensor"]["intrinsics"]
        h, w = depth.shape
        cam = Intrinsics(w, h, intr["fx"], intr["fy"], intr["cx"], intr["cy"])
        pred = predictor.predict(depth)
        comp, table = seg.cluster_table(depth, cam, pred)
        size = table["pixels"]
        body_truth = np.bincount(comp.ravel(), weights=(truth > 0).ravel(),
                                 minlength=len(size))
        ok = ((size >= seg.min_pixels) & (table["extent_m"] >= seg.min_extent_m)
              & (table["extent_m"] <= seg.max_extent_m))
        ok[0] = False
        is_person = ok & (body_truth > 0.5 * size)
        is_other = ok & ~is_person
        person_px += size[is_person].sum()
        other_px += size[is_other].sum()
        for k, frac in enumerate(fractions):
            called = replace(seg, min_body_fraction=frac).is_person(table)
            kept[k] += size[is_person & called].sum()
            passed[k] += size[is_other & called].sum()
    print(f"forest {args.forest}: {len(frames)} build frames not trained on, "
          f"{person_px:.0f} person-cluster pixels, {other_px:.0f} other-cluster pixels "
          f"({time.perf_counter() - t0:.0f} s)")
    print(f"{'min_body_fraction':>18} {'person kept':>12} {'other passed':>13}")
    for k, frac in enumerate(fractions):
        print(f"{frac:>18.2f} {kept[k] / max(person_px, 1):>12.3f} "
              f"{passed[k] / max(other_px, 1):>13.3f}")


if __name__ == "__main__":
    main()
