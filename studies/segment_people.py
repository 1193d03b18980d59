"""What the segmentation stage's geometry loses, with the forest out of the question: the
rendered truth labels stand in for a forest's, so every loss is the stage's (planes,
clusters, splitting, size and extent tests), by distance and group size.

    python studies/segment_people.py STORE [--frames 40] [--seed 0]

STORE: a vhgen store with people (``instances`` array), e.g. one made from
``configs/forest/people_test.yaml``. Prints, for the stage before issue 27 (every plane
background, one candidate per cluster) and now (planes that stand in front of the room
kept, clusters split at heads): person instances found (at least half of their visible
pixels kept, and no other person holding more of them than they do) and person pixels
kept, per distance bin of the person (median depth) and per group size of the frame.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

BINS = [(0.0, 1.0, "<1 m"), (1.0, 2.0, "1-2 m"), (2.0, 3.0, "2-3 m"), (3.0, 4.5, "3-4.5 m"),
        (4.5, 99.0, ">4.5 m")]
GROUPS = [(1, 1, "1 person"), (2, 3, "2-3 people"), (4, 6, "4-6 people"), (7, 255, "7+")]


def main() -> None:
    import vhgen.dataset as vd
    from vhgen.camera import Intrinsics
    from vhgen.forest.segment import Segmenter

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("store")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    ds = vd.open(args.store, arrays=["depth", "labels", "instances"],
                 columns=["width", "height", "fx", "fy", "cx", "cy"])
    rng = np.random.default_rng(args.seed)
    frames = np.sort(rng.choice(len(ds), min(args.frames, len(ds)), replace=False))
    stages = {"before": Segmenter(min_patch_m=0.0, keep_occluders=False, split=False),
              "now": Segmenter()}
    # (stage, row) -> [found, instances, pixels kept, pixels]
    tally: dict[tuple[str, str], list[float]] = {}
    seconds = dict.fromkeys(stages, 0.0)
    for f in frames:
        item = ds[int(f)]
        m = item["manifest"]
        intr = Intrinsics(int(m["width"]), int(m["height"]), m["fx"], m["fy"], m["cx"],
                          m["cy"])
        depth, labels, inst = item["depth"], item["labels"], item["instances"]
        person = (labels > 0) & (depth > 0)
        people = [k for k in np.unique(inst[person]) if (person & (inst == k)).sum() >= 100]
        group = next(name for lo, hi, name in GROUPS if lo <= len(people) <= hi)
        for name, seg in stages.items():
            t0 = time.perf_counter()
            found = seg.instances(depth, intr, labels)
            seconds[name] += time.perf_counter() - t0
            for k in people:
                mk = person & (inst == k)
                z = float(np.median(depth[mk])) / 1000.0
                dist = next(b for lo, hi, b in BINS if lo <= z < hi)
                ids, counts = np.unique(found[mk], return_counts=True)
                best = ids[np.argmax(counts)]
                ok = best > 0 and counts.max() >= 0.5 * mk.sum()
                if ok:  # that instance is mostly this person, not a merge of several
                    share = (inst[(found == best) & person] == k).mean()
                    ok = bool(share >= 0.5)
                for row in (dist, group, "all"):
                    t = tally.setdefault((name, row), [0, 0, 0, 0])
                    t[0] += ok
                    t[1] += 1
                    t[2] += int((found[mk] > 0).sum())
                    t[3] += int(mk.sum())
    rows = [b for _, _, b in BINS] + [g for _, _, g in GROUPS] + ["all"]
    print(f"{len(frames)} frames of {args.store}; truth labels in place of a forest's")
    print(f"{'':<12} {'people':>7} | {'found before':>12} {'now':>7} | "
          f"{'pixels kept before':>18} {'now':>7}")
    for r in rows:
        if ("now", r) not in tally:
            continue
        b, n = tally[("before", r)], tally[("now", r)]
        print(f"{r:<12} {n[1]:>7} | {b[0] / b[1]:>12.3f} {n[0] / n[1]:>7.3f} | "
              f"{b[2] / b[3]:>18.3f} {n[2] / n[3]:>7.3f}")
    print(f"seconds per frame: before {seconds['before'] / len(frames):.3f}, "
          f"now {seconds['now'] / len(frames):.3f}")


if __name__ == "__main__":
    main()
