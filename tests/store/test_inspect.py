"""`vhgen inspect` on a real store, then on copies damaged by hand in one way each: every
defect must be reported with the array, shard and frame range (or manifest row) at fault."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.conftest import unmerge_manifest
from vhgen.cli import main
from vhgen.store.inspect import inspect_store

pytestmark = pytest.mark.slow


@pytest.fixture
def damaged(small_store, tmp_path) -> Path:
    out = tmp_path / "copy.zarr"
    shutil.copytree(small_store, out)
    return out


def test_clean_store_has_no_defects_and_a_histogram(small_store, capsys):
    import zarr

    rep = inspect_store(small_store)
    assert rep.defects == []
    assert rep.num_frames == 8 and rep.frames_per_shard == 3 and rep.frames_checked == 8
    assert set(rep.arrays) == {"depth", "labels", "raw", "instances", "classes"}
    g = zarr.open_group(str(small_store), mode="r")
    labels = g["labels"][:]
    # the histogram is the exact pixel count per part over every frame
    assert rep.histogram.tolist() == np.bincount(labels.ravel(), minlength=32).tolist()
    d = rep.to_dict()
    assert d["histogram"][1]["name"] == "LU_head" and d["histogram"][0]["name"] == "background"
    depth = g["depth"][:]
    frac = (depth > 0).reshape(8, -1).mean(axis=1)
    assert rep.valid["mean_fraction"] == pytest.approx(frac.mean())
    assert 0.7 < rep.valid["body_valid_fraction"] <= 1.0
    assert 800 <= rep.valid["depth_min_mm"] < rep.valid["depth_max_mm"] <= 4000
    assert main(["inspect", str(small_store)]) == 0
    out = capsys.readouterr().out
    assert "LU_head" in out and "OK: no defects" in out


def _defects(store: Path, capsys) -> list[str]:
    """Run the CLI; it must exit 1 and print one DEFECT line per defect."""
    assert main(["inspect", str(store)]) == 1
    out = capsys.readouterr().out
    return [line for line in out.splitlines() if line.startswith("DEFECT ")]


def test_deleted_shard_file(damaged, capsys):
    (damaged / "raw" / "c" / "2" / "0" / "0").unlink()
    assert _defects(damaged, capsys) == [
        "DEFECT raw shard 2 (frames 6-7): shard file raw/c/2/0/0 missing"]


def test_truncated_and_garbled_shards(damaged, capsys):
    f = damaged / "labels" / "c" / "1" / "0" / "0"
    f.write_bytes(f.read_bytes()[:1000])  # truncated: the shard index checksum fails
    g = damaged / "depth" / "c" / "0" / "0" / "0"
    b = bytearray(g.read_bytes())
    b[50:150] = b"\xff" * 100  # garbled inside the first chunk's zstd frame
    g.write_bytes(bytes(b))
    lines = _defects(damaged, capsys)
    assert len(lines) == 2, lines
    assert lines[0].startswith("DEFECT depth shard 0 (frames 0-2): unreadable")
    assert lines[1].startswith("DEFECT labels shard 1 (frames 3-5): unreadable")


def _rewrite_manifest(store: Path, edit) -> None:
    t = pq.read_table(store / "manifest.parquet")
    pq.write_table(edit(t), store / "manifest.parquet")


def test_dropped_manifest_row(damaged, capsys):
    _rewrite_manifest(damaged, lambda t: t.filter(pa.array(
        [f != 4 for f in t.column("frame").to_pylist()])))
    assert _defects(damaged, capsys) == [
        "DEFECT manifest.parquet: no row for frames 4 (shards 1)"]


def test_duplicated_manifest_row(damaged, capsys):
    _rewrite_manifest(damaged, lambda t: pa.concat_tables([t, t.slice(6, 1)]))
    assert _defects(damaged, capsys) == [
        "DEFECT manifest.parquet: frame 6 appears 2 times (rows 6, 8)"]


def test_changed_label_pixel(damaged, capsys):
    import zarr

    g = zarr.open_group(str(damaged), mode="r+")
    lab = g["labels"][3:6]
    ys, xs = np.nonzero(lab[1] == 0)
    lab[1, ys[0], xs[0]] = 7  # one background pixel becomes R_shoulder
    g["labels"][3:6] = lab
    body = int(pq.read_table(damaged / "manifest.parquet").column("body_pixels")[4].as_py())
    where = "frame 4 (shard 1 (frames 3-5))"
    assert _defects(damaged, capsys) == [
        f"DEFECT {where}: labels have {body + 1} body pixels, manifest body_pixels says {body}",
        f"DEFECT {where}: instances and labels disagree on 1 pixels (person without body "
        "part or the reverse)",
        f"DEFECT {where}: classes and labels disagree on 1 pixels (person class without body "
        "part or the reverse)"]


def test_instances_and_classes_checked_against_labels(damaged, capsys):
    import zarr

    g = zarr.open_group(str(damaged), mode="r+")
    inst = g["instances"][0:3]
    ys, xs = np.nonzero(inst[1] > 0)
    inst[1, ys[:5], xs[:5]] = 0  # five person pixels lose their instance
    inst[2][inst[2] > 0] = 3  # frame 2 has one person, not three
    g["instances"][0:3] = inst
    cls = g["classes"][6:8]
    cls[0, 0, 0] = 9  # no such class
    g["classes"][6:8] = cls
    assert _defects(damaged, capsys) == [
        "DEFECT frame 1 (shard 0 (frames 0-2)): instances and labels disagree on 5 pixels "
        "(person without body part or the reverse)",
        "DEFECT frame 2 (shard 0 (frames 0-2)): instance 3 but the manifest row has "
        "num_people 1",
        "DEFECT frame 6 (shard 2 (frames 6-7)): class 9 is not in class_names (0..4)"]


def test_changed_depth_pixel_and_out_of_range_label(damaged, capsys):
    import zarr

    g = zarr.open_group(str(damaged), mode="r+")
    dep = g["depth"][6:8]
    dep[1][dep[1] > 0] = 0  # every measurement of frame 7 lost
    g["depth"][6:8] = dep
    lab = g["labels"][0:3]
    lab[2, 0, 0] = 200
    g["labels"][0:3] = lab
    lines = _defects(damaged, capsys)
    assert lines[0] == "DEFECT labels shard 0 (frames 0-2): label 200 > K=31 in frames 2"
    assert lines[1].startswith("DEFECT frame 2 (shard 0 (frames 0-2)): labels have")
    # the stray label also has no person instance or class under it
    assert lines[2].startswith("DEFECT frame 2 (shard 0 (frames 0-2)): instances and labels")
    assert lines[3].startswith("DEFECT frame 2 (shard 0 (frames 0-2)): classes and labels")
    assert lines[4].startswith("DEFECT frame 7 (shard 2 (frames 6-7)): depth has 0 valid")
    assert len(lines) == 5


def test_missing_manifest_and_part(damaged, capsys):
    unmerge_manifest(damaged, drop=(1,))
    lines = _defects(damaged, capsys)
    assert lines == [
        "DEFECT manifest.parquet missing (job not finished? run 'vhgen generate ... --resume')",
        "DEFECT shard 1 (frames 3-5): completion record manifest/part-000001.parquet missing"]


def test_not_a_store_is_a_user_error(tmp_path, capsys):
    assert main(["inspect", str(tmp_path)]) == 2
    assert "not a Zarr v3 group" in capsys.readouterr().err
