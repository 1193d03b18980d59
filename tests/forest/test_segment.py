"""The segmentation stage after the forest: planes out, clusters in 2.5D, a cluster kept
when the forest calls most of it a body part (synthetic scene with a known answer, and
the shared real frame of a person with its mask)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from vhgen.camera import Intrinsics, pixel_rays
from vhgen.depthfile import read_depth
from vhgen.forest.segment import Segmenter

REPO = Path(__file__).resolve().parents[2]
REAL = REPO.parent / "shared" / "real"
INTR = Intrinsics(160, 120, 131.25, 131.25, 79.5, 59.5)


def _scene() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A camera 1.5 m above a floor, looking level at a wall 4 m away; a 'person' (0.5 x
    1.7 m, its front rounded like a body: 15 cm nearer in the middle than at the sides)
    standing on the floor 2.5 m away, and a 'cabinet' box (0.8 x 1.0 m) at 3 m. Returns
    depth mm, the person's pixels and the cabinet's."""
    rays = pixel_rays(INTR)  # z = 1
    h, w = INTR.height, INTR.width
    depth = np.full((h, w), 4.0)  # the wall
    y = rays[..., 1]
    floor = np.where(y > 1e-9, 1.5 / np.maximum(y, 1e-9), np.inf)  # camera y is down
    depth = np.minimum(depth, floor)

    def box(x0, x1, top, z):
        # front face at depth z, from the floor (1.5 m below) up to `top` above the floor
        x, yy = rays[..., 0] * z, rays[..., 1] * z
        hit = (x >= x0) & (x <= x1) & (yy <= 1.5) & (yy >= 1.5 - top) & (z < depth)
        return hit

    person = box(-0.25, 0.25, 1.7, 2.5)
    x = rays[..., 0] * 2.5
    depth[person] = 2.5 - 0.15 * np.sqrt(np.clip(1 - (x[person] / 0.25) ** 2, 0, 1))
    cabinet = box(0.6, 1.4, 1.0, 3.0)
    depth[cabinet] = 3.0
    return np.round(depth * 1000).astype(np.uint16), person, cabinet


def test_keeps_the_person_cluster_only():
    depth, person, cabinet = _scene()
    rng = np.random.default_rng(1)
    labels = np.zeros(depth.shape, np.uint8)
    labels[person & (rng.uniform(size=depth.shape) < 0.8)] = 7  # most of the person
    labels[cabinet & (rng.uniform(size=depth.shape) < 0.3)] = 9  # some of the cabinet
    labels[~person & ~cabinet & (rng.uniform(size=depth.shape) < 0.05)] = 4  # speckle
    out = Segmenter(min_pixels=50).apply(depth, INTR, labels)
    assert (out[person] == 7).all()  # the person kept, its unlabelled pixels filled
    assert not out[~person].any()  # the cabinet, the wall and the floor are background


def test_a_cluster_the_forest_does_not_call_a_person_goes():
    depth, person, _ = _scene()
    labels = np.zeros(depth.shape, np.uint8)
    labels[person] = 3
    labels[np.nonzero(person)[0].min():][:, :] *= 0  # nothing labelled at all
    assert not Segmenter(min_pixels=50).apply(depth, INTR, labels).any()
    labels[person] = 3
    sparse = labels.copy()
    sparse[person & (np.random.default_rng(2).uniform(size=depth.shape) < 0.7)] = 0
    # under half of the cluster called: not a person
    assert not Segmenter(min_pixels=50).apply(depth, INTR, sparse).any()


@pytest.mark.parametrize("noise", [0.0, 0.3])
def test_real_person_frame(noise):
    """person.pcd with 'forest labels' = its mask plus a share of random background
    pixels: the stage returns exactly the person (the mask: scripts/make_person_mask.py)."""
    f = read_depth(REAL / "person.pcd")
    assert f.intrinsics is not None
    mask = np.asarray(Image.open(REPO / "docs/forest_study/real_masks/person.png")) > 0
    d = np.asarray(f.depth_mm)
    rng = np.random.default_rng(0)
    labels = ((mask | (rng.uniform(size=d.shape) < noise)) & (d > 0)).astype(np.uint8) * 5
    out = Segmenter().apply(d, f.intrinsics, labels)
    called = (out > 0) & (d > 0)
    assert (called == (mask & (d > 0))).all()
