"""The person stage's part features: whether the forest's parts lie where they lie on a
person (head over chest over legs), with the parts' typical heights learned from vhgen
candidates that are people."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.forest.test_person_stage import INTR, candidates, room
from vhgen.forest.from_stores import stage_rows, with_part_features, with_weaker_vote
from vhgen.forest.person_stage import PersonStage
from vhgen.forest.segment import (
    FEATURES,
    HEIGHT_BINS,
    Segmenter,
    learn_part_heights,
    part_features,
)
from vhgen.forest.trees import Forest

ORDER, TOP, BOTTOM = (FEATURES.index(f) for f in ("part_order", "top_parts", "bottom_parts"))


def test_typical_heights_are_learned_from_people_only():
    hist = np.zeros((3, 4, HEIGHT_BINS))
    hist[0, 1, 0] = 30  # a person: label 1 at the bottom, 3 at the top
    hist[0, 3, 9] = 10
    hist[1, 1, 9] = 1000  # not a person: label 1 at the top, ignored
    hist[2, 1, 2] = 10  # a second person: label 1 a little higher
    hist[:, 0, 5] = 50  # background, never a part
    heights = learn_part_heights(hist, np.array([True, False, True]))
    np.testing.assert_allclose(heights[1], (30 * 0.05 + 10 * 0.25) / 40)
    assert heights[3] == 0.95
    assert np.isnan(heights[0]) and np.isnan(heights[2])  # background; never seen


def test_order_is_one_in_order_minus_one_upside_down_and_zero_when_unknown():
    heights = np.array([np.nan, 0.1, 0.5, 0.9])
    hist = np.zeros((4, 4, HEIGHT_BINS))
    hist[0, 1, 0:3] = 20  # a person: feet low, chest in the middle, head on top
    hist[0, 2, 4:7] = 20
    hist[0, 3, 8:10] = 20
    hist[1] = hist[0, :, ::-1]  # the same parts upside down
    hist[2, 2, :] = 5  # one part all the way up: no spread of typical heights
    hist[3, 1, 0] = 3  # too few pixels called a part
    hist[3, 3, 9] = 3
    hist[:, 0, :] += 7  # called background: counts in the shares only
    f = part_features(hist, heights)
    assert f[0, 0] > 0.95 and f[1, 0] < -0.95
    assert f[2, 0] == 0.0 and f[3, 0] == 0.0
    # top fifth: 40 head pixels of 54; lowest 30%: 60 foot pixels of 81
    np.testing.assert_allclose(f[0, 1:], [40 / 54, 60 / 81])
    assert f[1, 1] == 0.0 and f[1, 2] == 0.0


def test_the_room_people_are_in_order_and_a_reversed_labelling_is_not():
    seg = Segmenter(min_pixels=50)
    xs, ys, hs = [], [], []
    for s in range(12):
        depth, labels, who = room(s)
        x, y, h = stage_rows(seg, depth, INTR, labels, who, num_labels=12)
        xs.append(x)
        ys.append(y)
        hs.append(h)
    assert (np.concatenate(xs)[:, ORDER:] == 0).all()  # zero until filled
    x, heights = with_part_features(np.concatenate(xs), np.concatenate(ys),
                                    np.concatenate(hs))
    y = np.concatenate(ys)
    assert len(heights) == 12 and heights[11] > 0.8 and 0.2 < heights[4] < 0.6
    assert np.isnan(heights[[0, 1, 5]]).all()
    # two parts a person: a head over a body (the correlation of a two-valued part)
    assert (x[y, ORDER] >= 0).all() and np.median(x[y, ORDER]) > 0.35
    assert np.median(x[y, TOP]) > 0.2
    assert np.median(x[~y, ORDER]) == 0  # cabinets and walls: nothing called a part
    # the describe of a frame with the learned heights gives the same features
    depth, labels, who = room(3)
    cand = seg.candidates(depth, INTR, labels)
    got = seg.describe(cand, depth, INTR, labels, part_heights=heights)
    rows = stage_rows(seg, depth, INTR, labels, who, without_floor=False, num_labels=12)
    want = part_features(rows[2], heights)
    np.testing.assert_allclose(got[~np.isnan(got).any(1)][:, ORDER:], want)
    # the people's heads called bodies and their bodies heads: the order reversed (two
    # parts: a part's typical height maps linearly onto the other's)
    flipped = np.select([labels == 4, labels == 11], [11, 4], 0).astype(np.uint8)
    bad = seg.describe(cand, depth, INTR, flipped, part_heights=heights)
    ok = ~np.isnan(got).any(1)
    np.testing.assert_allclose(bad[ok, ORDER], -got[ok, ORDER], atol=1e-12)
    assert (got[ok, ORDER] > 0.3).any()


def test_part_heights_travel_with_the_stage_and_an_older_stage_reads_without_them(tmp_path):
    x, y = candidates(range(8), vote=0.6)
    heights = np.array([np.nan, 0.2, np.nan, np.nan, 0.5])
    stage = replace(PersonStage.fit(x, y, FEATURES, trees=4, seed=1), part_heights=heights)
    f = Forest(np.zeros((1, 4), np.int16), np.zeros(1, np.int32), np.full(1, -1, np.int32),
               np.zeros(1, np.int16), np.ones((1, 3), np.int64), np.zeros(1, np.int64),
               {"label_names": ["a", "b"]}, stage)
    back = Forest.load(f.save(tmp_path / "f.npz")).person_stage
    assert back is not None
    np.testing.assert_array_equal(back.part_heights, heights)
    # a stage of before the part features: no heights, and its own columns only
    old = PersonStage.fit(x[:, :ORDER], y, FEATURES[:ORDER], trees=4, seed=1)
    f.person_stage = old
    back = Forest.load(f.save(tmp_path / "old.npz")).person_stage
    assert back is not None and back.part_heights is None
    depth, labels, _ = room(5)
    seg = Segmenter(min_pixels=50)
    comp, person = seg.people(depth, INTR, labels, back)
    _, feats = seg.features(depth, INTR, labels)
    assert (feats[~np.isnan(feats).any(1)][:, ORDER:] == 0).all()
    expect = back.predict_proba(feats[:, :ORDER]) >= seg.min_person_prob
    expect[0] = False
    np.testing.assert_array_equal(person, expect)
    # with heights, the stage's own: the people of the frame read with them
    f.person_stage = stage
    _, person = seg.people(depth, INTR, labels, stage)
    _, feats = seg.features(depth, INTR, labels, heights)
    expect = stage.predict_proba(feats) >= seg.min_person_prob
    expect[0] = False
    np.testing.assert_array_equal(person, expect)
    # what studies read: the same features and probabilities, the heights the stage's
    _, got, p = seg.person_probability(depth, INTR, labels, stage)
    np.testing.assert_array_equal(got, feats)
    np.testing.assert_array_equal(p, stage.predict_proba(feats))


def test_cli_part_order_is_opt_in(tmp_path, capsys):
    from tests.forest.test_cli import one_line_error, run
    from tests.forest.test_person_stage import SMALL, rooms_store

    store = rooms_store(tmp_path / "rooms.zarr", range(20))
    forest = tmp_path / "f.npz"
    code, _, _ = run(capsys, "forest", "train", store, "--out", str(forest), *SMALL,
                     "--max-frames", "8", "--background-share", "0.5")
    assert code == 0
    stages = {}
    for name, extra in (("plain", ()), ("order", ("--part-order",)),
                        ("weak", ("--part-order", "--weaker-vote", "0.7"))):
        out = tmp_path / f"{name}.npz"
        code, _, err = run(capsys, "forest", "person-stage", str(forest), store, "--frames",
                           "8", "--out", str(out), "--quiet", *extra)
        assert code == 0, err
        stages[name] = Forest.load(out)
    plain, order = stages["plain"], stages["order"]
    assert plain.person_stage.part_heights is None
    assert not set(plain.person_stage.features) & {"part_order", "top_parts", "bottom_parts"}
    assert not plain.meta["person_stage"]["part_order"]
    assert order.person_stage.features == FEATURES and order.meta["person_stage"]["part_order"]
    heights = order.person_stage.part_heights
    assert len(heights) == order.num_classes and np.isnan(heights[0])
    assert ((heights[~np.isnan(heights)] > 0) & (heights[~np.isnan(heights)] < 1)).all()
    # the weaker-vote copies come after the heights are learned: the same heights, other
    # trees; off unless asked for
    weak = stages["weak"]
    assert weak.meta["person_stage"]["weaker_vote"] == 0.7
    assert order.meta["person_stage"]["weaker_vote"] is None
    np.testing.assert_array_equal(weak.person_stage.part_heights, heights)
    assert not np.array_equal(weak.person_stage.threshold, order.person_stage.threshold)
    one_line_error(capsys, "forest", "person-stage", str(forest), store, "--weaker-vote", "1",
                   match="--weaker-vote")
    test = rooms_store(tmp_path / "test.zarr", range(300, 304))
    code, out, err = run(capsys, "forest", "eval", str(tmp_path / "order.npz"), test,
                         "--segment")
    assert code == 0 and "person stage" in out, err


def test_weaker_vote_copies_every_row_with_only_its_vote_lowered():
    rng = np.random.default_rng(5)
    x = rng.uniform(0.1, 1.0, (200, len(FEATURES)))
    y = rng.random(200) < 0.3
    body = FEATURES.index("body")
    xx, yy = with_weaker_vote(x, y, 0.7, seed=3)
    assert xx.shape == (400, len(FEATURES))
    np.testing.assert_array_equal(xx[:200], x)
    np.testing.assert_array_equal(yy, np.concatenate([y, y]))
    others = np.arange(len(FEATURES)) != body
    np.testing.assert_array_equal(xx[200:, others], x[:, others])
    factor = xx[200:, body] / x[:, body]
    assert factor.min() >= 0.7 and factor.max() <= 1.0 and factor.std() > 0.05
    np.testing.assert_array_equal(with_weaker_vote(x, y, 0.7, seed=3)[0], xx)
    assert not np.array_equal(with_weaker_vote(x, y, 0.7, seed=4)[0], xx)
    for low in (0.0, 1.0):
        with pytest.raises(ValueError, match=r"\(0, 1\)"):
            with_weaker_vote(x, y, low, seed=3)
