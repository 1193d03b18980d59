"""Make the person mask of a real depth frame whose person is the nearest thing in view.

    .venv/bin/python scripts/make_person_mask.py ../shared/real/person.pcd \
        -o docs/forest_study/real_masks/person.png [--max-depth-mm 1000]

How: the valid pixels nearer than ``--max-depth-mm`` (for ``person.pcd`` the depth
histogram is empty between 1.0 and 1.2 m: the person stands at 0.6-1.0 m, the room
behind starts at 1.2 m), the largest 8-connected component of them (the person; stray
near pixels elsewhere are dropped), written as an 8-bit PNG: 255 = person, 0 = not a
person (pixels without a measurement are 0 too; metrics only count valid pixels).
Check the result by eye: ``--overlay sheet.png`` draws the mask's outline on the depth.
"""

from __future__ import annotations

import argparse

import numpy as np
from PIL import Image
from scipy import ndimage

from vhgen.depthfile import read_depth


def person_mask(depth_mm: np.ndarray, max_depth_mm: int) -> np.ndarray:
    """(H, W) bool: the largest 8-connected component of valid pixels nearer than
    ``max_depth_mm``."""
    near = (depth_mm > 0) & (depth_mm < max_depth_mm)
    lab, n = ndimage.label(near, structure=np.ones((3, 3), bool))
    if n == 0:
        raise SystemExit(f"no valid pixel nearer than {max_depth_mm} mm")
    sizes = np.bincount(lab.ravel())[1:]
    return lab == 1 + int(np.argmax(sizes))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("frame")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--max-depth-mm", type=int, default=1000)
    ap.add_argument("--overlay", help="also write the depth with the mask outline")
    a = ap.parse_args()
    depth = read_depth(a.frame).depth_mm
    mask = person_mask(np.asarray(depth), a.max_depth_mm)
    Image.fromarray(mask.astype(np.uint8) * 255).save(a.out)
    print(f"wrote {a.out}: {int(mask.sum())} person pixels of {int((depth > 0).sum())} valid")
    if a.overlay:
        d = np.asarray(depth, np.float64)
        g = np.where(d > 0, 255 * (1 - np.clip((d - 500) / 4000, 0, 1)), 0).astype(np.uint8)
        rgb = np.repeat(g[..., None], 3, axis=2)
        edge = mask & ~ndimage.binary_erosion(mask, iterations=2)
        rgb[edge] = (255, 0, 0)
        Image.fromarray(rgb).save(a.overlay)


if __name__ == "__main__":
    main()
