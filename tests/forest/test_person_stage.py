"""The segmentation stage's trained person decision (vhgen.forest.person_stage) and the
parts forest of segmented people (forest train --segmented, --parts): synthetic rooms
with a known answer, where the forest's vote alone cannot tell people from furniture."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.forest.conftest import write_store
from vhgen.camera import Intrinsics, pixel_rays
from vhgen.cli import main
from vhgen.forest.person_stage import PersonStage
from vhgen.forest.segment import FEATURES, Segmenter
from vhgen.forest.trees import Forest, Predictor

INTR = Intrinsics(160, 120, 131.25, 131.25, 79.5, 59.5)
SMALL = ["--trees", "2", "--depth", "6", "--pixels-per-image", "200", "--features", "40",
         "--thresholds", "8", "--max-offset", "40", "--min-samples", "4", "--quiet"]


def room(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A camera 1.3 m above a floor, level, a wall 6 m away; 1-3 'people' (a body 0.45 m
    wide, legs, a 0.2 m head up to 1.6-1.9 m) and 1-2 'cabinets' (0.6-1.2 m wide, 0.5-1.0 m
    tall) 2-4.5 m away, apart. Returns depth mm, labels (people: part 4 on their bodies,
    part 11 on their heads; cabinets 0) and the person index (0 = none)."""
    rng = np.random.default_rng(seed)
    rays = pixel_rays(INTR)
    h, w = INTR.height, INTR.width
    y = rays[..., 1]
    depth = np.minimum(np.full((h, w), 6.0),
                       np.where(y > 1e-9, 1.3 / np.maximum(y, 1e-9), np.inf))
    labels = np.zeros((h, w), np.uint8)
    who = np.zeros((h, w), np.int64)

    def slab(xa, xb, lo, hi, z, label, k):
        x, up = rays[..., 0] * z, 1.3 - rays[..., 1] * z
        hit = (x >= xa) & (x <= xb) & (up >= lo) & (up <= hi) & (z < depth)
        depth[hit] = z
        labels[hit] = label
        who[hit] = k

    slots = rng.permutation(np.linspace(-2.0, 2.0, 6))
    people = int(rng.integers(1, 4))
    for k, centre in enumerate(slots[:people] * 0.9, start=1):
        z = rng.uniform(2.0, 4.5)
        x = centre * z / 4.5
        top = rng.uniform(1.6, 1.9)
        slab(x - 0.18, x + 0.18, 0.0, top - 0.75, z + 0.06, 4, k)  # legs
        slab(x - 0.225, x + 0.225, top - 0.75, top - 0.22, z, 4, k)  # the body
        slab(x - 0.1, x + 0.1, top - 0.22, top, z - 0.03, 11, k)  # head
    for centre in slots[people:people + int(rng.integers(1, 3))]:
        z = rng.uniform(2.0, 4.5)
        x = centre * z / 4.5
        half = rng.uniform(0.3, 0.6)
        slab(x - half, x + half, 0.0, rng.uniform(0.5, 1.0), z, 0, 0)
    return np.round(depth * 1000).astype(np.uint16), labels, who


def candidates(seeds, vote: float):
    """Features and truths of the candidates of rooms ``seeds``, the 'forest' calling a
    random ``vote`` share of every candidate's pixels a body part (people and cabinets
    alike: the vote tells nothing)."""
    seg = Segmenter(min_pixels=50)
    xs, ys = [], []
    for s in seeds:
        depth, labels, who = room(s)
        rng = np.random.default_rng(1000 + s)
        called = ((rng.uniform(size=depth.shape) < vote) & (depth > 0)).astype(np.uint8) * 4
        comp, x = seg.features(depth, INTR, called)
        size = np.bincount(comp.ravel(), minlength=len(x))
        person = np.bincount(comp.ravel(), weights=(who > 0).ravel(), minlength=len(x))
        ok = ~np.isnan(x).any(1)
        xs.append(x[ok])
        ys.append(person[ok] >= 0.5 * size[ok])
    return np.concatenate(xs), np.concatenate(ys)


def test_people_are_told_from_furniture_where_the_vote_cannot():
    x, y = candidates(range(30), vote=0.3)
    assert 30 <= y.sum() and (~y).sum() >= 20  # both kinds occur
    stage = PersonStage.fit(x, y, FEATURES, trees=30, seed=0)
    xt, yt = candidates(range(100, 115), vote=0.3)
    called = stage.predict_proba(xt) >= 0.5
    assert called[yt].mean() >= 0.9 and called[~yt].mean() <= 0.1
    body = FEATURES.index("body")
    assert (xt[:, body] < 0.5).all()  # the vote at 0.5 would have found nobody
    # the segmentation stage with it: instances of a new room are its people
    depth, labels, who = room(200)
    seg = Segmenter(min_pixels=50)
    noisy = ((np.random.default_rng(5).uniform(size=depth.shape) < 0.3)
             & (depth > 0)).astype(np.uint8) * 4
    inst = seg.instances(depth, INTR, noisy, stage)
    assert inst.max() == who.max()
    for k in range(1, who.max() + 1):
        assert (inst[who == k] > 0).mean() > 0.9
    assert (inst[who == 0] == 0).mean() > 0.99
    assert not seg.instances(depth, INTR, noisy).any()  # the vote alone: nobody


def test_fit_is_seeded_and_nan_rows_are_nobody():
    x, y = candidates(range(8), vote=0.6)
    a = PersonStage.fit(x, y, FEATURES, trees=5, seed=3)
    b = PersonStage.fit(x, y, FEATURES, trees=5, seed=3)
    c = PersonStage.fit(x, y, FEATURES, trees=5, seed=4)
    np.testing.assert_array_equal(a.threshold, b.threshold)
    assert len(a.threshold) != len(c.threshold) or not np.array_equal(a.threshold,
                                                                       c.threshold)
    rows = np.vstack([x[:3], np.full((1, len(FEATURES)), np.nan)])
    p = a.predict_proba(rows)
    assert p[-1] == 0.0 and ((p >= 0) & (p <= 1)).all()
    with pytest.raises(ValueError, match="both kinds"):
        PersonStage.fit(x[y], y[y], FEATURES)


def test_stage_travels_in_the_forest_file(tmp_path, capsys):
    from vhgen.forest.trees import first_trees, truncate

    x, y = candidates(range(8), vote=0.6)
    stage = PersonStage.fit(x, y, FEATURES, trees=4, seed=1)
    f = Forest(np.zeros((1, 4), np.int16), np.zeros(1, np.int32), np.full(1, -1, np.int32),
               np.zeros(1, np.int16), np.ones((1, 3), np.int64), np.zeros(1, np.int64),
               {"label_names": ["a", "b"]}, stage)
    back = Forest.load(f.save(tmp_path / "f.npz"))
    assert back.person_stage is not None and back.person_stage.features == FEATURES
    np.testing.assert_array_equal(back.person_stage.predict_proba(x), stage.predict_proba(x))
    assert truncate(back, 3).person_stage is back.person_stage
    assert first_trees(back, 1).person_stage is back.person_stage
    f.person_stage = None
    assert Forest.load(f.save(tmp_path / "g.npz")).person_stage is None
    # a stage of other features (an older vhgen's): a warning, and the vote decides
    from dataclasses import replace

    from vhgen.forest.commands import load_any_forest

    f.person_stage = replace(stage, features=(*FEATURES[:-1], "retired_feature"))
    path = f.save(tmp_path / "old.npz")
    capsys.readouterr()
    assert load_any_forest(str(path)).person_stage is None
    assert "retired_feature" in capsys.readouterr().err


def rooms_store(path, seeds) -> str:
    frames = [room(s) for s in seeds]
    return write_store(path, np.stack([f[0] for f in frames]),
                       np.stack([f[1] for f in frames]), fx=INTR.fx)


def eval_json(capsys, tmp_path, name: str, *args: str) -> dict:
    """``vhgen forest eval ARGS --json tmp_path/name``: its JSON (the command must succeed)."""
    from tests.forest.test_cli import run

    code, _, err = run(capsys, "forest", "eval", *args, "--json", str(tmp_path / name))
    assert code == 0, err
    return json.loads((tmp_path / name).read_text())


def test_cli_person_stage_and_segmented_parts(tmp_path, capsys):
    from tests.forest.test_cli import one_line_error, run

    store = rooms_store(tmp_path / "rooms.zarr", range(24))
    forest = tmp_path / "f.npz"
    code, out, _ = run(capsys, "forest", "train", store, "--out", str(forest), *SMALL,
                       "--max-frames", "8", "--background-share", "0.5",
                       "--person-frames", "16")
    assert code == 0
    f = Forest.load(forest)
    assert f.person_stage is not None and f.meta["person_stage"]["frames"] == 16
    # its frames were the 16 the forest did not train on
    from vhgen.forest.data import select_frames, store_info
    from vhgen.forest.from_stores import person_stage_frames

    used = {g for _, _, g in select_frames([store_info(store)], 8, 0)}
    stage_frames = {g for _, _, g in person_stage_frames(f, [store], 16, 0)}
    assert len(stage_frames) == 16 and not used & stage_frames
    # with another store before it: still none of the forest's frames, matched by store
    other = rooms_store(tmp_path / "other.zarr", range(500, 504))
    mixed = person_stage_frames(f, [other, store], 20, 0)
    assert len(mixed) == 20
    assert not {fr for p, fr, _ in mixed if p == store} & used
    assert sum(p == other for p, _, _ in mixed) == 4

    parts = tmp_path / "parts.npz"
    code, _, _ = run(capsys, "forest", "train", store, "--out", str(parts), *SMALL,
                     "--segmented")
    assert code == 0
    p = Forest.load(parts)
    assert p.meta["params"]["segmented"] and not p.counts[:, 0].any()  # no background seen

    test = rooms_store(tmp_path / "test.zarr", range(300, 306))
    res = eval_json(capsys, tmp_path, "e.json", str(forest), test, "--segment", "--parts",
                    str(parts))
    assert res["parts_on"] == "the true people alone"
    assert "person stage" in res["people"]["called"]
    assert res["mean_per_class"] > 0.9  # body and head of segmented people
    # --cut-out: the same frames with their people alone measured: nothing else to call
    whole = eval_json(capsys, tmp_path, "w.json", str(forest), test)
    assert not whole["cut_out"] and whole["people"]["overall"]["precision"] < 0.99
    cut = eval_json(capsys, tmp_path, "c.json", str(forest), test, "--cut-out")
    assert cut["cut_out"] and cut["people"]["overall"]["precision"] == 1.0
    cut = eval_json(capsys, tmp_path, "c.json", str(forest), test, "--segment", "--cut-out")
    assert cut["people"]["overall"]["instance_recall"] > 0.5
    one_line_error(capsys, "forest", "eval", str(forest), "--real", str(tmp_path / "rooms.zarr"),
                   "--cut-out", match="--cut-out: a setting of the test stores")
    # the segmented forest evaluated alone: also on the true people
    code, _, _ = run(capsys, "forest", "eval", str(parts), test, "--json",
                     str(tmp_path / "p.json"))
    assert json.loads((tmp_path / "p.json").read_text())["parts_on"] == "the true people alone"

    from PIL import Image

    depth, _, who = room(400)
    png = tmp_path / "d.png"
    Image.fromarray(depth).save(png)
    code, out, _ = run(capsys, "forest", "label", str(forest), str(png), "-o",
                       str(tmp_path / "l.png"), "--segment", "--parts", str(parts),
                       "--instances", str(tmp_path / "i.png"), "--fx", str(INTR.fx))
    assert code == 0
    lab = np.asarray(Image.open(tmp_path / "l.png"))
    inst = np.asarray(Image.open(tmp_path / "i.png"))
    assert ((lab > 0) == (inst > 0))[depth > 0].all()  # parts exactly on the people found

    one_line_error(capsys, "forest", "label", str(forest), str(png), "-o",
                   str(tmp_path / "x.png"), "--segment", "--parts", str(forest),
                   match="not a --segmented forest")
    one_line_error(capsys, "forest", "label", str(forest), str(png), "-o",
                   str(tmp_path / "x.png"), "--parts", str(parts), match="--parts: needs --segment")
    code, out, _ = run(capsys, "forest", "person-stage", str(forest), store, "--frames", "4",
                       "--out", str(tmp_path / "g.npz"), "--quiet")
    assert code == 0 and Forest.load(tmp_path / "g.npz").person_stage is not None
    assert not Forest.load(tmp_path / "g.npz").meta["person_stage"]["cut_out"]
    code, out, _ = run(capsys, "forest", "person-stage", str(forest), store, "--frames", "4",
                       "--out", str(tmp_path / "h.npz"), "--quiet", "--cut-out")
    assert code == 0 and Forest.load(tmp_path / "h.npz").meta["person_stage"]["cut_out"]
    a, b = (Forest.load(tmp_path / n).person_stage.to_arrays("s") for n in ("g.npz", "h.npz"))
    assert any(a[k].shape != b[k].shape or (a[k] != b[k]).any() for k in a)  # other rows
    # --vote mass: kept in the file, so that eval and label decide as the stage learnt
    code, out, _ = run(capsys, "forest", "person-stage", str(forest), store, "--frames", "4",
                       "--out", str(tmp_path / "m.npz"), "--quiet", "--vote", "mass")
    mass = Forest.load(tmp_path / "m.npz")
    assert code == 0 and mass.meta["vote"] == "mass" and mass.meta["person_stage"]["vote"] == "mass"
    assert "vote" not in Forest.load(tmp_path / "g.npz").meta  # argmax: as before
    assert Predictor(mass).vote == "mass"
    code, _, err = run(capsys, "forest", "export", str(tmp_path / "m.npz"), "-o",
                       str(tmp_path / "pcl"))
    assert code == 0 and "--vote mass" in err
    every = tmp_path / "every.npz"
    assert main(["forest", "train", store, "--out", str(every), *SMALL]) == 0
    capsys.readouterr()
    one_line_error(capsys, "forest", "person-stage", str(every), store,
                   match="every frame of these stores trained the part forest")
    one_line_error(capsys, "forest", "train", store, "--out", str(every), *SMALL,
                   "--segmented", "--background-share", "0.5",
                   match="a --segmented forest sees no background")


def test_a_stage_trained_without_the_floor_too_decides_where_none_is_found():
    from vhgen.forest.from_stores import stage_rows

    seg = Segmenter(min_pixels=50)
    depth, labels, who = room(3)
    called = (labels > 0).astype(np.uint8) * 4
    cand = seg.candidates(depth, INTR, called)
    assert cand.floor is not None  # the level camera sees the floor
    with_floor = seg.describe(cand, depth, INTR, called)
    np.testing.assert_array_equal(with_floor, seg.features(depth, INTR, called)[1])
    bare = seg.describe(cand, depth, INTR, called, use_floor=False)
    ok = ~np.isnan(with_floor).any(1)
    col = {k: FEATURES.index(k) for k in ("has_floor", "top_m", "bottom_m", "height_m",
                                          "body", "depth_m")}
    assert (with_floor[ok, col["has_floor"]] == 1).all() and (bare[ok, col["has_floor"]] == 0).all()
    np.testing.assert_array_equal(bare[ok, col["top_m"]], bare[ok, col["height_m"]])
    assert (bare[ok, col["bottom_m"]] == 0).all()
    for k in ("body", "depth_m"):  # what does not depend on the floor stays
        np.testing.assert_array_equal(bare[ok, col[k]], with_floor[ok, col[k]])
    # the training rows: each candidate twice with a floor found, once with the option off
    x2, y2 = stage_rows(seg, depth, INTR, called, who)
    x1, y1 = stage_rows(seg, depth, INTR, called, who, without_floor=False)
    assert len(x2) == 2 * len(x1) == 2 * ok.sum() and y2.sum() == 2 * y1.sum() > 0
    np.testing.assert_array_equal(x1, with_floor[ok])

    # a stage that learned from both descriptions finds the people of new rooms whose
    # floor was not found, and not their cabinets
    def rows(seeds, without_floor):
        xs, ys = [], []
        for s in seeds:
            d, lab, k = room(s)
            noisy = ((np.random.default_rng(1000 + s).uniform(size=d.shape) < 0.3)
                     & (d > 0)).astype(np.uint8) * 4
            x, y = stage_rows(seg, d, INTR, noisy, k, without_floor)
            xs.append(x)
            ys.append(y)
        return np.concatenate(xs), np.concatenate(ys)

    stage = PersonStage.fit(*rows(range(30), True), FEATURES, trees=30, seed=0)
    xt, yt = rows(range(100, 115), True)
    floorless = xt[:, col["has_floor"]] == 0
    assert floorless.sum() >= 20
    p = stage.predict_proba(xt[floorless]) >= 0.5
    assert p[yt[floorless]].mean() >= 0.9 and p[~yt[floorless]].mean() <= 0.1
def test_segmented_share_sees_some_frames_segmented():
    """--segmented-share: each frame, by its own seeded draw, is seen segmented (no
    background depth, no background sample) or whole (background sampled at its share)."""
    from vhgen.forest.features import BACKGROUND_MM
    from vhgen.forest.train import ImageShard, TrainParams

    frames = [room(s) for s in range(40)]
    depth = np.stack([f[0] for f in frames])
    labels = np.stack([f[1] for f in frames])
    params = TrainParams(trees=1, depth=4, pixels_per_image=200, background_share=0.5,
                         segmented_share=0.5, seed=2)
    shard = ImageShard(depth, labels, range(40), params)
    seg = shard.segmented
    assert 10 < seg.sum() < 30  # about half
    again = ImageShard(depth, labels, range(40), params)
    np.testing.assert_array_equal(again.segmented, seg)  # seeded per frame
    bg = (labels == 0) & (depth > 0)
    assert (shard.depth[seg][bg[seg]] == BACKGROUND_MM).all()
    assert (shard.depth[~seg][bg[~seg]] == depth[~seg][bg[~seg]]).all()
    shard.start_tree(0, int(labels.max()) + 1)
    on_bg = shard.s_lab == 0
    assert on_bg.any() and not seg[shard.s_img[on_bg]].any()  # background of whole frames only
    whole = ~seg[shard.s_img]
    assert 0.4 < on_bg[whole].mean() < 0.6  # at the background share
    assert not ImageShard(depth, labels, range(40), TrainParams(
        segmented_share=0.0)).segmented.any()
    # a store given in segmented_stores: every frame of it segmented, whatever the share
    where = ["/a"] * 20 + ["/b"] * 20
    forced = ImageShard(depth, labels, range(40), TrainParams(
        segmented_share=0.5, seed=2, segmented_stores=("/b",)), where).segmented
    assert forced[20:].all() and (forced[:20] == seg[:20]).all()
    assert ImageShard(depth, labels, range(40), TrainParams(segmented=True)).segmented.all()


def test_cli_one_forest_for_the_stage_and_the_parts(tmp_path, capsys):
    """A forest trained with --segmented-share takes a person stage and labels the people
    it finds as their parts (--parts with the same file)."""
    from tests.forest.test_cli import one_line_error, run

    store = rooms_store(tmp_path / "rooms.zarr", range(24))
    forest = tmp_path / "f.npz"
    code, out, err = run(capsys, "forest", "train", store, "--out", str(forest), *SMALL,
                         "--max-frames", "8", "--background-share", "0.5",
                         "--segmented-share", "0.5", "--person-frames", "16")
    assert code == 0, err
    f = Forest.load(forest)
    assert f.person_stage is not None and f.meta["params"]["segmented_share"] == 0.5
    test = rooms_store(tmp_path / "test.zarr", range(300, 306))
    res = eval_json(capsys, tmp_path, "e.json", str(forest), test, "--segment", "--parts",
                    str(forest))
    assert res["parts_on"] == "the true people alone"
    assert res["people"]["overall"]["instance_recall"] > 0.5
    # without --parts: the forest labels the people it finds itself, the same scores
    alone = eval_json(capsys, tmp_path, "s.json", str(forest), test, "--segment")
    assert alone["mean_per_class"] == res["mean_per_class"]
    assert alone["people"]["overall"] == res["people"]["overall"]
    from PIL import Image

    depth, _, _ = room(400)
    png = tmp_path / "d.png"
    Image.fromarray(depth).save(png)
    code, out, err = run(capsys, "forest", "label", str(forest), str(png), "-o",
                         str(tmp_path / "l.png"), "--segment", "--instances",
                         str(tmp_path / "i.png"), "--fx", str(INTR.fx))
    assert code == 0, err
    lab = np.asarray(Image.open(tmp_path / "l.png"))
    inst = np.asarray(Image.open(tmp_path / "i.png"))
    assert inst.any() and ((lab > 0) == (inst > 0))[depth > 0].all()
    one_line_error(capsys, "forest", "train", store, "--out", str(tmp_path / "x.npz"), *SMALL,
                   "--segmented-share", "1.5",
                   match="--segmented-share 1.5: must be a number in [0, 1]")
    one_line_error(capsys, "forest", "train", store, "--out", str(tmp_path / "x.npz"), *SMALL,
                   "--segmented", "--segmented-share", "0.5",
                   match="--segmented sees every frame segmented")
    one_line_error(capsys, "forest", "train", store, "--out", str(tmp_path / "x.npz"), *SMALL,
                   "--segmented-share", "0.5", "--segmented-stores", str(test),
                   match="test.zarr: not one of the training stores")


def _one_tree_at_a_time(stage: PersonStage, x: np.ndarray) -> np.ndarray:
    """The reference of PersonStage.predict_proba: each tree walked alone, row by row."""
    out = np.zeros(len(x))
    for i, row in enumerate(x):
        if np.isnan(row).any():
            continue
        total = 0.0
        for r in stage.roots:
            node = r
            while stage.feature[node] >= 0:
                left = row[stage.feature[node]] < stage.threshold[node]
                node = stage.left[node] if left else stage.right[node]
            total += stage.prob[node]
        out[i] = total / len(stage.roots)
    return out


def test_every_tree_at_once_equals_one_tree_at_a_time():
    x, y = candidates(range(10), vote=0.4)
    stage = PersonStage.fit(x, y, FEATURES, trees=25, seed=2)
    rows = np.vstack([x, np.full((2, len(FEATURES)), np.nan)])
    np.testing.assert_array_equal(stage.predict_proba(rows), _one_tree_at_a_time(stage, rows))
    assert stage.predict_proba(np.full((3, len(FEATURES)), np.nan)).tolist() == [0.0] * 3


def test_a_stage_of_fewer_features_reads_its_own_columns():
    from vhgen.forest.segment import feature_columns

    x, y = candidates(range(12), vote=0.3)
    old = FEATURES[:16]  # the features of the stages before "behind" and the column
    stage = PersonStage.fit(x[:, :16], y, old, trees=10, seed=0)
    depth, labels, who = room(7)
    seg = Segmenter(min_pixels=50)
    noisy = ((np.random.default_rng(3).uniform(size=depth.shape) < 0.3)
             & (depth > 0)).astype(np.uint8) * 4
    comp, person = seg.people(depth, INTR, noisy, stage)
    _, feats = seg.features(depth, INTR, noisy)
    expect = stage.predict_proba(feats[:, :16]) >= seg.min_person_prob
    expect[0] = False
    np.testing.assert_array_equal(person, expect)
    assert person.any()
    assert feature_columns(("body", "depth_m")) == [FEATURES.index("body"), 0]
    with pytest.raises(ValueError, match="retired"):
        feature_columns(("body", "retired"))


def test_a_person_seen_past_someone_in_front_keeps_their_column():
    """A 1.8 m person 4 m away, their middle (0.6-1.2 m) hidden by a 0.6 m wide board 2 m
    away (0.95-1.25 m above the floor): the segmentation sees two pieces of them, each
    short, but each piece's column is the whole person, and something stands in front of
    both."""
    rays = pixel_rays(INTR)
    y = rays[..., 1]
    depth = np.minimum(np.full(y.shape, 6.0),
                       np.where(y > 1e-9, 1.3 / np.maximum(y, 1e-9), np.inf))
    who = np.zeros(y.shape, np.int64)

    def slab(xa, xb, lo, hi, z, k):
        x, up = rays[..., 0] * z, 1.3 - rays[..., 1] * z
        hit = (x >= xa) & (x <= xb) & (up >= lo) & (up <= hi) & (z < depth)
        depth[hit] = z
        who[hit] = k

    slab(-0.25, 0.25, 0.0, 1.8, 4.0, 1)  # the person
    slab(-0.3, 0.3, 0.95, 1.25, 2.0, 2)  # the board in front
    d = np.round(depth * 1000).astype(np.uint16)
    labels = (who == 1).astype(np.uint8) * 4
    seg = Segmenter(min_pixels=30)
    cand = seg.candidates(d, INTR, labels)
    x = seg.describe(cand, d, INTR, labels)
    col = {k: FEATURES.index(k) for k in ("height_m", "top_m", "behind", "column_height_m",
                                          "column_share")}
    pieces = [c for c in range(1, cand.count + 1) if not np.isnan(x[c]).any()
              and (who[cand.comp == c] == 1).mean() > 0.9]
    assert len(pieces) == 2  # the head and shoulders above the board, the legs below
    box = int(np.bincount(cand.comp[who == 2]).argmax())
    for c in pieces:
        assert x[c, col["height_m"]] < 0.6  # each piece alone is short (0.52-0.55)
        # its column is the person (2nd to 98th percentile heights of its pieces: 1.71)
        assert 1.6 < x[c, col["column_height_m"]] <= 1.8
        assert x[c, col["column_share"]] < 0.8
        assert x[c, col["behind"]] > 0.15  # the board stands in front of it (0.23)
    assert x[box, col["behind"]] == 0.0  # nothing stands in front of the board
    # the board's own column: itself alone (the person is 2 m behind it)
    assert x[box, col["column_share"]] == 1.0


def test_a_cropped_view_cuts_people_off_at_its_edges():
    from vhgen.forest.from_stores import cropped_view

    depth, labels, who = room(4)
    views = [cropped_view(depth, who, np.random.default_rng(s)) for s in range(20)]
    again = cropped_view(depth, who, np.random.default_rng(3))
    np.testing.assert_array_equal(views[3][0], again[0])  # seeded
    h, w = depth.shape
    for d, t in views:
        rows = np.flatnonzero((d > 0).any(1))
        cols = np.flatnonzero((d > 0).any(0))
        assert rows[0] == 0 and 0.4 * h - 1 <= rows[-1] + 1 <= 0.8 * h + 1  # the top kept
        assert 0.5 * w - 1 <= cols[-1] + 1 - cols[0] <= w
        window = np.zeros_like(d, bool)
        window[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1] = True
        np.testing.assert_array_equal(d[window], depth[window])  # measured as before inside
        assert not d[~window].any() and not t[~window].any()
        np.testing.assert_array_equal(t[window], who[window])
    # a person's legs are out of view in some of the views, the floor in most
    assert any((t[who > 0] == 0).any() and (t > 0).any() for _, t in views)


def test_at_image_edge_is_the_measured_frames_edge():
    """A sensor leaves a border unmeasured, so a candidate cut off by the frame never
    reaches the image's last pixel: ``at_image_edge`` is measured against the box of the
    measured pixels. In a room whose 10 px border is unmeasured, a person in the middle is
    not at the edge; the same person in a view cut off above their knees is."""
    depth, labels, who = room(4)
    seg = Segmenter(min_pixels=50)
    edge = FEATURES.index("at_image_edge")
    framed = depth.copy()
    framed[:10], framed[-10:], framed[:, :10], framed[:, -10:] = 0, 0, 0, 0

    def people_edges(d):
        comp, x = seg.features(d, INTR, labels * (d > 0))
        ids = [c for c in range(1, len(x)) if not np.isnan(x[c]).any()
               and (who[comp == c] > 0).mean() > 0.9]
        assert ids
        return x[ids, edge]

    assert (people_edges(framed) == 0).all()
    cut = framed.copy()
    cut[int(np.flatnonzero((who > 0).any(1)).max()) - 15:] = 0  # the bottom 15 rows of people
    assert (people_edges(cut) == 1).all()
    # every candidate reaching the first measured column (the floor's) is at the edge,
    # though none reaches the image's own first column
    comp, x = seg.features(framed, INTR, labels)
    left = [c for c in range(1, len(x)) if not np.isnan(x[c]).any() and (comp[:, 10] == c).any()]
    assert left and (x[left, edge] == 1).all() and not comp[:, 0].any()


def test_a_lone_things_view_keeps_the_free_standing_things_alone():
    """The things of a frame with nothing around them: furniture, props and clutter
    measured; people (labelled or by class), what they carry, the room's surfaces and
    what hangs on them not; classes the store does not name are not things."""
    from vhgen.forest.data import lone_things_view

    names = ("background", "floor", "wall", "prop", "person", "chair", "window", "carried",
             "lamp")
    classes = np.array([[0, 1, 2, 3, 4, 5, 6, 7, 8, 9]], np.uint8)
    depth = np.arange(1000, 1010, dtype=np.uint16)[None]
    truth = np.zeros_like(classes)
    view = lone_things_view(depth, truth, classes, names)
    assert view.dtype == depth.dtype
    assert np.flatnonzero(view[0]).tolist() == [3, 5, 8]  # prop, chair, lamp
    truth[0, 5] = 7  # a labelled person's pixel (a hand on the chair's back) is no thing
    assert np.flatnonzero(lone_things_view(depth, truth, classes, names)[0]).tolist() == [3, 8]


def test_a_cut_out_view_keeps_the_people_alone(tmp_path):
    """The person stage also learns from frames whose background was removed before the
    forest saw them (``cut_out_view``): only people measured, hair and clothes (scene class
    person) with them. Learnt from such views of rooms, it calls the people of new cut-out
    rooms people and still rejects the cabinets of whole rooms."""
    import zarr

    from vhgen.forest.data import read_classes, select_frames, store_info
    from vhgen.forest.from_stores import cut_out_view, stage_rows
    from vhgen.scene.geometry import FLOOR, PERSON

    depth, labels, who = room(5)
    classes = np.where(who > 0, PERSON, FLOOR).astype(np.uint8)
    truth = np.where(labels == 11, 0, labels)  # the heads unlabelled: hair, as a hat is
    view = cut_out_view(depth, truth, classes)
    keep = who > 0
    np.testing.assert_array_equal(view[keep], depth[keep])
    assert not view[~keep].any() and view.dtype == depth.dtype
    # without a classes array (zeros): the labelled people alone
    assert not cut_out_view(depth, truth, np.zeros_like(classes))[labels == 11].any()

    # classes read where a store has them, background (0) where it has none
    with_c = rooms_store(tmp_path / "c.zarr", range(3))
    zarr.open_group(with_c, mode="r+").create_array(
        "classes", data=np.full((3,) + depth.shape, PERSON, np.uint8),
        chunks=(1,) + depth.shape)
    without = rooms_store(tmp_path / "n.zarr", range(2))
    frames = select_frames([store_info(without), store_info(with_c)], None, 0)
    got = read_classes(frames, (5,) + depth.shape)
    assert not got[:2].any() and (got[2:] == PERSON).all()
    assert store_info(with_c).has_classes and not store_info(without).has_classes

    seg = Segmenter(min_pixels=50)

    def rows(seeds, cut):
        xs, ys = [], []
        for s in seeds:
            d, lab, k = room(s)
            if cut:
                d = cut_out_view(d, lab, np.zeros_like(lab))
            noisy = ((np.random.default_rng(1000 + s).uniform(size=d.shape) < 0.3)
                     & (d > 0)).astype(np.uint8) * 4
            x, y = stage_rows(seg, d, INTR, noisy, k)
            xs.append(x)
            ys.append(y)
        return np.concatenate(xs), np.concatenate(ys)

    train = [rows(range(30), False), rows(range(30), True)]
    stage = PersonStage.fit(np.concatenate([x for x, _ in train]),
                            np.concatenate([y for _, y in train]), FEATURES, trees=30, seed=0)
    xc, yc = rows(range(100, 115), True)
    assert yc.sum() >= 20 and (stage.predict_proba(xc[yc]) >= 0.5).mean() >= 0.9
    xw, yw = rows(range(100, 115), False)
    assert (~yw).sum() >= 10 and (stage.predict_proba(xw[~yw]) >= 0.5).mean() <= 0.1


def test_nothing_narrower_than_a_forearm_is_a_person():
    """A stage that calls every candidate a person still passes no candidate under
    ``min_width_m`` wide on the floor: a pole 0.03 m across (a curtain fold) in a room of
    people is dropped, the people are kept."""
    from dataclasses import replace

    depth, labels, who = room(3)
    rays = pixel_rays(INTR)
    z = 2.2
    x, up = rays[..., 0] * z, 1.3 - rays[..., 1] * z
    pole = (np.abs(x - 1.2) <= 0.015) & (up >= 0.0) & (up <= 1.5) & (depth > z * 1000)
    depth[pole], labels[pole], who[pole] = round(z * 1000), 4, 0
    yes = PersonStage(np.array([-1]), np.zeros(1), np.array([-1]), np.array([-1]),
                      np.ones(1), np.array([0]), FEATURES)
    seg = Segmenter(min_pixels=20)
    comp, x_all = seg.features(depth, INTR, labels)
    k = np.bincount(comp[pole]).argmax()  # the pole's candidate
    assert (comp == k).sum() >= 20 and x_all[k, FEATURES.index("width_m")] < 0.05
    _, ok = seg.people(depth, INTR, labels, yes)
    assert not ok[k]
    for p in range(1, who.max() + 1):  # every person still kept
        assert ok[np.bincount(comp[who == p]).argmax()]
    _, every = replace(seg, min_width_m=0.0).people(depth, INTR, labels, yes)
    assert every[k] and every.sum() == ok.sum() + 1
