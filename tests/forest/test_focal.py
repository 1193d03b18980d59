"""The forest and the camera's focal length: probes scaled to the frame's camera at
inference (``at_focal``); frames seen as a camera of another focal length sees them
(``zoom_view``)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.forest.conftest import two_boxes
from vhgen.errors import ForestError
from vhgen.executor import InlinePool
from vhgen.forest.data import zoom_view
from vhgen.forest.train import ImageShard, TrainParams, grow_forest
from vhgen.forest.trees import Forest, Predictor, at_focal

PARAMS = TrainParams(trees=2, depth=8, pixels_per_image=300, features=60, thresholds=12,
                     seed=5, max_offset=40, min_samples=4)


def train(depth, labels, params=PARAMS) -> Forest:
    shard = ImageShard(depth, labels, range(len(depth)), params)
    forest = grow_forest(InlinePool.holding([shard]), 3, params, {})
    forest.meta.update({"fx": 525.0, "fy": 525.0})
    return forest


def zoomed(depth, labels, zoom):
    pairs = [zoom_view(d, lab, zoom) for d, lab in zip(depth, labels, strict=True)]
    return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])


def accuracy(forest, depth, labels) -> float:
    pred = Predictor(forest).predict(depth)
    body = labels > 0
    return float((pred[body] == labels[body]).mean())


def test_zoom_view_is_a_longer_or_shorter_focal_length():
    d = np.zeros((60, 80), np.uint16)
    lab = np.zeros((60, 80), np.uint8)
    d[25:35, 35:45], lab[25:35, 35:45] = 2000, 1  # a 10 px box at the centre
    z, zl = zoom_view(d, lab, 2.0)
    assert (zl == 1).sum() == 400 and set(np.unique(z)) == {0, 2000}  # 20 px, same depth
    z, zl = zoom_view(d, lab, 0.5)
    assert (zl == 1).sum() == 25
    assert not z[:14].any() and not z[:, :19].any()  # outside the rendered view: nothing
    same = zoom_view(d, lab, 1.0)
    assert same[0] is d and same[1] is lab


def test_probes_follow_the_frames_focal_length():
    d, lab = two_boxes(24, seed=1)
    forest = train(d, lab)
    dt, lt = zoomed(*two_boxes(8, seed=99), 1.6)  # a camera of 1.6 x the focal length
    plain = accuracy(forest, dt, lt)
    scaled = at_focal(forest, 525.0 * 1.6)
    assert scaled.meta["fx"] == pytest.approx(840.0)
    assert scaled.meta["trained_focal"] == [525.0, 525.0]
    np.testing.assert_array_equal(scaled.offsets, np.rint(forest.offsets * 1.6))
    assert accuracy(scaled, dt, lt) > 0.97 and plain < 0.9
    # the training camera within half a pixel, or an unknown one: the forest itself
    assert at_focal(forest, 525.4) is forest and at_focal(forest, None) is forest
    nofx = Forest(forest.offsets, forest.thresh, forest.left, forest.depth, forest.counts,
                  forest.roots, {})
    assert at_focal(nofx, 600.0) is nofx
    # fy on its own: only the vertical offsets change
    tall = at_focal(forest, 525.0, 1050.0)
    np.testing.assert_array_equal(tall.offsets[:, [0, 2]], forest.offsets[:, [0, 2]])
    np.testing.assert_array_equal(tall.offsets[:, [1, 3]], forest.offsets[:, [1, 3]] * 2)


def test_label_scales_the_probes_to_fx(tmp_path, capsys):
    from PIL import Image

    from tests.forest.conftest import write_store
    from tests.forest.test_cli import SMALL, run

    d, lab = two_boxes(24, seed=1)
    store = write_store(tmp_path / "boxes.zarr", d, lab)
    forest = tmp_path / "f.npz"
    assert run(capsys, "forest", "train", store, "--out", str(forest), *SMALL)[0] == 0
    dt, lt = zoomed(*two_boxes(1, seed=97), 1.6)
    png = tmp_path / "near.png"
    Image.fromarray(dt[0]).save(png)
    body = lt[0] > 0
    got = {}
    for fx in (None, "840"):
        out = tmp_path / f"lab{fx}.png"
        code, _, err = run(capsys, "forest", "label", str(forest), str(png), "-o", str(out),
                           *(["--fx", fx] if fx else []))
        assert code == 0
        assert ("scaled by 1.600" in err) == (fx is not None)
        # a PNG records no focal length: said, unless --fx gives it
        assert ("near.png: no focal length recorded" in err) == (fx is None)
        got[fx] = (np.array(Image.open(out))[body] == lt[0][body]).mean()
    assert got["840"] > 0.97 and got["840"] > got[None] + 0.05
    # a PCD says its camera's focal length itself, and --fx overrides what it says
    from vhgen.camera import Intrinsics
    from vhgen.depthfile import write_pcd

    h, w = dt[0].shape
    for said, fx, scaled in ((840.0, None, True), (525.0, "840", True), (525.0, None, False)):
        pcd = write_pcd(tmp_path / "near.pcd", dt[0],
                        Intrinsics(w, h, said, said, (w - 1) / 2, (h - 1) / 2))
        out = tmp_path / "pcd.png"
        code, _, err = run(capsys, "forest", "label", str(forest), str(pcd), "-o", str(out),
                           *(["--fx", fx] if fx else []))
        right = (np.array(Image.open(out))[body] == lt[0][body]).mean()
        assert code == 0 and ("scaled by 1.600" in err) == scaled
        assert "no focal length recorded" not in err  # a PCD records its own
        assert (right > 0.97) == scaled, (said, fx, right)


def test_the_person_stage_learns_from_the_vote_at_its_stores_focal_length(tmp_path,
                                                                          monkeypatch):
    """train_person_stage labels each store's frames with the forest scaled to that
    store's focal length, as forest eval does (the stage learns the vote it will see)."""
    import vhgen.forest.trees as trees
    from tests.forest.conftest import write_store
    from vhgen.forest.from_stores import train_person_stage

    d, lab = two_boxes(24, seed=1)
    forest = train(d, lab)
    forest.meta.update({"label_names": ["a", "b"], "stores": []})
    dz, lz = zoomed(*two_boxes(6, seed=5), 1.6)
    store = write_store(tmp_path / "near.zarr", dz, lz, fx=840.0)
    asked = []
    real = trees.at_focal

    def spy(f, fx, fy=None):
        asked.append((fx, fy))
        return real(f, fx, fy)

    monkeypatch.setattr(trees, "at_focal", spy)
    try:
        train_person_stage(forest, [store], frames=6, trees=2, cropped=False)
    except ForestError:
        pass  # two boxes are no people: what matters is the forest the frames were labelled by
    assert asked == [(840.0, 840.0)]


def test_eval_says_once_that_png_frames_record_no_focal_length(tmp_path, capsys):
    from PIL import Image

    from tests.forest.conftest import write_store
    from tests.forest.test_cli import SMALL, run

    d, lab = two_boxes(12, seed=3)
    store = write_store(tmp_path / "boxes.zarr", d, lab)
    forest = tmp_path / "f.npz"
    assert run(capsys, "forest", "train", store, "--out", str(forest), *SMALL)[0] == 0
    frames = tmp_path / "people"
    frames.mkdir()
    for i in range(3):
        Image.fromarray(d[i]).save(frames / f"f{i}.png")
    code, _, err = run(capsys, "forest", "eval", str(forest), "--people-only", str(frames))
    assert code == 0 and err.count("no focal length recorded") == 1
    assert "(and 2 more frames)" in err and "--fx" in err
    code, _, err = run(capsys, "forest", "eval", str(forest), "--people-only", str(frames),
                       "--fx", "525")
    assert code == 0 and "focal length" not in err
