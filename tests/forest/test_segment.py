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


def _group(n: int, gap: float = 0.0, arm: bool = False, coat_from: float = 0.8,
           round_m: float = 0.0):
    """A camera 1.3 m above a floor, level, a wall 5 m away; ``n`` people side by side
    3 m away, ``gap`` m apart (0: shoulders touching), coats' fronts on one plane: torso
    0.5 m wide from 0.8 to 1.45 m, legs 8 cm further back, a head 0.22 m wide up to 1.72 m.
    ``arm``: the first person holds an arm out sideways at shoulder height; ``coat_from``:
    the height the coats reach down to (the legs below them); ``round_m``: how much nearer
    a coat's middle is than its sides (0: flat). Returns depth
    mm and the (H, W) int person index (0 = none, k = k-th from the left)."""
    intr = Intrinsics(320, 240, 262.5, 262.5, 159.5, 119.5)
    rays = pixel_rays(intr)
    h, w = intr.height, intr.width
    y = rays[..., 1]
    depth = np.minimum(np.full((h, w), 5.0), np.where(y > 1e-9, 1.3 / np.maximum(y, 1e-9),
                                                      np.inf))
    who = np.zeros((h, w), int)
    x0 = -(n * 0.5 + (n - 1) * gap) / 2

    def slab(xa, xb, lo, hi, z, k, rnd=0.0):
        x, yy = rays[..., 0] * z, 1.3 - rays[..., 1] * z  # height above the floor
        hit = (x >= xa) & (x <= xb) & (yy >= lo) & (yy <= hi) & (z < depth)
        u = (x[hit] - (xa + xb) / 2) / ((xb - xa) / 2)
        depth[hit] = z - rnd * np.sqrt(np.clip(1 - u ** 2, 0, 1))
        who[hit] = k

    for k in range(n):
        left = x0 + k * (0.5 + gap)
        slab(left + 0.05, left + 0.45, 0.0, coat_from, 3.08, k + 1)  # legs
        slab(left, left + 0.5, coat_from, 1.45, 3.0, k + 1, round_m)  # the coat's front
        slab(left + 0.14, left + 0.36, 1.45, 1.72, 2.97, k + 1)  # head
    if arm:
        slab(x0 - 0.6, x0, 1.3, 1.42, 3.0, 1)
    return intr, np.round(depth * 1000).astype(np.uint16), who


@pytest.mark.parametrize("n,gap", [(5, 0.0), (3, 0.0), (2, 0.15), (1, 0.0)])
def test_people_side_by_side_are_found_one_by_one(n, gap):
    """Touching people at 3 m with their fronts on one plane: each is one instance, none
    lost to the plane (a large one, but standing in front of the room) or to the cluster's
    width."""
    intr, depth, who = _group(n, gap)
    labels = (who > 0).astype(np.uint8) * 4
    seg = Segmenter()
    inst = seg.instances(depth, intr, labels)
    assert inst.max() == n
    for k in range(1, n + 1):  # instance k is person k, almost pixel for pixel
        person = who == k
        assert (inst[person] == k).mean() > 0.95
        assert (who[inst == k] == k).mean() > 0.95
    assert not inst[who == 0].any()
    if n >= 3:  # without step 2b: the people are one candidate
        comp, table = Segmenter(split=False).cluster_table(depth, intr, labels)
        assert len(np.unique(comp[(who > 0) & (comp > 0)])) == 1


def test_an_arm_held_out_is_not_a_head():
    intr, depth, who = _group(2, 0.3, arm=True)
    inst = Segmenter().instances(depth, intr, (who > 0).astype(np.uint8) * 4)
    assert inst.max() == 2 and (inst[who == 1] == 1).mean() > 0.95


def test_real_person_is_one_instance():
    f = read_depth(REAL / "person.pcd")
    mask = np.asarray(Image.open(REPO / "docs/forest_study/real_masks/person.png")) > 0
    d = np.asarray(f.depth_mm)
    inst = Segmenter().instances(d, f.intrinsics, (mask & (d > 0)).astype(np.uint8) * 5)
    assert inst.max() == 1 and (inst[mask & (d > 0)] == 1).all()


def test_people_whose_background_was_removed():
    """The skeltrack frames (real Kinect v1, background removed by their source: the mask
    is depth > 0; check frames, no setting chosen on them) with every pixel called a body
    part: the stage keeps the people. Its flat coats are no wall: the stage before kept
    4-23% of each; with the occluding-edge rule alone 65-100%; with the forest's say on
    planes (a plane it calls a body is no wall) 92-100%."""
    kept = []
    for path in sorted((REAL / "skeltrack").glob("*.png")):
        d = np.asarray(read_depth(path).depth_mm)
        h, w = d.shape
        intr = Intrinsics(w, h, 525.0, 525.0, (w - 1) / 2, (h - 1) / 2)
        inst = Segmenter().instances(d, intr, (d > 0).astype(np.uint8) * 5)
        kept.append((inst[d > 0] > 0).mean())
    assert len(kept) == 7 and min(kept) > 0.9 and np.mean(kept) > 0.97, kept


def test_a_flat_front_the_forest_calls_a_body_is_no_wall():
    """A person 1.4 m away with both arms raised and nothing behind them (the background
    removed): body, arms and head on one plane 1.2 m wide and tall, whose border is no
    occluding edge. Without the forest's say it is a wall (background); the forest calls it
    a body, so it stays, while a wall it calls background still goes."""
    intr = Intrinsics(320, 240, 262.5, 262.5, 159.5, 119.5)
    rays = pixel_rays(intr)
    x, y = rays[..., 0] * 1.4, rays[..., 1] * 1.4  # y down
    torso = (np.abs(x) <= 0.25) & (y >= -0.35) & (y <= 0.6)
    head = (np.abs(x) <= 0.1) & (y >= -0.58) & (y < -0.35)
    shoulders = (np.abs(x) <= 0.6) & (y >= -0.35) & (y <= -0.2)
    arms = (np.abs(x) >= 0.45) & (np.abs(x) <= 0.6) & (y >= -1.0) & (y <= -0.2)
    body = torso | head | shoulders | arms
    depth = np.where(body, 1400, 0).astype(np.uint16)
    labels = body.astype(np.uint8) * 4
    assert body.sum() > 3000
    ignored = Segmenter(max_plane_body=None).instances(depth, intr, labels)
    assert (ignored[body] > 0).mean() < 0.2  # the plane step took the person for a wall
    inst = Segmenter().instances(depth, intr, labels)
    assert (inst[body] > 0).mean() > 0.99
    # the same plane called background by the forest is background
    assert (Segmenter().instances(depth, intr, labels * 0) == 0).all()


def test_a_row_of_fronts_the_forest_calls_background_is_no_wall():
    """Five people side by side facing the camera in long coats (rounded: 10 cm nearer in
    the middle), and the forest calling the insides of their torsos background (as it
    does a real torso's more often than a vhgen one's): the plane through their chests is
    2.5 m wide and a metre tall, so the plane step took its pieces, the middles of the
    torsos, for a wall. Each piece stands in front of what surrounds it (the gaps beside
    the people, the room above their shoulders) more than behind anything: it stays, and
    the wall behind them still goes."""
    intr, depth, who = _group(5, 0.0, coat_from=0.4, round_m=0.1)
    h = 1.3 - pixel_rays(intr)[..., 1] * depth / 1000.0  # height above the floor
    torso = (who > 0) & (h > 0.4) & (h < 1.45)
    labels = ((who > 0) & ~torso).astype(np.uint8) * 4
    without = Segmenter(keep_fronts=False).candidates(depth, intr, labels)
    assert (without.comp[torso] == 0).mean() > 0.15
    cand = Segmenter().candidates(depth, intr, labels)
    assert (cand.comp[torso] == 0).mean() < 0.01
    wall = (who == 0) & (depth >= 4990)
    assert wall.sum() > 1000 and (cand.comp[wall] == 0).all()
