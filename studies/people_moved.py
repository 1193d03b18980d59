"""Real people whose background was removed, moved nearer or farther from the camera: a
check of the person stage at distances the real frames do not show, on real bodies.

    python studies/people_moved.py FRAMES OUT --to 0.7
    vhgen forest eval FOREST --segment --people-only OUT --fx 575.8

FRAMES: a folder of 16-bit millimetre PNGs in which every measured pixel is a person (e.g.
``../shared/real/skeltrack``). Every frame's points are moved along the optical axis so
that their median depth becomes ``--to`` metres, projected again with the same
intrinsics (the principal point at the image centre; the focal length cancels) and drawn
nearest first, each point over the pixels its magnification covers; the frames are
written to OUT under their own names. The real
sensor's noise and quantisation move with the points, so a person moved nearer is
noisier than one measured there. It makes frames to check on, never to choose on.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def moved(depth_mm: np.ndarray, to_m: float) -> np.ndarray:
    """``depth_mm`` (H, W) uint16 with its points moved along the optical axis so that
    their median depth is ``to_m``; (H, W) uint16 millimetres, 0 where nothing lands."""
    h, w = depth_mm.shape
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    v, u = np.nonzero(depth_mm > 0)
    z = depth_mm[v, u].astype(np.float64) / 1000.0
    z2 = z - (float(np.median(z)) - to_m)
    keep = z2 > 0.05
    u, v, z, z2 = u[keep], v[keep], z[keep], z2[keep]
    m = z / z2  # each point's magnification
    uu = cx + (u - cx) * m
    vv = cy + (v - cy) * m
    out = np.full((h, w), np.inf)
    reach = int(np.ceil(m.max() / 2 + 0.5))
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            ok = (abs(dx) <= m / 2 + 0.5) & (abs(dy) <= m / 2 + 0.5)
            a = np.round(uu + dx).astype(np.int64)
            b = np.round(vv + dy).astype(np.int64)
            ok &= (a >= 0) & (a < w) & (b >= 0) & (b < h)
            np.minimum.at(out, (b[ok], a[ok]), z2[ok])
    return np.where(np.isfinite(out), np.round(out * 1000.0), 0).astype(np.uint16)


def main() -> None:
    from PIL import Image

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("frames", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--to", type=float, required=True, help="median depth to move to (m)")
    args = ap.parse_args()
    files = sorted(args.frames.glob("*.png"))
    if not files:
        sys.exit(f"people_moved: no .png frames in {args.frames}")
    args.out.mkdir(parents=True, exist_ok=True)
    for f in files:
        d = np.asarray(Image.open(f))
        if d.dtype != np.uint16:
            print(f"people_moved: {f}: not a 16-bit PNG, skipped")
            continue
        m = moved(d, args.to)
        Image.fromarray(m).save(args.out / f.name)
        z = d[d > 0]
        print(f"{f.name}: median {np.median(z) / 1000:.2f} -> {args.to:.2f} m, "
              f"{len(z)} -> {int((m > 0).sum())} person pixels")


if __name__ == "__main__":
    main()
