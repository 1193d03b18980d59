"""Person scores by distance, group size and instance (vhgen.forest.persons) on hand-made
frames whose answers are counted by hand, and through `vhgen forest eval` on a store with
an ``instances`` array."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.forest.conftest import two_boxes, write_store
from tests.forest.test_cli import one_line_error, run
from vhgen.cli import main
from vhgen.forest.persons import (
    DISTANCE_BINS,
    PeopleScore,
    distance_bin,
    frame_people,
    group_bin,
    neighbour_pairs,
    table,
)


@pytest.mark.parametrize(("d", "name"), [(0.5, "<1"), (0.999, "<1"), (1.0, "1-2"),
                                         (1.999, "1-2"), (2.0, "2-3"), (2.999, "2-3"),
                                         (3.0, "3-4.5"), (4.499, "3-4.5"), (4.5, ">4.5"),
                                         (9.0, ">4.5")])
def test_distance_bins_are_half_open(d, name):
    assert distance_bin(d) == name


@pytest.mark.parametrize(("n", "name"), [(0, "0"), (1, "1"), (2, "2-3"), (3, "2-3"),
                                         (4, "4-6"), (6, "4-6"), (7, ">6"), (None, "?")])
def test_group_bins(n, name):
    assert group_bin(n) == name


def known_frame() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 10x12 frame: a wall at 5 m; person 1 (rows 0-4, cols 0-3, 20 px) at 1.5 m
    but for 4 px at 1.9 m and 2 px without a measurement (18 valid, median 1.5 m);
    person 2 (rows 0-4, cols 4-7, 20 px) at 2.5 m, touching person 1; person 3 (rows
    7-9, cols 8-11, 12 px) at 4.0 m, apart. Called: all of person 1, exactly half of
    person 2 (10 px), 5 of person 3's 12 px, 3 wall pixels and one pixel of person 1
    without a measurement (not counted)."""
    depth = np.full((10, 12), 5000, np.uint16)
    inst = np.zeros((10, 12), np.uint8)
    inst[0:5, 0:4], depth[0:5, 0:4] = 1, 1500
    depth[4, 0:4] = 1900
    depth[0, 0:2] = 0
    inst[0:5, 4:8], depth[0:5, 4:8] = 2, 2500
    inst[7:10, 8:12], depth[7:10, 8:12] = 3, 4000
    called = inst == 1
    called[0:5, 4:6] = True  # person 2: 10 of 20
    called[7, 8:12] = True
    called[8, 8] = True  # person 3: 5 of 12
    called[9, 0:3] = True  # the wall
    return called, depth, inst


def test_one_known_frame():
    called, depth, inst = known_frame()
    fp = frame_people(called, depth, inst)
    assert fp.group == "2-3"
    by = {p["instance"]: p for p in fp.people}
    assert by[1] == {"instance": 1, "pixels": 18, "called": 18, "distance_m": 1.5,
                     "touching": True}
    assert by[2] == {"instance": 2, "pixels": 20, "called": 10, "distance_m": 2.5,
                     "touching": True}
    assert by[3] == {"instance": 3, "pixels": 12, "called": 5, "distance_m": 4.0,
                     "touching": False}
    # called pixels by their own depth: person 1's 14 at 1.5 m and 4 at 1.9 m, person
    # 2's 10 at 2.5 m, person 3's 5 at 4 m; the wall's 3 at 5 m
    np.testing.assert_array_equal(fp.called_person, [0, 18, 10, 5, 0])
    np.testing.assert_array_equal(fp.called_other, [0, 0, 0, 0, 3])

    score = PeopleScore()
    score.add(fp, ("s", 0))
    res = score.result()
    rows = {r["bin"]: r for r in res["by_distance"]}
    assert list(rows) == ["1-2", "2-3", "3-4.5", ">4.5"]
    assert (rows["1-2"]["people"], rows["1-2"]["found"], rows["1-2"]["recall"]) == (1, 1, 1.0)
    # exactly half of its pixels called: found
    assert (rows["2-3"]["found"], rows["2-3"]["recall"]) == (1, 0.5)
    assert (rows["3-4.5"]["found"], rows["3-4.5"]["recall"]) == (0, 5 / 12)
    assert rows["3-4.5"]["precision"] == 1.0
    assert rows[">4.5"]["people"] == 0 and rows[">4.5"]["precision"] == 0.0
    groups = {r["bin"]: r for r in res["by_group"]}
    assert list(groups) == ["1", "2-3", "4-6"]
    assert groups["1"]["frames"] == 0 and groups["1"]["recall"] is None
    g = groups["2-3"]
    assert (g["frames"], g["people"], g["found"]) == (1, 3, 2)
    assert g["recall"] == pytest.approx(33 / 50) and g["precision"] == pytest.approx(33 / 36)
    contact = {r["bin"]: r for r in res["by_contact"]}
    assert (contact["touching"]["people"], contact["touching"]["found"]) == (2, 2)
    assert (contact["apart"]["people"], contact["apart"]["found"]) == (1, 0)
    assert res["overall"]["instance_recall"] == pytest.approx(2 / 3)
    assert res["instances"][2] == ["s", 0, 3, 12, 4.0, round(5 / 12, 4), False, False]
    text = table(res)
    assert "1-2 m" in text and "4-6" in text and "0.660" in text and "touching" in text


def test_everyone_found_counts_frames_whose_every_person_is():
    """The issue's "every person found": a frame counts only when all its people are;
    frames with nobody visible are not in the share."""
    called, depth, inst = known_frame()  # persons 1 and 2 found, 3 not
    score = PeopleScore()
    score.add(frame_people(called, depth, inst), ("s", 0))
    everyone = called | (inst == 3)  # now person 3 too
    score.add(frame_people(everyone, depth, inst), ("s", 1))
    score.add(frame_people(everyone, depth, np.zeros_like(inst)), ("s", 2))  # nobody
    res = score.result()
    g = {r["bin"]: r for r in res["by_group"]}["2-3"]
    assert (g["frames"], g["frames_everyone_found"], g["everyone_found"]) == (2, 1, 0.5)
    assert res["overall"]["frames"] == 3 and res["overall"]["everyone_found"] == 0.5
    assert {r["bin"]: r for r in res["by_group"]}["1"]["everyone_found"] is None
    assert "all found" in table(res) and "0.500" in table(res)


def test_false_people_are_called_instances_mostly_not_a_person():
    """With the calls given as instance ids, a called instance less than half of whose
    measured pixels are a person's is a false person; exactly half is not one. A bare
    mask counts none and reports no false_per_frame."""
    called, depth, inst = known_frame()
    ids = np.zeros(called.shape, np.uint8)
    ids[called & (inst == 1)] = 1  # person 1
    ids[called & (inst == 2)] = 2  # half of person 2
    ids[called & (inst == 3)] = 3  # some of person 3
    ids[9, 0:3] = 4  # the wall: 3 px, no person
    ids[5, 0:2], ids[6, 0:2] = 5, 5  # 4 px of wall
    ids[7, 0:4] = 5  # and 4 more: 0 of 8 a person
    half = np.zeros(called.shape, bool)
    half[5, 8:12] = True  # 4 wall pixels with 4 of person 3's not yet called
    ids[half] = 6
    rows, cols = np.nonzero((inst == 3) & ~(ids > 0))
    ids[rows[:4], cols[:4]] = 6  # 4 person pixels + 4 wall: exactly half, not false
    fp = frame_people(ids, depth, inst)
    assert fp.false_people == 2  # 4 and 5
    # the scores of the ids are those of the mask they cover
    same = frame_people(ids > 0, depth, inst)
    assert same.false_people is None
    np.testing.assert_array_equal(fp.called_other, same.called_other)
    assert [p["called"] for p in fp.people] == [p["called"] for p in same.people]

    score = PeopleScore()
    score.add(fp, ("s", 0))
    score.add(frame_people(np.zeros_like(ids), depth, inst), ("s", 1))  # nothing called
    res = score.result()
    g = {r["bin"]: r for r in res["by_group"]}
    assert (g["2-3"]["false_people"], g["2-3"]["false_per_frame"]) == (2, 1.0)
    # six called instances, two of them false (the empty frame calls none)
    assert (g["2-3"]["called_people"], g["2-3"]["instance_precision"]) == (6, 4 / 6)
    assert "false_per_frame" not in g["1"]  # no frames there
    assert res["overall"]["false_per_frame"] == 1.0
    assert "false/frame" in table(res) and "1.000" in table(res)

    plain = PeopleScore()
    plain.add(same, ("s", 0))
    assert "false_per_frame" not in plain.result()["overall"]
    assert "false/frame" not in table(plain.result())


def test_frames_whose_background_is_called_past_three_percent():
    """A frame's background called: its measured pixels on no person that are called,
    over those pixels (68 of the known frame's wall). 3 of 68 is over 3%, 2 of 68 not;
    the frames over it are counted per group bin and overall."""
    called, depth, inst = known_frame()
    fp = frame_people(called, depth, inst)
    assert fp.background == 68 and fp.background_called == pytest.approx(3 / 68)
    fewer = called.copy()
    fewer[9, 2] = False
    assert frame_people(fewer, depth, inst).background_called == pytest.approx(2 / 68)
    score = PeopleScore()
    score.add(fp, ("s", 0))
    score.add(frame_people(fewer, depth, inst), ("s", 1))
    alone = np.where(inst == 1, inst, 0)  # one person: the others' pixels are background
    score.add(frame_people(called, depth, alone), ("s", 2))
    res = score.result()
    g = {r["bin"]: r for r in res["by_group"]}
    assert (g["2-3"]["background_over"], g["2-3"]["background_over_share"]) == (1, 0.5)
    assert g["1"]["background_over"] == 1  # persons 2 and 3's called pixels now count
    assert res["overall"]["background_over"] == 2
    assert res["background_frames"] == [["s", 0, round(3 / 68, 4)], ["s", 2, round(
        frame_people(called, depth, alone).background_called, 4)]]
    assert res["background_share"] == 0.03 and "bg>3%" in table(res)
    nothing = frame_people(np.zeros_like(called), depth, np.full_like(inst, 1))
    assert nothing.background == 0 and nothing.background_called == 0.0


def test_neighbour_pairs_are_the_4_neighbours_of_different_ids():
    ids = np.array([[1, 1, 0, 3],
                    [2, 1, 0, 3],
                    [0, 2, 4, 0]], np.int32)  # 2 touches 1 twice and 4; 4, 3 by a corner
    assert neighbour_pairs(ids).tolist() == [[1, 2], [2, 1], [2, 4], [4, 2]]
    ids[2, 3] = 3  # now by an edge
    assert neighbour_pairs(ids).tolist() == [[1, 2], [2, 1], [2, 4], [3, 4], [4, 2], [4, 3]]
    assert neighbour_pairs(np.zeros((3, 3), np.int32)).shape == (0, 2)


def test_one_pixel_short_of_half_is_not_found():
    called, depth, inst = known_frame()
    called[0, 4] = False  # person 2: 9 of 20
    score = PeopleScore()
    score.add(frame_people(called, depth, inst), ("s", 0))
    row = {r["bin"]: r for r in score.result()["by_distance"]}["2-3"]
    assert (row["people"], row["found"]) == (1, 0)


def slow_reference(frames: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> dict:
    """Per distance bin: (people, found, pixels, called pixels), pixel by pixel."""
    out: dict[str, list[int]] = {}
    for called, depth, inst in frames:
        for k in range(1, 256):
            px = [(y, x) for y in range(inst.shape[0]) for x in range(inst.shape[1])
                  if inst[y, x] == k and depth[y, x] > 0]
            if not px:
                continue
            d = sorted(int(depth[p]) for p in px)
            n = len(d)
            med = (d[n // 2] if n % 2 else (d[n // 2 - 1] + d[n // 2]) / 2) / 1000.0
            hit = sum(bool(called[p]) for p in px)
            row = out.setdefault(distance_bin(med), [0, 0, 0, 0])
            row[0] += 1
            row[1] += int(2 * hit >= n)
            row[2] += n
            row[3] += hit
    return out


def test_random_frames_against_a_slow_reference():
    rng = np.random.default_rng(5)
    frames = []
    score = PeopleScore()
    for i in range(6):
        inst = rng.integers(0, 5, size=(9, 11)).astype(np.uint8)
        depth = rng.integers(600, 6000, size=(9, 11)).astype(np.uint16)
        depth[rng.random((9, 11)) < 0.2] = 0
        called = rng.random((9, 11)) < 0.5
        frames.append((called, depth, inst))
        score.add(frame_people(called, depth, inst), ("s", i))
    res = score.result()
    ref = slow_reference(frames)
    for r in res["by_distance"]:
        want = ref.get(r["bin"], [0, 0, 0, 0])
        assert [r["people"], r["found"], r["pixels"]] == want[:3]
        if want[2]:
            assert r["recall"] == pytest.approx(want[3] / want[2])
    assert {r["bin"] for r in res["by_distance"]} <= set(DISTANCE_BINS)


def test_labels_without_instances_are_one_person_of_unknown_group():
    called, depth, inst = known_frame()
    fp = frame_people(called, depth, (inst > 0).astype(np.uint8), has_instances=False)
    assert fp.group == "?" and len(fp.people) == 1
    score = PeopleScore()
    score.add(fp, ("s", 0), has_instances=False)
    res = score.result()
    assert res["truth"] == "labels" and res["by_group"][-1]["bin"] == "?"


def add_instances(store: str, inst: np.ndarray) -> None:
    import zarr

    g = zarr.open_group(store, mode="r+", zarr_format=3)
    g.create_array("instances", data=inst, chunks=(1,) + inst.shape[1:])


def test_forest_eval_prints_and_writes_person_scores(tmp_path, capsys, boxes_store):
    forest = tmp_path / "f.npz"
    assert main(["forest", "train", boxes_store, "--out", str(forest), "--trees", "1",
                 "--depth", "4", "--features", "10", "--thresholds", "4",
                 "--pixels-per-image", "50", "--quiet"]) == 0
    # two frames: each box pair as two touching people (2.0 and 2.4 m: both in 2-3)
    d, lab = two_boxes(2, seed=4)
    inst = lab.copy()
    store = write_store(tmp_path / "people.zarr", d, lab)
    add_instances(store, inst)
    code, out, err = run(capsys, "forest", "eval", str(forest), store, "--json",
                         str(tmp_path / "e.json"))
    assert code == 0 and err == "", err
    assert "person scores (called: forest labels > 0" in out
    assert "2-3 m" in out and "touching" in out
    res = json.loads((tmp_path / "e.json").read_text())["people"]
    assert res["truth"] == "instances" and res["overall"]["people"] == 4
    assert {r["bin"]: r["frames"] for r in res["by_group"]}["2-3"] == 2
    assert {r["bin"]: r["people"] for r in res["by_distance"]}["2-3"] == 4
    assert len(res["instances"]) == 4 and all(row[7] for row in res["instances"])
    # the segmentation's mask instead: the same people, scored on another mask; the part
    # scores stay the forest's own
    code, out, err = run(capsys, "forest", "eval", str(forest), store, "--segment",
                         "--json", str(tmp_path / "s.json"))
    assert code == 0 and "called: --segment (min_body_fraction 0.5)" in out
    seg = json.loads((tmp_path / "s.json").read_text())["people"]
    assert seg["overall"]["people"] == 4
    assert seg["overall"]["pixels"] == res["overall"]["pixels"]
    # the segmentation's people are instances: its false people are counted, the forest's
    # bare labels have none to count
    assert seg["overall"]["false_people"] >= 0 and "false/frame" in out
    assert seg["overall"]["false_per_frame"] == seg["overall"]["false_people"] / 2
    assert "false_per_frame" not in res["overall"]
    a = json.loads((tmp_path / "e.json").read_text())
    b = json.loads((tmp_path / "s.json").read_text())
    assert a["confusion"] == b["confusion"]


def test_eval_flag_errors_are_one_line(tmp_path, capsys, boxes_store):
    forest = str(tmp_path / "f.npz")
    assert main(["forest", "train", boxes_store, "--out", forest, "--trees", "1",
                 "--depth", "2", "--features", "4", "--thresholds", "2",
                 "--pixels-per-image", "20", "--quiet"]) == 0
    capsys.readouterr()
    one_line_error(capsys, "forest", "eval", forest, boxes_store, "--masks", str(tmp_path),
                   match="person masks are for --real frames")
    one_line_error(capsys, "forest", "eval", forest, boxes_store, "--min-body-fraction",
                   "0.5", match="a setting of --segment")
    one_line_error(capsys, "forest", "eval", forest, "--people-only",
                   str(tmp_path / "missing"), match="--people-only")
    one_line_error(capsys, "forest", "eval", forest, match="--people-only")


def test_people_test_config_is_held_out_and_covers_the_bins():
    """configs/forest/people_test.yaml: groups of 1-6, the first person 1-4 m away (the
    others up to 1.5 m further); it, the lines and the offices have no motion or seed of
    the training configs (the forests' and the person stage's, and the lines tried as
    training data)."""
    from pathlib import Path

    from vhgen.job_config import JobConfig

    configs = Path(__file__).resolve().parents[2] / "configs" / "forest"
    test = JobConfig.load(configs / "people_test.yaml")
    assert test.scene.people == (1, 6)
    assert test.camera.distance_m[0] <= 1.0 and test.camera.distance_m[1] >= 3.0
    # the groups standing side by side (people_lineup_test.yaml): 4-6 in a line
    lineup = JobConfig.load(configs / "people_lineup_test.yaml")
    assert lineup.scene.people == (4, 6) and lineup.scene.lineup is not None
    assert lineup.scene.lineup.share == 1.0
    assert lineup.seed != test.seed
    # the offices full of chairs (people_office_test.yaml): 1-2 people, mostly chairs
    office = JobConfig.load(configs / "people_office_test.yaml")
    assert office.scene.people == (1, 2) and office.seed not in (test.seed, lineup.seed)
    weight = dict(zip(office.scene.clutter.kinds, office.scene.clutter.weights, strict=True))
    assert weight["chair"] > 2 * max(w for k, w in weight.items() if k != "chair")
    for held_out in (test, lineup, office):
        for name in ("people_room", "people_real", "people_groups", "people_far",
                     "people_lines", "people_things"):
            train = JobConfig.load(configs / f"{name}.yaml")
            assert not ({Path(m).name for m in held_out.motions}
                        & {Path(m).name for m in train.motions})
            assert held_out.seed != train.seed


def test_people_things_config_draws_person_sized_things_more():
    """configs/forest/people_things.yaml (the recipe's fifth person-stage store): every
    clutter kind, the free-standing person-sized ones the recipe's stage took for people
    drawn more often than any other."""
    from vhgen.job_config import JobConfig
    from vhgen.scene.clutter.kinds import CLUTTER_KINDS
    from vhgen.yamlio import configs_dir

    clutter = JobConfig.load(configs_dir() / "forest" / "people_things.yaml").scene.clutter
    weight = dict(zip(clutter.kinds, clutter.weights, strict=True))
    assert set(weight) == set(CLUTTER_KINDS)
    tall = ("chair", "coat_stand", "plant", "lamp", "door", "bookcase")
    assert min(weight[k] for k in tall) > max(w for k, w in weight.items() if k not in tall)
