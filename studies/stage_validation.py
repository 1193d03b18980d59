"""The person stage on a validation split of its own training stores: frames that neither
the forest nor its person stage trained on.

    python studies/stage_validation.py FOREST.npz [FOREST.npz ...] [--val 320] [--after N]

For each forest (with a person stage, ``forest person-stage``): the stage's stores, frame
count N and seed from the forest's file; the validation frames are the next ``--val``
frames of the stage's own seeded draw (``person_stage_frames`` with N + val frames, less
its first N), so they are never the part forest's nor the stage's; ``--after N`` starts
them after the draw's first N frames instead (at least the stage's own count), so that
stages of different frame counts are scored on the same frames. Labels them with the
forest, keeps the people the segmentation stage and the person stage keep (``--segment``)
and prints the person scores of ``forest eval`` (found and pixel precision by distance
and group size). Forests whose stages drew from the same stores, count and seed are
scored on the same frames: how the person stage's features, training views and trees
were chosen (docs/forest.md, "The person stage"), before the held-out ``people_test`` and
the real check frames were scored.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main() -> None:
    from vhgen.forest.data import store_info
    from vhgen.forest.from_stores import person_stage_frames
    from vhgen.forest.persons import PeopleScore, frame_people, table
    from vhgen.forest.segment import Segmenter
    from vhgen.forest.trees import Forest, Predictor
    from vhgen.store.zarr_store import open_store
    from vhgen.store.zarr_store import read_frames as read_store_frames

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("forests", nargs="+")
    ap.add_argument("--val", type=int, default=320, help="validation frames (default 320)")
    ap.add_argument("--after", type=int, default=0,
                    help="start after this many frames of the draw (default: the stage's)")
    args = ap.parse_args()
    seg = Segmenter()
    for path in args.forests:
        t0 = time.perf_counter()
        forest = Forest.load(path)
        meta = forest.meta.get("person_stage")
        if forest.person_stage is None or not meta:
            sys.exit(f"{path}: no person stage (forest person-stage adds one)")
        stores, n, seed = list(meta["stores"]), int(meta["frames"]), int(meta["seed"])
        if args.after and args.after < n:
            sys.exit(f"{path}: --after {args.after} is below the stage's {n} frames")
        first = args.after or n
        taken = set(person_stage_frames(forest, stores, first, seed))
        val = [t for t in person_stage_frames(forest, stores, first + args.val, seed)
               if t not in taken]
        pred = Predictor(forest)
        score = PeopleScore(called_by="segmentation + person stage")
        for store in sorted({p for p, _, _ in val}):
            frames = np.asarray(sorted(f for p, f, _ in val if p == store), np.int64)
            got = read_store_frames(open_store(store), ("depth", "instances"), frames,
                                    store_info(store).frames_per_shard)
            intr = store_info(store).intrinsics
            for s in range(0, len(frames), 16):
                depth = got["depth"][s:s + 16]
                labels = pred.predict(depth)
                for i, d in enumerate(depth):
                    inst = seg.instances(d, intr, labels[i], forest.person_stage)
                    score.add(frame_people(inst, d, got["instances"][s + i]),
                              (store, int(frames[s + i])))
        print(f"{path}: {len(val)} validation frames of {len(stores)} stores "
              f"(the draw's first {first} frames, seed {seed}, left out; the stage took {n}), "
              f"{time.perf_counter() - t0:.0f} s")
        print(table(score.result()))
        print()


if __name__ == "__main__":
    main()
