"""Real-frame evaluation: person IoU, recall, precision and background called a body
part, on synthetic frames with known answers and through `vhgen forest eval` on the
shared real frames (person.pcd with its mask, a room capture with nobody in it)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.forest.test_cli import one_line_error
from vhgen.camera import Intrinsics
from vhgen.cli import main
from vhgen.depthfile import write_pcd
from vhgen.forest.realeval import evaluate_real, load_real_frames, person_counts

REPO = Path(__file__).resolve().parents[2]
REAL = REPO.parent / "shared" / "real"
MASKS = REPO / "docs" / "forest_study" / "real_masks"
INTR = Intrinsics(64, 48, 52.5, 52.5, 31.5, 23.5)


def _frame(tmp_path: Path, name: str, mask: np.ndarray | None = None, box: bool = True
           ) -> Path:
    """A 64x48 frame: a wall at 3 m, a 'person' box at 1.5 m in columns 20-39, rows 10-47
    (unless not ``box``), no measurement in rows 0-1; its mask beside it when given."""
    d = np.full((48, 64), 3000, np.uint16)
    if box:
        d[10:, 20:40] = 1500
    d[:2] = 0
    p = write_pcd(tmp_path / f"{name}.pcd", d, INTR)
    if mask is not None:
        Image.fromarray(mask.astype(np.uint8) * 255).save(tmp_path / f"{name}.mask.png")
    return p


def _box_mask() -> np.ndarray:
    m = np.zeros((48, 64), bool)
    m[10:, 20:40] = True
    return m


def test_counts_on_a_known_frame():
    depth = np.full((4, 5), 1000, np.uint16)
    depth[0, 0] = 0  # no measurement: never counted
    mask = np.zeros((4, 5), bool)
    mask[:, :2] = True  # 7 valid person pixels
    pred = np.zeros((4, 5), np.uint8)
    pred[:, 1:3] = 3  # called: column 1 (person) and column 2 (background)
    pred[0, 0] = 5  # called but without a measurement
    c = person_counts(pred, depth, mask)
    assert c == {"tp": 4, "fp": 4, "fn": 3, "background": 12}
    assert person_counts(pred, depth, None) == {"tp": 0, "fp": 8, "fn": 0, "background": 19}


def test_scores_of_perfect_and_of_everything_called(tmp_path):
    _frame(tmp_path, "a", _box_mask())
    _frame(tmp_path, "room", box=False)
    frames = load_real_frames([tmp_path / "a.pcd"], [tmp_path / "room.pcd"])
    assert [f.mask is not None for f in frames] == [True, False]
    perfect = evaluate_real(lambda fr: (fr.depth_mm == 1500).astype(np.uint8), frames)
    assert perfect["person_iou"] == 1.0 and perfect["background_called"] == 0.0
    everything = evaluate_real(lambda fr: np.ones(fr.depth_mm.shape, np.uint8), frames,
                               out_dir=tmp_path / "sheet")
    valid = 48 * 64 - 2 * 64
    person = 38 * 20
    assert everything["person_iou"] == pytest.approx(person / valid)
    assert everything["person_recall"] == 1.0
    assert everything["background_called"] == 1.0
    assert everything["background_called_nobody"] == 1.0
    assert (tmp_path / "sheet" / "real_sheet.png").is_file()


def test_bad_or_missing_masks_are_one_line_and_skipped(tmp_path):
    _frame(tmp_path, "good", _box_mask())
    _frame(tmp_path, "nomask")
    _frame(tmp_path, "small")
    Image.fromarray(np.zeros((10, 10), np.uint8)).save(tmp_path / "small.mask.png")
    warned: list[str] = []
    frames = load_real_frames([tmp_path], [], warn=warned.append)
    assert [Path(f.frame.path).name for f in frames] == ["good.pcd"]
    assert len(warned) == 2 and all("\n" not in w for w in warned)
    assert any("nomask.pcd: a frame with people needs a person mask" in w for w in warned)
    assert any("small.mask.png: mask is 10x10, its frame 64x48" in w for w in warned)


def test_forest_eval_on_shared_real_frames(tmp_path, capsys, boxes_store):
    """`vhgen forest eval FOREST --real person.pcd --masks ... --nobody capture0001.pcd`
    scores the forest on the real frames (the mask of person.pcd is ours:
    scripts/make_person_mask.py) and writes the scores and the sheet."""
    forest = tmp_path / "f.npz"
    assert main(["forest", "train", boxes_store, "--out", str(forest), "--trees", "1",
                 "--depth", "4", "--features", "10", "--thresholds", "4",
                 "--pixels-per-image", "50", "--quiet"]) == 0
    out = tmp_path / "eval"
    assert main(["forest", "eval", str(forest), "--real", str(REAL / "person.pcd"),
                 "--masks", str(MASKS), "--nobody", str(REAL / "capture0001.pcd"),
                 "--out", str(out), "--json", str(out / "scores.json")]) == 0
    printed = capsys.readouterr().out
    assert "person.pcd" in printed and "capture0001.pcd" in printed
    res = json.loads((out / "scores.json").read_text())["real"]
    assert res["frames_with_people"] == 1 and res["frames_with_nobody"] == 1
    rows = {Path(r["frame"]).name: r for r in res["per_frame"]}
    mask = np.asarray(Image.open(MASKS / "person.png")) > 0
    assert rows["person.pcd"]["tp"] + rows["person.pcd"]["fn"] == int(mask.sum())
    for k in ("person_iou", "person_recall", "person_precision", "background_called"):
        assert 0.0 <= res[k] <= 1.0
    assert (out / "real_sheet.png").is_file() and res["segment"] is False
    # the segmentation stage: never more body pixels than the forest alone gave
    assert main(["forest", "eval", str(forest), "--real", str(REAL / "person.pcd"),
                 "--masks", str(MASKS), "--segment", "--json", str(out / "seg.json")]) == 0
    seg = json.loads((out / "seg.json").read_text())["real"]
    assert seg["segment"] is True
    plain = rows["person.pcd"]
    srow = seg["per_frame"][0]
    assert srow["fp"] <= plain["fp"] and srow["tp"] + srow["fn"] == plain["tp"] + plain["fn"]
    label = tmp_path / "label.png"
    assert main(["forest", "label", str(forest), str(REAL / "person.pcd"), "-o", str(label),
                 "--segment"]) == 0
    assert np.asarray(Image.open(label)).shape == (480, 640)
    strict = tmp_path / "strict.png"  # a stricter vote can only drop whole clusters
    assert main(["forest", "label", str(forest), str(REAL / "person.pcd"), "-o", str(strict),
                 "--segment", "--min-body-fraction", "1.0"]) == 0
    loose_body = np.asarray(Image.open(label)) > 0
    strict_body = np.asarray(Image.open(strict)) > 0
    assert not (strict_body & ~loose_body).any()
    one_line_error(capsys, "forest", "label", str(forest), str(REAL / "person.pcd"), "-o",
                   str(strict), "--segment", "--min-body-fraction", "2",
                   match="--min-body-fraction")
    one_line_error(capsys, "forest", "eval", str(forest), match="give test stores")


def test_people_only_frames_are_scored_on_recall(tmp_path):
    """A frame of people only (the source removed the background): the mask is depth > 0,
    so every call is a hit and every miss a person pixel; kept out of IoU and precision."""
    d = np.zeros((48, 64), np.uint16)
    d[10:, 20:40] = 1500  # 760 px
    Image.fromarray(d).save(tmp_path / "only.png")
    Image.fromarray(np.zeros((48, 64), np.uint16)).save(tmp_path / "empty.png")
    warned: list[str] = []
    frames = load_real_frames([], [], people_only=[tmp_path], warn=warned.append)
    assert [f.kind for f in frames] == ["people_only"]
    assert len(warned) == 1 and "empty.png" in warned[0] and "without a measured" in warned[0]
    half = evaluate_real(lambda fr: np.where(np.arange(64) < 30, 1, 0).astype(np.uint8)
                         [None].repeat(48, 0), frames)
    row = half["per_frame"][0]
    assert (row["tp"], row["fn"], row["fp"], row["background"]) == (380, 380, 0, 0)
    assert row["recall"] == 0.5 and row["iou"] is None
    assert half["people_only"] == {"frames": 1, "person_recall": 0.5,
                                   "person_recall_mean": 0.5}
    assert half["frames_with_people"] == 0 and half["person_iou"] is None


def test_forest_eval_on_skeltrack_frames(tmp_path, capsys, boxes_store):
    """`vhgen forest eval FOREST --people-only` on two of the shared Skeltrack frames
    (one with two people): per-frame recall over every measured pixel."""
    forest = tmp_path / "f.npz"
    assert main(["forest", "train", boxes_store, "--out", str(forest), "--trees", "1",
                 "--depth", "4", "--features", "10", "--thresholds", "4",
                 "--pixels-per-image", "50", "--quiet"]) == 0
    names = ["depth-data-1028894671.png", "depth-data-1399145206.png"]
    assert main(["forest", "eval", str(forest), "--people-only",
                 *[str(REAL / "skeltrack" / n) for n in names],
                 "--json", str(tmp_path / "s.json")]) == 0
    printed = capsys.readouterr().out
    assert "people only (mask = depth > 0): person recall" in printed
    res = json.loads((tmp_path / "s.json").read_text())["real"]
    rows = {Path(r["frame"]).name: r for r in res["per_frame"]}
    assert list(rows) == names
    for n, r in rows.items():
        valid = int((np.asarray(Image.open(REAL / "skeltrack" / n)) > 0).sum())
        assert r["kind"] == "people_only" and r["tp"] + r["fn"] == valid and r["fp"] == 0
        assert f"{n:<28}   only" in printed
    assert res["people_only"]["frames"] == 2 and 0.0 <= res["people_only"]["person_recall"] <= 1
