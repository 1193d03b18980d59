"""How the part forest's vote changes with the camera's focal length (or a person's size),
and with the angle the camera sees a person at.

    python studies/forest_zoom.py FOREST.npz [FOREST.npz ...] --store STORE [--frames 160]
        [--people-only DIR ...] [--zooms 0.8,0.9,1,1.1,1.25] [--tilts=-20,-10,0,10,20,30]

A camera with ``z`` times the training focal length sees a person ``z`` times larger at the
same depth; so does the training camera a person ``z`` times the size. For every person of
the first ``--frames`` frames of ``STORE`` (a held-out store with ``classes``) cut out
alone (:func:`vhgen.forest.from_stores.cut_out_view`, each person on their own, nothing
else measured), and for every frame of ``--people-only`` (real people whose background
their source removed), the frame is zoomed about its centre by each ``z``
(:func:`vhgen.forest.data.zoom_view`) and the share of the person's pixels each forest
calls a body part is printed: the median over the vhgen people by their median depth, and
per real frame. ``--tilts``: a second table, each person's points turned about the level
axis across the image through their median depth by each angle (degrees; positive: the
lower body farther, as a camera looking further down sees a person, or a person leaning
forward) and seen again through the same camera (:func:`tilt_view`: the store's camera;
for the real frames one of ``--fx`` centred on the image). Nothing is chosen here
(docs/forest_log.md, "The camera's focal length" and "What the real people's vote does and
does not depend on").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

BINS_M = (0.0, 1.7, 3.0, np.inf)


def body_share(predictor, depth: np.ndarray, mask: np.ndarray, views: list) -> list[float]:
    """The share of ``mask``'s pixels called a body part in each view of ``depth`` (a view:
    (depth, mask) -> the new (depth, mask))."""
    out = []
    for view in views:
        d, m = view(np.where(mask, depth, 0).astype(np.uint16), mask)
        out.append(float((predictor.predict(d)[m] > 0).mean()) if m.any() else np.nan)
    return out


def zoomed(z: float):
    """The view of :func:`vhgen.forest.data.zoom_view` by ``z``."""
    from vhgen.forest.data import zoom_view

    def view(depth: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, m = zoom_view(depth, mask.astype(np.uint8), z)
        return d, m > 0

    return view


def tilted(intr, degrees: float):
    """The view of :func:`tilt_view` by ``degrees`` through the camera ``intr``."""
    return lambda depth, mask: tilt_view(depth, mask, intr, degrees)


def tilt_view(depth_mm: np.ndarray, mask: np.ndarray, intr, degrees: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) depth of the ``mask`` pixels alone, their points (camera ``intr``) turned by
    ``degrees`` about the level axis through their median depth on the optical axis (y
    down, z forward: a positive angle takes points below it farther), seen again by the
    same camera (nearest pixel, the nearest point wins; a pixel left empty among measured
    neighbours takes the farthest of them), and the new mask."""
    from scipy import ndimage

    from vhgen.camera import backproject, project

    keep = mask & (depth_mm > 0)
    p = backproject(intr, depth_mm / 1000.0)[keep]
    zc, a = float(np.median(p[:, 2])), np.radians(degrees)
    turn = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)],
                     [0.0, np.sin(a), np.cos(a)]])
    p = (p - [0.0, 0.0, zc]) @ turn.T + [0.0, 0.0, zc]
    uv = np.rint(np.nan_to_num(project(intr, p), nan=-1.0)).astype(np.int64)
    h, w = depth_mm.shape
    ok = ((uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
          & (p[:, 2] > 0.1))
    big = np.iinfo(np.int64).max
    out = np.full((h, w), big)
    np.minimum.at(out, (uv[ok, 1], uv[ok, 0]), np.rint(p[ok, 2] * 1000).astype(np.int64))
    out = np.where(out < big, out, 0)
    gaps = ndimage.binary_closing(out > 0) & (out == 0)
    out[gaps] = ndimage.maximum_filter(out, 3)[gaps]
    return out.astype(np.uint16), out > 0


def main() -> None:
    from vhgen.camera import Intrinsics
    from vhgen.depthfile import depth_files, read_depth
    from vhgen.forest.data import read_classes, read_frames, read_instances, store_info
    from vhgen.forest.from_stores import cut_out_view
    from vhgen.forest.trees import Forest, Predictor, predictors_at_focal

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("forests", nargs="+")
    ap.add_argument("--store", required=True)
    ap.add_argument("--frames", type=int, default=160)
    ap.add_argument("--people-only", nargs="*", default=[])
    ap.add_argument("--zooms", default="0.8,0.9,1,1.1,1.25")
    ap.add_argument("--tilts", default="", help="angles, degrees (a second table)")
    ap.add_argument("--fx", type=float, default=None,
                    help="focal length of the --people-only frames: the forest's probes "
                    "follow it (default: the training camera's)")
    args = ap.parse_args()
    zooms = [float(z) for z in args.zooms.split(",")]
    tilts = [float(t) for t in args.tilts.split(",")] if args.tilts else []
    info = store_info(args.store)
    if not info.has_classes:
        raise SystemExit(f"{args.store}: no classes array (the cut-out views need it)")
    count = min(args.frames, info.num_frames)
    real = [(Path(f).name, np.asarray(read_depth(f).depth_mm))
            for f in depth_files(args.people_only)]
    # the real frames' camera for the tilts: --fx (else the store's), centred on the image
    h, w = real[0][1].shape if real else (info.intrinsics.height, info.intrinsics.width)
    fx = args.fx or info.fx
    real_intr = Intrinsics(w, h, fx, fx, (w - 1) / 2, (h - 1) / 2)
    for path in args.forests:
        forest = Forest.load(path)
        predictor = Predictor(forest)
        rows: list[tuple[float, list[float]]] = []
        turned: list[tuple[float, list[float]]] = []
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
                        z = float(np.median(cut[i][mask])) / 1000
                        rows.append((z, body_share(predictor, cut[i], mask,
                                                   [zoomed(k) for k in zooms])))
                        if tilts:
                            turned.append((z, body_share(predictor, cut[i], mask, [
                                tilted(info.intrinsics, t) for t in tilts])))
        # the real frames through the forest at their camera's focal length when --fx says
        # it (at_focal), else at the training one
        on_real = (predictors_at_focal(forest)(args.fx, args.fx) if args.fx else predictor)
        print(f"{path}: share of each person called a body part, the frame zoomed "
              f"(median over people; {count} frames of {args.store}, people cut out alone)")
        table(rows, zooms, "x", [(n, body_share(on_real, d, d > 0, [zoomed(z) for z in zooms]))
                                 for n, d in real])
        if tilts:
            print(f"{path}: the same, each person tilted (degrees; positive: the lower body "
                  f"farther; real frames seen at fx {real_intr.fx:g} px)")
            table(turned, tilts, "", [(n, body_share(on_real, d, d > 0, [
                tilted(real_intr, t) for t in tilts])) for n, d in real])


def table(rows: list[tuple[float, list[float]]], columns: list[float], prefix: str,
          real: list[tuple[str, list[float]]]) -> None:
    """A markdown table: the median of ``rows`` (depth, shares) by depth bin, then
    ``real`` (name, shares) one per line."""
    print("| people at | n | " + " | ".join(f"{prefix}{c:g}" for c in columns) + " |")
    print("|---|---" + "|---" * len(columns) + "|")
    for lo, hi in zip(BINS_M[:-1], BINS_M[1:], strict=True):
        b = np.array([r for z, r in rows if lo <= z < hi]).reshape(-1, len(columns))
        cells = " | ".join(f"{v:.2f}" for v in np.median(b, axis=0)) if len(b) else "-"
        print(f"| {lo:g}-{hi:g} m | {len(b)} | {cells} |")
    for name, shares in real:
        print(f"| {name} | 1 | " + " | ".join(f"{v:.2f}" for v in shares) + " |")


if __name__ == "__main__":
    main()
