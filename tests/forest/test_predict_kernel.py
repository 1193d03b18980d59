"""The compiled inference kernel gives exactly the labels of a slow obvious reference."""

from __future__ import annotations

import numpy as np
import pytest

from tests.forest.conftest import two_boxes
from tests.forest.test_features import reference_feature
from vhgen.errors import ForestError
from vhgen.executor import InlinePool
from vhgen.forest.features import BACKGROUND_MM, draw_offsets, prepare_depth
from vhgen.forest.predict_kernel import pack_forest, probe_indices
from vhgen.forest.train import ImageShard, TrainParams, grow_forest
from vhgen.forest.trees import Forest, Predictor, truncate


def reference_leaves(forest: Forest, depth: np.ndarray) -> np.ndarray:
    """(T, H, W) leaf node per pixel and tree, -1 where there is no measurement: the
    module docstring of vhgen.forest.features in NumPy, all pixels one level at a time."""
    d = prepare_depth(depth).astype(np.int64)
    h, w = d.shape
    ys, xs = np.nonzero(d != BACKGROUND_MM)
    scale = 1000.0 / d[ys, xs]
    out = np.full((forest.num_trees, h, w), -1, np.int64)
    for t in range(forest.num_trees):
        node = np.full(len(ys), forest.roots[t], np.int64)
        while True:
            inner = forest.left[node] >= 0
            if not inner.any():
                break
            n, x, y, s = node[inner], xs[inner], ys[inner], scale[inner]
            o = forest.offsets[n].astype(np.int64)
            # float64 position -> float32 -> truncation -> clamp (PCL runThroughTree)
            u1, v1, u2, v2 = (np.clip((c + o[:, k] * s).astype(np.float32).astype(np.int64),
                                      0, lim - 1)
                              for k, c, lim in ((0, x, w), (1, y, h), (2, x, w), (3, y, h)))
            f = d[v1, u1] - d[v2, u2]
            node[inner] = forest.left[n] + (f > forest.thresh[n])
        out[t, ys, xs] = node
    return out


def reference_predict(forest: Forest, depth: np.ndarray, mass: bool = False) -> np.ndarray:
    """(H, W) uint8: argmax (first maximum) of the sum of the trees' normalised float32 leaf
    histograms, summed tree after tree; 0 where there is no measurement. ``mass``: 0 where
    the background's sum is at least the parts' (summed in float32 class after class),
    else the first maximum among the parts."""
    leaves = reference_leaves(forest, depth)
    prob = forest.probabilities()
    body = leaves[0] >= 0
    acc = prob[leaves[0][body]].copy()
    for t in range(1, forest.num_trees):
        acc += prob[leaves[t][body]]
    out = np.zeros(depth.shape, np.uint8)
    if mass:
        parts = np.zeros(len(acc), np.float32)
        for k in range(1, acc.shape[1]):
            parts += acc[:, k]
        out[body] = np.where(acc[:, 0] >= parts, 0, 1 + np.argmax(acc[:, 1:], axis=1))
    else:
        out[body] = np.argmax(acc, axis=1)
    return out


def random_complete_forest(rng: np.random.Generator, trees: int, depth: int,
                           classes: int, max_offset: int) -> Forest:
    """Complete trees with random features, thresholds and leaf histograms."""
    n, inner = 2 ** (depth + 1) - 1, 2**depth - 1
    idx = np.arange(n)
    parts = []
    for t in range(trees):
        left = np.where(idx < inner, 2 * idx + 1 + t * n, -1)
        counts = rng.integers(0, 5, (n, classes)) * (rng.random((n, 1)) < 0.9)
        parts.append((draw_offsets(rng, n, max_offset), rng.integers(-400, 401, n), left,
                      np.floor(np.log2(idx + 1)), counts))
    cat = [np.concatenate([p[i] for p in parts]) for i in range(5)]
    return Forest(cat[0], cat[1].astype(np.int32), cat[2].astype(np.int32),
                  cat[3].astype(np.int16), cat[4].astype(np.int64),
                  np.arange(trees, dtype=np.int64) * n)


def blob_frames(rng: np.random.Generator, n: int, h: int, w: int) -> np.ndarray:
    """Frames of random boxes at 0.4-4 m that cross every border, with holes (0)."""
    d = np.zeros((n, h, w), np.uint16)
    for i in range(n):
        for _ in range(6):
            y0, x0 = rng.integers(-h // 4, h), rng.integers(-w // 4, w)
            d[i, max(y0, 0):y0 + h // 2, max(x0, 0):x0 + w // 3] = rng.integers(400, 4000)
        d[i] = np.where(rng.random((h, w)) < 0.05, 0, d[i] + rng.integers(0, 30, (h, w)))
    d[:, 0, :] = rng.integers(0, 3000, (n, w))  # body on the top border
    d[:, :, -1] = 1  # 1 mm: probes land far outside the image
    return d


@pytest.mark.parametrize("which", [0, 1])
def test_probe_indices_match_the_formula(which):
    """Both index paths (generic vector multiply; pmaddwd on x86, USE_PMADDWD) against the
    formula, with offsets and depths that throw probes far outside the image."""
    rng = np.random.default_rng(3)
    for h, w in ((480, 640), (1, 1), (7, 3), (300, 32767)):
        n = 4000
        off = draw_offsets(rng, n, 130).astype(np.int64)
        off[:50] = rng.choice([-32768, 32767, 0, 1, -1], (50, 4))
        x, y = rng.integers(0, w, n), rng.integers(0, h, n)
        d = rng.integers(1, 65535, n)
        d[:100] = rng.integers(1, 20, 100)
        s = 1000.0 / d
        packed = np.ascontiguousarray(off.astype(np.int16)).view(np.int64).ravel()
        xyxy = np.stack([x, y, x, y], axis=1).astype(np.float64)
        got = probe_indices(packed, xyxy, s, w, h, which)
        lim = (w, h, w, h)
        c = [np.clip(((x, y, x, y)[k] + off[:, k] * s).astype(np.float32).astype(np.int64),
                     0, lim[k] - 1) for k in range(4)]
        np.testing.assert_array_equal(got[:, 0], c[1] * w + c[0])
        np.testing.assert_array_equal(got[:, 1], c[3] * w + c[2])


def test_numpy_reference_is_the_pcl_feature():
    """The NumPy reference walk takes the branch reference_feature (plain Python) says."""
    rng = np.random.default_rng(5)
    depth = blob_frames(rng, 1, 24, 32)[0]
    forest = random_complete_forest(rng, 2, 4, 3, max_offset=300)
    d = prepare_depth(depth)
    leaves = reference_leaves(forest, depth)
    for t in range(2):
        for y, x in zip(*np.nonzero(depth), strict=True):
            node = int(forest.roots[t])
            while forest.left[node] >= 0:
                f = reference_feature(d, int(x), int(y), forest.offsets[node], "float64")
                node = int(forest.left[node]) + int(f > forest.thresh[node])
            assert leaves[t, y, x] == node


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("vote", ["argmax", "mass"])
def test_complete_forests_match_reference(seed, vote):
    rng = np.random.default_rng(seed)
    frames = blob_frames(rng, 3, 48, 64)
    forest = random_complete_forest(rng, 3, 9, 26, max_offset=130)
    if vote == "mass":  # background at about half of every leaf: both decisions occur
        forest.counts[:, 0] = forest.counts[:, 1:].sum(1) * rng.uniform(0.5, 1.5,
                                                                        len(forest.counts))
    pred = Predictor(forest, vote=vote)
    mass = vote == "mass"
    for d in frames:
        np.testing.assert_array_equal(pred.predict(d), reference_predict(forest, d, mass))
    # the batch path (frames in parallel) is the same kernel
    np.testing.assert_array_equal(pred.predict(frames),
                                  np.stack([reference_predict(forest, d, mass) for d in frames]))
    if mass:
        got = pred.predict(frames)
        assert 0.1 < (got[frames > 0] == 0).mean() < 0.9  # both sides of the decision


def test_mass_vote_calls_a_person_whose_parts_outweigh_the_background():
    """One leaf: background 0.4, three parts 0.2 each. argmax: background; by mass: the
    parts (0.6) outweigh it, so the first most probable part. Background 0.5 against 0.5:
    background (ties go to it). The forest's meta ``vote`` is the default, and a bad
    one names itself."""
    def stump(counts, meta=None):
        return Forest(np.zeros((1, 4), np.int16), np.zeros(1, np.int32),
                      np.full(1, -1, np.int32), np.zeros(1, np.int16), np.array([counts]),
                      np.zeros(1, np.int64), meta or {})

    depth = np.full((4, 5), 2500, np.uint16)
    depth[0, 0] = 0
    spread = stump([4, 2, 2, 2])
    assert (Predictor(spread).predict(depth) == 0).all()
    got = Predictor(spread, vote="mass").predict(depth)
    assert got[0, 0] == 0 and (got.ravel()[1:] == 1).all()
    assert (Predictor(stump([4, 2, 2, 2], {"vote": "mass"})).predict(depth)[1:] == 1).all()
    assert (Predictor(stump([2, 1, 0, 1]), vote="mass").predict(depth) == 0).all()
    with pytest.raises(ForestError, match="vote 'sum'"):
        Predictor(stump([1, 1]), vote="sum")
    with pytest.raises(ForestError, match="forest vote 'sum'"):
        Predictor(stump([1, 1], {"vote": "sum"}))


def test_trained_forest_with_early_leaves_and_a_stump():
    d, lab = two_boxes(20, seed=6)
    d = np.where(d > 0, d + np.random.default_rng(6).integers(0, 400, d.shape), 0)
    p = TrainParams(trees=3, depth=10, pixels_per_image=300, features=40, thresholds=10,
                    seed=4, max_offset=60, min_samples=3)
    shard = ImageShard(d.astype(np.uint16), lab, range(20), p)
    forest = grow_forest(InlinePool.holding([shard]), 3, p, {})
    leaf_depths = forest.depth[forest.left < 0]
    assert leaf_depths.min() < leaf_depths.max()  # paths of different lengths
    # a fourth tree that is a single leaf (no split at all)
    stump = Forest(np.zeros((1, 4), np.int16), np.zeros(1, np.int32), np.full(1, -1, np.int32),
                   np.zeros(1, np.int16), np.array([[0, 5, 1, 9]]), np.zeros(1, np.int64))
    test, _ = two_boxes(4, seed=60)
    test[:, :, :3] = 2000  # body on the left border
    cut = truncate(forest, 4)  # deeper nodes stay in the arrays, unreachable
    assert Predictor(cut)._packed.levels.tolist() == [4, 4, 4]
    for f in (forest, _concat(forest, stump), cut):
        pred = Predictor(f)
        for frame in test:
            np.testing.assert_array_equal(pred.predict(frame), reference_predict(f, frame))


def _concat(a: Forest, b: Forest) -> Forest:
    n = len(a.left)
    return Forest(np.concatenate([a.offsets, b.offsets]), np.concatenate([a.thresh, b.thresh]),
                  np.concatenate([a.left, np.where(b.left >= 0, b.left + n, -1)]).astype(
                      np.int32),
                  np.concatenate([a.depth, b.depth]),
                  np.concatenate([a.counts, b.counts[:, :a.num_classes]]),
                  np.concatenate([a.roots, b.roots + n]))


def test_vote_ties_go_to_the_lowest_class():
    # two single-leaf trees: class 2 in one, class 1 in the other -> a tie -> 1; an empty
    # histogram in both -> all classes 0 -> 0 (background)
    def two_stumps(c0, c1):
        return Forest(np.zeros((2, 4), np.int16), np.zeros(2, np.int32),
                      np.full(2, -1, np.int32), np.zeros(2, np.int16),
                      np.array([c0, c1]), np.array([0, 1]))

    depth = np.full((5, 6), 1500, np.uint16)
    depth[0, 0] = 0
    tie = Predictor(two_stumps([0, 0, 3], [0, 7, 0])).predict(depth)
    assert tie[0, 0] == 0 and (tie.ravel()[1:] == 1).all()
    assert (Predictor(two_stumps([0, 0, 0], [0, 0, 0])).predict(depth) == 0).all()


def test_packed_layout():
    rng = np.random.default_rng(2)
    f = random_complete_forest(rng, 2, 3, 5, 100)
    pf = pack_forest(f.offsets, f.thresh, f.left, f.counts, f.roots)
    assert pf.levels.tolist() == [3, 3] and pf.prob.shape == (16, 8)
    cyclic = np.where(f.left == 3, 0, f.left)  # node 1's children are the root and node 4
    with pytest.raises(ValueError, match="cycle"):
        pack_forest(f.offsets, f.thresh, cyclic, f.counts, f.roots)
    assert (pf.prob[:, 5:] == -1).all()
    np.testing.assert_array_equal(pf.prob[:, :5], f.probabilities()[f.left < 0])
    nodes = pf.nodes.reshape(-1, 2)
    leaves = np.flatnonzero(f.left < 0)
    assert (nodes[leaves, 0] == 0).all()  # leaves: zero offsets...
    assert (nodes[leaves, 1] >> 32 == leaves).all()  # ...loop to themselves
    assert ((nodes[leaves, 1] & 0xFFFFFFFF) == np.arange(len(leaves))).all()  # prob row


def test_huge_image_is_a_clear_error():
    f = random_complete_forest(np.random.default_rng(0), 1, 2, 3, 10)
    with pytest.raises(ForestError, match="32767"):
        Predictor(f).predict(np.zeros((2, 40000), np.uint16))
