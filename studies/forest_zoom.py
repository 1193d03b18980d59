"""How the part forest's vote changes with the camera's focal length (or a person's size).

    python studies/forest_zoom.py FOREST.npz [FOREST.npz ...] --store STORE [--frames 160]
        [--people-only DIR ...] [--zooms 0.8,0.9,1,1.1,1.25]

A camera with ``z`` times the training focal length sees a person ``z`` times larger at the
same depth; so does the training camera a person ``z`` times the size. For every person of
the first ``--frames`` frames of ``STORE`` (a held-out store with ``classes``) cut out
alone (:func:`vhgen.forest.from_stores.cut_out_view`, each person on their own, nothing
else measured), and for every frame of ``--people-only`` (real people whose background
their source removed), the frame is zoomed about its centre by each ``z``
(:func:`vhgen.forest.data.zoom_view`) and the share of the person's pixels each forest
calls a body part is printed: the median over the vhgen people by their median depth, and
per real frame. Nothing is chosen here (docs/forest.md, "The camera's focal length").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

BINS_M = (0.0, 1.7, 3.0, np.inf)


def body_share(predictor, depth: np.ndarray, mask: np.ndarray, zooms: list[float]) -> list[float]:
    """The share of ``mask``'s pixels called a body part in ``depth`` zoomed by each zoom."""
    from vhgen.forest.data import zoom_view

    alone = np.where(mask, depth, 0).astype(np.uint16)
    out = []
    for z in zooms:
        d, m = zoom_view(alone, mask.astype(np.uint8), z)
        labels = predictor.predict(d)
        out.append(float((labels[m > 0] > 0).mean()) if (m > 0).any() else np.nan)
    return out


def main() -> None:
    from vhgen.depthfile import depth_files, read_depth
    from vhgen.forest.data import read_classes, read_frames, read_instances, store_info
    from vhgen.forest.from_stores import cut_out_view
    from vhgen.forest.trees import Forest, Predictor

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("forests", nargs="+")
    ap.add_argument("--store", required=True)
    ap.add_argument("--frames", type=int, default=160)
    ap.add_argument("--people-only", nargs="*", default=[])
    ap.add_argument("--zooms", default="0.8,0.9,1,1.1,1.25")
    args = ap.parse_args()
    zooms = [float(z) for z in args.zooms.split(",")]
    info = store_info(args.store)
    if not info.has_classes:
        raise SystemExit(f"{args.store}: no classes array (the cut-out views need it)")
    count = min(args.frames, info.num_frames)
    head = " | ".join(f"x{z:g}" for z in zooms)
    for path in args.forests:
        predictor = Predictor(Forest.load(path))
        rows: list[tuple[float, list[float]]] = []
        for s in range(0, count, 8):
            part = [(args.store, i, 0) for i in range(s, min(s + 8, count))]
            depth, truth = read_frames(part)
            cut = cut_out_view(depth, truth, read_classes(part, depth.shape))
            instances, _ = read_instances(part, truth)
            for i in range(len(part)):
                inst = instances[i]
                for p in np.unique(inst)[1:]:
                    mask = (inst == p) & (cut[i] > 0)
                    if mask.sum() >= 1500:  # people, not slivers at the frame's edge
                        rows.append((float(np.median(cut[i][mask])) / 1000,
                                     body_share(predictor, cut[i], mask, zooms)))
        print(f"{path}: share of each person called a body part, the frame zoomed "
              f"(median over people; {count} frames of {args.store}, people cut out alone)")
        print(f"| people at | n | {head} |")
        print("|---|---" + "|---" * len(zooms) + "|")
        for lo, hi in zip(BINS_M[:-1], BINS_M[1:], strict=True):
            b = np.array([r for z, r in rows if lo <= z < hi]).reshape(-1, len(zooms))
            cells = " | ".join(f"{v:.2f}" for v in np.median(b, axis=0)) if len(b) else "-"
            print(f"| {lo:g}-{hi:g} m | {len(b)} | {cells} |")
        for frame_path in depth_files(args.people_only):
            d = np.asarray(read_depth(frame_path).depth_mm)
            cells = " | ".join(f"{v:.2f}" for v in body_share(predictor, d, d > 0, zooms))
            print(f"| {Path(frame_path).name} | 1 | {cells} |")


if __name__ == "__main__":
    main()
