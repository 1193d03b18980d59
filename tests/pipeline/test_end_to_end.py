"""End to end through Ray on 2 CPUs with the OSMesa backend, on real CMU files: the CI
smoke run. Checks the dataset contract, worker-count invariance (byte for byte) and that
a worker killed mid-job neither loses nor duplicates a frame."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import unmerge_manifest
from tests.pipeline.faulty_worker import run_faulty
from vhgen.job_config import JobConfig
from vhgen.pipeline.driver import run_job

pytestmark = pytest.mark.slow

CONFIG = """
name: smoke
seed: 11
motions: [{m}/01_01.bvh, {m}/02_01.bvh, {m}/10_01.bvh, {tmp}/broken.bvh]
sensor: kinect_v1_full
poses: {{frame_step: 400, skip_first: 1, max_per_motion: 3}}
avatars: {{count: 2}}
output: {{frames_per_shard: 3, arrays: [depth, labels, instances, classes, raw]}}
render: {{backend: osmesa}}
num_workers: 2
"""


def _config(tmp: Path, shared: Path, **kw) -> JobConfig:
    p = tmp / "smoke.yaml"
    text = (shared / "02_01.bvh").read_text()
    (tmp / "broken.bvh").write_text(text[: len(text) // 2])  # cut mid-file
    p.write_text(CONFIG.format(m=shared, tmp=tmp))
    return JobConfig.load(p, **kw)


@pytest.fixture(scope="module")
def smoke(tmp_path_factory, shared_mocap, asset_dir):
    tmp = tmp_path_factory.mktemp("e2e")
    cfg = _config(tmp, shared_mocap)
    summary = run_job(cfg, tmp / "two.zarr")
    return tmp, cfg, summary


def _store_files(path: Path) -> dict[str, bytes]:
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*"))
            if p.is_file() and {"depth", "labels", "instances", "classes"} & set(p.parts)}


def test_contract(smoke, shared_mocap):
    import pyarrow.parquet as pq
    import zarr

    tmp, cfg, summary = smoke
    store = tmp / "two.zarr"
    assert summary.frames == 10 and summary.poses == 5
    assert [s["file"].split("/")[-1] for s in summary.skipped] == ["broken.bvh"]
    assert "data rows" in summary.skipped[0]["error"]
    assert all("llvmpipe" in r for r in summary.renderers)
    g = zarr.open_group(str(store), mode="r")
    depth, labels = g["depth"], g["labels"]
    assert depth.shape == (10, 480, 640) and depth.dtype == np.uint16
    assert labels.shape == (10, 480, 640) and labels.dtype == np.uint8
    names = g.attrs["label_names"]
    assert len(names) == 31 and names[0] == "LU_head"
    assert len(g.attrs["label_colors"]) == 32
    # the motions attribute uses the one clip report format (same as corpus build)
    motions = {m["file"].split("/")[-1]: m for m in g.attrs["motions"]}
    assert list(motions["02_01.bvh"]) == ["file", "status", "frames", "poses_read",
                                          "poses_kept", "dialect", "units_m", "error",
                                          "mapping", "confidence", "up", "reference_frame",
                                          "ref_error_deg", "ref_error_bone", "notes"]
    assert motions["02_01.bvh"]["mapping"] == "map" and motions["02_01.bvh"]["confidence"] == 1
    assert motions["broken.bvh"]["status"] == "skipped"
    assert sum(m["poses_kept"] for m in motions.values()) == summary.poses
    d = depth[:]
    lab = labels[:]
    # scene arrays, read with plain zarr: one person, no geometry in this config
    inst, cls = g["instances"][:], g["classes"][:]
    assert inst.shape == cls.shape == (10, 480, 640)
    assert inst.dtype == cls.dtype == np.uint8
    assert g.attrs["class_names"][:5] == ["background", "floor", "wall", "prop", "person"]
    person = g.attrs["class_names"].index("person")
    assert ((inst == 1) == (lab > 0)).all() and ((cls == person) == (lab > 0)).all()
    for f in range(10):
        body = lab[f] > 0
        assert body.sum() > 5000, f  # a person fills part of every frame
        assert set(np.unique(lab[f])) <= set(range(32))
        valid = d[f] > 0
        # kinect_v1_full: shadows, the correlation window and grazing dropout make holes,
        # and the window's splats fatten edges by a few pixels beyond the body
        assert 0.7 * body.sum() < valid.sum() <= body.sum() * 1.05
        assert (valid & ~body).sum() < 0.05 * body.sum()
        assert d[f][valid].min() >= 800 and d[f][valid].max() <= 4000
    man = pq.read_table(store / "manifest.parquet")
    assert man.num_rows == 10
    assert man.column("frame").to_pylist() == list(range(10))
    assert {Path(f).name for f in man.column("motion_file").to_pylist()} == {
        "01_01.bvh", "02_01.bvh", "10_01.bvh"}
    row = man.slice(0, 1).to_pylist()[0]
    for key in ("motion_file", "source_frame", "avatar_id", "avatar_params", "fx", "fy", "cx",
                "cy", "world_to_camera", "seed", "sensor"):
        assert key in row
    assert Path(row["motion_file"]).name == "01_01.bvh" and row["source_frame"] == 1
    effects = [next(iter(e)) for e in json.loads(row["sensor"])["effects"]]
    assert effects[0] == "range_gate" and effects[-1] == "encode"
    assert "correlation_window" in effects
    holes = json.loads(row["holes"])
    assert holes["no_hit"] > 0 and holes["window"] > 0 and holes["shadow"] >= 0
    raw = g["raw"][:]
    assert raw.dtype == np.uint16 and ((raw == 2047) == (d == 0)).all()
    assert "scale" in json.loads(row["avatar_params"])
    assert row["num_people"] == 1 and json.loads(row["scene"]) is None
    assert man.schema.field("num_people").type == "int32"
    joints = np.asarray(row["joints_cam"], np.float32).reshape(31, 3)
    assert 1.5 < joints[0, 2] < 4.5  # hips in front of the camera


def test_same_bytes_with_one_worker(smoke, shared_mocap):
    """Two local worker processes and one Ray actor write the same bytes."""
    import pyarrow.parquet as pq

    tmp, _, summary = smoke
    assert summary.executor == "local"  # auto, no cluster address: local processes
    cfg1 = _config(tmp, shared_mocap, num_workers=1)
    assert run_job(cfg1, tmp / "one.zarr", executor="ray").executor == "ray"
    a, b = _store_files(tmp / "two.zarr"), _store_files(tmp / "one.zarr")
    assert a.keys() == b.keys() and len(a) >= 6
    assert all(a[k] == b[k] for k in a)
    ma = pq.read_table(tmp / "two.zarr" / "manifest.parquet")
    mb = pq.read_table(tmp / "one.zarr" / "manifest.parquet")
    assert ma.equals(mb)


@pytest.mark.parametrize("executor", ["local", "ray"])
def test_dead_worker_loses_and_duplicates_nothing(smoke, shared_mocap, executor):
    import pyarrow.parquet as pq

    tmp, cfg, _ = smoke
    out = tmp / f"faulty-{executor}.zarr"
    summary = run_faulty(cfg, out, {"die_once": {0, 2}}, executor=executor)
    assert summary.frames == 10 and summary.retries == 2
    a, b = _store_files(tmp / "two.zarr"), _store_files(out)
    assert all(a[k] == b[k] for k in a)
    man = pq.read_table(out / "manifest.parquet")
    assert man.column("frame").to_pylist() == list(range(10))


@pytest.mark.parametrize("executor", ["local", "ray"])
def test_lost_gl_context_is_a_dead_worker(smoke, executor, capfd):
    """A GL context that fails mid-shard (injected moderngl.Error at the shard's second
    frame): the worker exits, the shard is redone whole on a new worker, and the store is
    the same bytes as a run without faults, every frame once."""
    import pyarrow.parquet as pq

    tmp, cfg, _ = smoke
    out = tmp / f"gl-lost-{executor}.zarr"
    summary = run_faulty(cfg, out, {"gl_lost_once": {1}}, executor=executor)
    assert summary.frames == 10 and summary.retries == 1
    a, b = _store_files(tmp / "two.zarr"), _store_files(out)
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a)
    man = pq.read_table(out / "manifest.parquet")
    assert man.column("frame").to_pylist() == list(range(10))
    if executor == "local":  # the worker's one line (a Ray actor's goes to its log)
        err = capfd.readouterr().err
        assert "GL failed on shard 1 (Error: GL_CONTEXT_LOST (injected))" in err


def test_preview_sheet(smoke, tmp_path):
    from PIL import Image

    from vhgen.preview import contact_sheet

    store = smoke[0] / "two.zarr"
    out = contact_sheet(store, tmp_path / "sheet.png", num_frames=3)
    img = np.asarray(Image.open(out))
    assert img.shape[0] >= 3 * 240 and img.shape[1] >= 640
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 40  # depth ramp + part colours


def test_generate_from_pose_table(tmp_path, shared_mocap, asset_dir):
    """`vhgen corpus build` output feeds the generate job instead of raw BVH."""
    import pyarrow.parquet as pq

    from vhgen.mocap.corpus import SparsifySettings, build_corpus
    from vhgen.mocap.posetable import read_pose_table

    table_path = tmp_path / "poses.parquet"
    build_corpus([str(shared_mocap / "02_02.bvh"), str(shared_mocap / "10_01.bvh")], table_path,
                 settings=SparsifySettings(min_angle_deg=40.0), workers=1)
    table = read_pose_table(table_path)
    assert 2 <= table.num_poses <= 40
    cfg_path = tmp_path / "t.yaml"
    cfg_path.write_text(f"name: t\nmotions: [{table_path}]\navatars: {{count: 1}}\n"
                        "output: {frames_per_shard: 8}\nrender: {backend: osmesa}\n"
                        "num_workers: 2\n")
    summary = run_job(JobConfig.load(cfg_path), tmp_path / "t.zarr")
    assert summary.frames == table.num_poses
    man = pq.read_table(tmp_path / "t.zarr" / "manifest.parquet")
    assert man.column("motion_file").to_pylist() == table.source_file
    assert man.column("source_frame").to_pylist() == table.source_frame.tolist()
    assert min(man.column("body_pixels").to_pylist()) > 5000


def test_resume_finishes_an_interrupted_run(smoke, shared_mocap):
    """A run cut short (shard 1's manifest part never written, a stray partial file left):
    --resume redoes only what is missing and ends with the same bytes."""
    import shutil

    import pyarrow.parquet as pq

    tmp, cfg, _ = smoke
    cut = tmp / "cut.zarr"
    shutil.copytree(tmp / "two.zarr", cut)
    unmerge_manifest(cut, drop=(1,))
    (cut / "depth" / "c" / "stray.partial").parent.mkdir(parents=True, exist_ok=True)
    (cut / "depth" / "c" / "stray.partial").write_bytes(b"junk")
    summary = run_job(cfg, cut, resume=True)
    assert summary.written == 1  # only the incomplete shard was redone
    assert not list(cut.rglob("*.partial"))
    a, b = _store_files(tmp / "two.zarr"), _store_files(cut)
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a)
    man = pq.read_table(cut / "manifest.parquet")
    assert man.column("frame").to_pylist() == list(range(10))
    assert not (cut / "manifest").exists()  # merged: the parts are gone, one copy left
    again = run_job(cfg, cut, resume=True)  # a finished store: nothing to render
    assert again.written == 0 and pq.read_table(cut / "manifest.parquet").equals(man)
    with pytest.raises(Exception, match="exists"):
        run_job(cfg, cut)  # neither resume nor overwrite: refuse to clobber


def test_cli_info_and_preview(smoke, tmp_path, capsys):
    from vhgen.cli import main

    store = smoke[0] / "two.zarr"
    assert main(["info", str(store)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["depth"] == [10, 480, 640] and info["manifest_rows"] == 10
    assert main(["preview", str(store), "-o", str(tmp_path / "p.png"), "--frames", "0,9"]) == 0
    assert (tmp_path / "p.png").stat().st_size > 10_000
    assert main(["info", str(tmp_path)]) == 2  # not a store: a clear error, exit 2
    assert "not a Zarr v3 group" in capsys.readouterr().err


SCENE_JOB = """
name: scene_smoke
seed: 7
motions: [{m}/02_01.bvh]
sensor: kinect_v1_full
poses: {{frame_step: 400, skip_first: 1, max_per_motion: 3}}
avatars: {{count: 2}}
scene:
  floor: true
  room: {{width_m: [4, 6], depth_m: [5.5, 7]}}
  people: [1, 3]
  props: {{count: [2, 4]}}
output: {{frames_per_shard: 2}}
render: {{backend: osmesa}}
num_workers: 2
"""


def test_scene_job_contract_and_same_bytes_with_one_worker(tmp_path, shared_mocap):
    """A living-room style job through Ray: the new arrays read with plain zarr/pyarrow,
    and the same bytes with 1 and 2 workers."""
    import pyarrow.parquet as pq
    import zarr

    p = tmp_path / "scene.yaml"
    p.write_text(SCENE_JOB.format(m=shared_mocap))
    summary = run_job(JobConfig.load(p), tmp_path / "two.zarr")
    run_job(JobConfig.load(p, num_workers=1), tmp_path / "one.zarr")
    a, b = _store_files(tmp_path / "two.zarr"), _store_files(tmp_path / "one.zarr")
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a)
    assert any("instances" in k for k in a) and any("classes" in k for k in a)
    ma = pq.read_table(tmp_path / "two.zarr" / "manifest.parquet")
    assert ma.equals(pq.read_table(tmp_path / "one.zarr" / "manifest.parquet"))

    g = zarr.open_group(str(tmp_path / "two.zarr"), mode="r")
    names = g.attrs["class_names"]
    lab, inst, cls = g["labels"][:], g["instances"][:], g["classes"][:]
    assert inst.dtype == cls.dtype == np.uint8 and inst.shape == lab.shape
    assert ((lab > 0) == (cls == names.index("person"))).all()
    present = set(np.unique(cls).tolist())
    assert {names.index(c) for c in ("floor", "wall", "person")} <= present
    rows = ma.to_pylist()
    for f, row in enumerate(rows):
        assert row["num_people"] == len(row["people"]) >= 1
        assert set(np.unique(inst[f]).tolist()) <= set(range(row["num_people"] + 1))
        person = row["people"][0]
        assert len(person["joints_px"]) == 2 * 31 and len(person["joints_visible"]) == 31
        assert json.loads(row["scene"])["floor"] is True
        # placements as a reader checks them: footprints apart (people, props)
        discs = [tuple(p["footprint"]) for p in row["people"]] + [
            (q["x"], q["z"], q["radius"]) for q in json.loads(row["scene"])["props"]]
        for i, (x, z, r) in enumerate(discs):
            assert r > 0.1
            for x2, z2, r2 in discs[i + 1:]:
                assert np.hypot(x - x2, z - z2) >= r + r2
    assert max(r["num_people"] for r in rows) > 1
    # the preview adds the instance and class images for scenes
    from PIL import Image

    from vhgen.preview import contact_sheet

    sheet = np.asarray(Image.open(contact_sheet(tmp_path / "two.zarr", tmp_path / "s.png",
                                                num_frames=2)))
    assert sheet.shape[1] >= 4 * 320
    # --joints: each person's 2D joints on the labels tile (x 320 .. 640, from y 14 on
    # the first row at scale 0.5), a dot of the instance colour where visible, a ring
    # (the labels' own colour at the centre) where not
    from vhgen.preview import instance_colors

    plain = np.asarray(Image.open(contact_sheet(tmp_path / "two.zarr", tmp_path / "p.png",
                                                frames=[0])))
    marked = np.asarray(Image.open(contact_sheet(tmp_path / "two.zarr", tmp_path / "j.png",
                                                 frames=[0], joints=True)))
    seen = {True: 0, False: 0}
    for person in rows[0]["people"]:
        color = instance_colors(person["instance"])
        px = np.asarray(person["joints_px"]).reshape(-1, 2)
        for (u, v), vis in zip(px, person["joints_visible"], strict=True):
            if 4 <= u < 636 and 4 <= v < 476:
                x, y = 320 + int((u + 0.5) / 2), 14 + int((v + 0.5) / 2)
                centre_is_dot = (marked[y, x, :3] == color).all()
                assert centre_is_dot == vis or (plain[y, x, :3] == color).all()
                seen[bool(vis)] += 1
    assert seen[True] > 0 and seen[False] > 0
    assert not np.array_equal(plain[:, 320:640], marked[:, 320:640])
    # objects that did not fit are counted, in the summary and per frame
    for k in ("people", "props"):
        assert summary.dropped[k] == sum(json.loads(r["scene"])["dropped"][k] for r in rows)
