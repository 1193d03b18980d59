"""How much of a person the part forest calls a body part: vhgen people against real ones.

    python studies/forest_vote.py FOREST.npz STORE [--frames 48] [--people-only DIR ...]
        [--fx F]

The person stage leans on the forest's vote (``body``: the share of a segmentation
candidate called a body part, :data:`vhgen.forest.segment.FEATURES`). For the first
``--frames`` frames of ``STORE`` (a held-out store, e.g. ``people_test.yaml``'s), prints
the quartiles of ``body`` over the candidates that are people (most of their pixels a
person's), by median depth, in whole frames and in the same frames with the people cut
out alone (:func:`vhgen.forest.from_stores.cut_out_view`); then, for each real frame of
``--people-only`` (frames whose source removed the background, e.g.
``../shared/real/skeltrack``), every candidate with its depth, ``body`` and the stage's
probability, the forest's probes scaled to ``--fx`` (the focal length of the real
frames' camera when they do not record one; default: the forest's training one). Nothing
is chosen here: it shows where the forest transfers less
(docs/forest_log.md, "The forest's vote on real people").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

BINS_M = (0.0, 1.5, 2.5, 3.5, np.inf)
RANGES = tuple(zip(BINS_M[:-1], BINS_M[1:], strict=True))


def main() -> None:
    from vhgen.depthfile import depth_files, read_depth
    from vhgen.forest.commands import frame_intrinsics
    from vhgen.forest.data import read_classes, read_frames, store_info
    from vhgen.forest.from_stores import cut_out_view, stage_rows
    from vhgen.forest.segment import FEATURES, Segmenter
    from vhgen.forest.trees import Forest, predictors_at_focal

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("forest")
    ap.add_argument("store")
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--people-only", nargs="*", default=[])
    ap.add_argument("--fx", type=float, default=None)
    args = ap.parse_args()
    forest = Forest.load(args.forest)
    at, seg = predictors_at_focal(forest), Segmenter()
    info = store_info(args.store)
    pred = at(info.fx, info.fy)
    if not info.has_classes:
        raise SystemExit(f"{args.store}: no classes array (the cut-out views need it)")
    body, depth_m = FEATURES.index("body"), FEATURES.index("depth_m")
    rows: dict[str, list[tuple[float, float]]] = {"whole": [], "cut out": []}
    count = min(args.frames, info.num_frames)
    for s in range(0, count, 8):
        part = [(args.store, i, 0) for i in range(s, min(s + 8, count))]
        depth, truth = read_frames(part)
        views = {"whole": depth,
                 "cut out": cut_out_view(depth, truth, read_classes(part, depth.shape))}
        for name, view in views.items():
            labels = pred.predict(view)
            for i in range(len(part)):
                # the stage's own training rows: features, and whether each is a person
                x, person = stage_rows(seg, view[i], info.intrinsics, labels[i], truth[i],
                                       without_floor=False)
                rows[name] += [(float(r[depth_m]), float(r[body])) for r in x[person]]
    print(f"{args.forest} on {count} frames of {args.store}: body of person candidates, "
          "quartiles (people)")
    print("| view | " + " | ".join(f"{lo:g}-{hi:g} m" for lo, hi in RANGES)
          + " |")
    print("|---" * (len(RANGES) + 1) + "|")
    for name, r in rows.items():
        a = np.array(r).reshape(-1, 2)
        cells = []
        for lo, hi in RANGES:
            b = a[(a[:, 0] >= lo) & (a[:, 0] < hi), 1]
            cells.append(" / ".join(f"{q:.2f}" for q in np.quantile(b, [0.25, 0.5, 0.75]))
                         + f" ({len(b)})" if len(b) else "-")
        print(f"| {name} | " + " | ".join(cells) + " |")
    stage = forest.person_stage
    for path in depth_files(args.people_only):
        frame = read_depth(path)
        intr = frame_intrinsics(frame, forest, args.fx)
        labels = at(intr.fx, intr.fy).predict(frame.depth_mm)
        if stage is not None:  # described with the stage's own part heights
            comp, x, p = seg.person_probability(frame.depth_mm, intr, labels, stage)
        else:
            comp, x = seg.features(frame.depth_mm, intr, labels)
            p = np.full(len(x), np.nan)
        for c in np.flatnonzero(~np.isnan(x).any(1)):
            pixels = int((comp == c).sum())
            if pixels >= 5000:  # people, not the crumbs at their edges
                print(f"{Path(path).name}: candidate {c}, {pixels} pixels, "
                      f"{x[c, 0]:.2f} m, body {x[c, body]:.2f}, stage {p[c]:.2f}")


if __name__ == "__main__":
    main()
