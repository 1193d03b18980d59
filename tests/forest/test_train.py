"""Level-wise training: a task it must learn perfectly, determinism, shard invariance."""

from __future__ import annotations

import numpy as np
import pytest

from tests.forest.conftest import two_boxes
from vhgen.errors import ForestError
from vhgen.executor import InlinePool
from vhgen.forest.train import ImageShard, TrainParams, grow_forest, sample_pixels
from vhgen.forest.trees import Forest, Predictor

PARAMS = TrainParams(trees=2, depth=8, pixels_per_image=300, features=60, thresholds=12,
                     seed=5, max_offset=40, min_samples=4)
ARRAYS = ("offsets", "thresh", "left", "depth", "counts", "roots")


def train(depth, labels, splits=(None,), params=PARAMS) -> Forest:
    bounds = [0, *[s for s in splits if s is not None], len(depth)]
    shards = [ImageShard(depth[a:b], labels[a:b], range(a, b), params)
              for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    return grow_forest(InlinePool.holding(shards), 3, params, {})


def test_two_boxes_learned_perfectly():
    d, lab = two_boxes(24, seed=1)
    forest = train(d, lab)
    dt, lt = two_boxes(6, seed=99)  # unseen placements
    pred = Predictor(forest).predict(dt)
    np.testing.assert_array_equal(pred, lt)  # background (no measurement) stays 0 as well
    assert forest.num_trees == 2 and forest.depth.max() <= PARAMS.depth


def test_same_seed_same_forest_whatever_the_shards():
    d, lab = two_boxes(15, seed=2)
    a = train(d, lab)
    b = train(d, lab, splits=(4,))
    c = train(d, lab, splits=(1, 7, 11))
    for k in ARRAYS:
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
        np.testing.assert_array_equal(getattr(a, k), getattr(c, k))
    other = train(d, lab, params=TrainParams(**{**PARAMS.__dict__, "seed": 6}))
    assert not np.array_equal(a.offsets, other.offsets)


def test_tree_depth_and_min_samples_stop():
    d, lab = two_boxes(10, seed=4)
    shallow = train(d, lab, params=TrainParams(**{**PARAMS.__dict__, "depth": 1}))
    assert shallow.depth.max() == 1
    # every leaf that is not pure had fewer than min_samples or hit the depth limit
    big = TrainParams(**{**PARAMS.__dict__, "min_samples": 10**6})
    stump = train(d, lab, params=big)
    assert len(stump.left) == 2 and (stump.left == -1).all()


def test_save_load_round_trip(tmp_path):
    d, lab = two_boxes(8, seed=8)
    f = train(d, lab)
    f.meta.update({"label_names": ["a", "b"], "fx": 525.0})
    path = f.save(tmp_path / "f.npz")
    g = Forest.load(path)
    for k in ARRAYS:
        np.testing.assert_array_equal(getattr(f, k), getattr(g, k))
    assert g.meta["label_names"] == ["a", "b"] and g.meta["params"]["seed"] == PARAMS.seed
    np.testing.assert_array_equal(Predictor(f).predict(d), Predictor(g).predict(d))
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ForestError, match="bad.npz"):
        Forest.load(bad)


def test_sampling_is_balanced_over_classes():
    lab = np.zeros((40, 40), np.uint8)
    lab[:30] = 1  # 1200 pixels of part 1
    lab[30:35] = 2  # 200 of part 2
    lab[35:] = 3  # 200 of part 3
    valid = np.ones_like(lab, bool)
    valid[35:, :20] = False  # half of part 3 has no measurement
    flat, cls = sample_pixels(lab, valid, 300, np.random.default_rng(0))
    counts = np.bincount(cls, minlength=4)
    assert counts.tolist() == [0, 100, 100, 100]
    assert valid.ravel()[flat].all() and len(np.unique(flat)) == len(flat)


def test_background_share_takes_its_share_and_the_parts_split_the_rest():
    lab = np.zeros((60, 60), np.uint8)  # 2400 background pixels
    lab[:10] = 1
    lab[10:20] = 2
    lab[20:] = 0
    valid = np.ones_like(lab, bool)
    _, cls = sample_pixels(lab, valid, 300, np.random.default_rng(0), background_share=0.5)
    assert np.bincount(cls, minlength=3).tolist() == [150, 75, 75]
    _, cls = sample_pixels(lab, valid, 300, np.random.default_rng(0))
    assert np.bincount(cls, minlength=3).tolist() == [100, 100, 100]  # 0: the old balance
    only_bg = np.zeros_like(lab)  # nothing but background: all n pixels, as before
    _, cls = sample_pixels(only_bg, valid, 300, np.random.default_rng(0), 0.5)
    assert len(cls) == 300 and not cls.any()
    with pytest.raises(ForestError, match="--background-share"):
        TrainParams(background_share=1.0).check()


def test_bad_params_name_the_flag():
    with pytest.raises(ForestError, match="--depth"):
        TrainParams(depth=0).check()
