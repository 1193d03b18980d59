"""Where the segmentation stage's wrong person pixels are, on held-out synthetic frames.

    python studies/person_precision.py FOREST.npz STORE [--frames 96] [--seed 0]

Labels ``--frames`` frames (seeded) of ``STORE`` (a held-out store with ``classes``, e.g.
``people_test.yaml``'s) with the forest and its person stage (``--segment``) and splits
the pixels called a person that the rendered truth says are not one: in candidates that
are mostly a person versus in candidates that are not, by the scene class the renderer
gave them, and by their distance in the image to the nearest true person pixel. The last
table is the pixel precision with the false pixels within k px of a person left out:
the sensor's correlation window fattens a near surface's edge by up to half its width
(4 px for 9x9), and those pixels carry the person's depth but the background's rendered
label. Nothing is chosen here; it says what bounds the precision.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main() -> None:
    import zarr
    from scipy import ndimage

    from vhgen.forest.data import read_frames, select_frames, store_info
    from vhgen.forest.segment import Segmenter
    from vhgen.forest.trees import Forest, Predictor

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("forest")
    ap.add_argument("store")
    ap.add_argument("--frames", type=int, default=96)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    forest = Forest.load(args.forest)
    if forest.person_stage is None:
        sys.exit(f"{args.forest}: no person stage (forest person-stage adds one)")
    pred = Predictor(forest)
    info = store_info(args.store)
    root = zarr.open_group(args.store, mode="r")
    if "classes" not in root:
        sys.exit(f"{args.store}: no classes array")
    attrs: Any = root.attrs.get("class_names") or []
    names = [str(n) for n in attrs]
    classes: Any = root["classes"]
    seg = Segmenter()
    frames = select_frames([info], args.frames, args.seed)
    by_class = {"in person candidates": np.zeros(256), "in other candidates": np.zeros(256)}
    near: list[np.ndarray] = []
    tp = fp = 0
    for s in range(0, len(frames), 16):
        part = frames[s:s + 16]
        depth, labels = read_frames(part)
        lab = pred.predict(depth)
        for i, (_, fr, _) in enumerate(part):
            d = depth[i]
            comp, x = seg.features(d, info.intrinsics, lab[i])
            inst = seg.instances(d, info.intrinsics, lab[i], forest.person_stage)
            truth = labels[i] > 0
            called = (inst > 0) & (d > 0)
            false = called & ~truth
            tp += int((called & truth).sum())
            fp += int(false.sum())
            n = comp.max() + 1
            share = np.bincount(comp.ravel(), weights=truth.ravel(), minlength=n) / np.maximum(
                np.bincount(comp.ravel(), minlength=n), 1)
            mostly = share[comp] >= 0.5
            c = np.asarray(classes[fr])
            by_class["in person candidates"] += np.bincount(c[false & mostly], minlength=256)
            by_class["in other candidates"] += np.bincount(c[false & ~mostly], minlength=256)
            near.append(ndimage.distance_transform_edt(~truth)[false])
    dist = np.concatenate(near) if near else np.zeros(0)
    print(f"{len(frames)} frames of {args.store}: pixel precision {tp / max(tp + fp, 1):.4f} "
          f"({fp} wrong pixels)")
    print(f"\n{'wrong pixels':<22} {'share':>6}  top scene classes (share of all wrong pixels)")
    for where, h in by_class.items():
        top = [k for k in np.argsort(-h)[:6] if h[k] > 0]
        print(f"{where:<22} {h.sum() / max(fp, 1):>6.3f}  " + ", ".join(
            f"{names[k] if k < len(names) else k} {h[k] / max(fp, 1):.3f}" for k in top))
    print(f"\n{'within k px of a person':<24} {'share of wrong':>14} {'precision without':>18}")
    for k in (1, 2, 3, 4, 6):
        m = int((dist <= k).sum())
        print(f"{k:<24} {m / max(fp, 1):>14.3f} {tp / max(tp + fp - m, 1):>18.4f}")


if __name__ == "__main__":
    main()
