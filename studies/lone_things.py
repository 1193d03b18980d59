"""How often the segmentation stage calls a thing with nothing around it a person.

    python studies/lone_things.py STORE FOREST.npz [FOREST.npz ...] [--frames 160] [--seed 0]

Takes ``--frames`` frames (seeded) of ``STORE`` (a held-out store with ``classes``, e.g.
``people_test.yaml``'s), keeps only their free-standing things (furniture, props,
clutter: :func:`vhgen.forest.data.lone_things_view`, no person, no floor, no walls), and
labels them with each forest and its person stage, as ``forest label --segment`` would.
Prints the share of the things' measured pixels called a person and the frames with any:
what a stage learnt from people alone (``forest person-stage --cut-out``) risks, since a
pipeline that removed the background can leave an object alone. Nothing is chosen here
(docs/forest_log.md, "Lone things as no people").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main() -> None:
    from vhgen.forest.data import (
        class_names,
        lone_things_view,
        read_classes,
        read_frames,
        select_frames,
        store_info,
    )
    from vhgen.forest.segment import Segmenter
    from vhgen.forest.trees import Forest, Predictor

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("store")
    ap.add_argument("forests", nargs="+")
    ap.add_argument("--frames", type=int, default=160)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    info = store_info(args.store)
    if not info.has_classes:
        raise SystemExit(f"{args.store}: no classes array (scene classes tell the things)")
    names = class_names(args.store)
    frames = select_frames([info], args.frames, args.seed)
    seg = Segmenter()
    for name in args.forests:
        forest = Forest.load(name)
        pred = Predictor(forest)
        called = measured = with_any = 0
        for s in range(0, len(frames), 16):
            part = frames[s:s + 16]
            depth, labels = read_frames(part)
            classes = read_classes(part, depth.shape)
            view = np.stack([lone_things_view(depth[i], labels[i], classes[i], names)
                             for i in range(len(part))])
            lab = pred.predict(view)
            for i in range(len(part)):
                comp, person = seg.people(view[i], info.intrinsics, lab[i],
                                          forest.person_stage)
                hit = person[comp] & (view[i] > 0)
                called += int(hit.sum())
                measured += int((view[i] > 0).sum())
                with_any += bool(hit.any())
        print(f"{name}: {called / max(measured, 1):.4f} of the lone things' pixels called a "
              f"person; frames with any: {with_any} / {len(frames)}")


if __name__ == "__main__":
    main()
