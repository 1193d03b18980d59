"""Scene classes of the user's own: declared on prop entries, listed in the store's
``class_names`` after the built-in five, written exactly where those props are seen."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vhgen.errors import ConfigError
from vhgen.job_config import JobConfig
from vhgen.scene.geometry import PROP, SCENE_CLASSES

BASE = """
name: classes
seed: 5
motions: [{m}/02_01.bvh]
sensor: kinect_v1_full
poses: {{frame_step: 100, skip_first: 1, max_per_motion: 4}}
avatars: {{count: 1}}
scene:
  floor: true
  room: {{width_m: [5, 6], depth_m: [6, 7]}}
  props:
    count: [3, 4]
    occlusion: [1, 1]
{props}
output: {{frames_per_shard: 2}}
render: {{backend: osmesa}}
num_workers: 1
"""
WITH_CLASSES = """    kinds: [{kind: box, class: crate}, table, {kind: sofa, class: crate}]
    meshes: [{path: lamp.obj, scale: 1.0, class: lamp}]"""
WITHOUT = """    kinds: [box, table, sofa]
    meshes: [{path: lamp.obj, scale: 1.0}]"""


def _write(tmp: Path, shared: Path, props: str, name: str) -> Path:
    import trimesh

    if not (tmp / "lamp.obj").is_file():
        trimesh.creation.cylinder(radius=0.25, height=1.0, sections=12).export(tmp / "lamp.obj")
    p = tmp / name
    p.write_text(BASE.format(m=shared, props=props))
    return p


def test_class_names_order_and_ids(tmp_path, shared_mocap):
    cfg = JobConfig.load(_write(tmp_path, shared_mocap, WITH_CLASSES, "a.yaml"))
    sc = cfg.scene
    assert sc.class_names == (*SCENE_CLASSES, "crate", "lamp")
    assert sc.props is not None
    assert sc.props.kind_classes == ("crate", "prop", "crate")
    assert [sc.class_id(c) for c in ("prop", "crate", "lamp")] == [PROP, 5, 6]
    plain = JobConfig.load(_write(tmp_path, shared_mocap, WITHOUT, "b.yaml"))
    assert plain.scene.class_names == SCENE_CLASSES


@pytest.mark.parametrize("props, field, match", [
    ("    kinds: [{kind: box, class: wall}]", "scene.props.kinds[0].class", "built-in"),
    ("    kinds: [box, {kind: box, class: person}]", "scene.props.kinds[1].class", "built-in"),
    ("    kinds: [{kind: box, class: 3d-box}]", "scene.props.kinds[0].class", "a name"),
    ("    kinds: [{kind: box, class: [a]}]", "scene.props.kinds[0].class", "a name"),
    ("    kinds: [{kind: crate, class: crate}]", "scene.props.kinds[0].kind", "one of"),
    ("    kinds: [{class: crate}]", "scene.props.kinds[0].kind", "missing"),
    ("    kinds: [{kind: box, klass: crate}]", "scene.props.kinds[0].klass", "unknown"),
    ("    kinds: []\n    meshes: [{path: lamp.obj, class: floor}]",
     "scene.props.meshes[0].class", "built-in"),
    ("    kinds: [" + ", ".join(f"{{kind: box, class: c{i}}}" for i in range(252)) + "]",
     "scene.props", "252 user classes"),
])
def test_bad_user_class_is_one_line_naming_the_field(tmp_path, shared_mocap, props, field,
                                                     match):
    with pytest.raises(ConfigError, match=match) as e:
        JobConfig.load(_write(tmp_path, shared_mocap, props, "bad.yaml"))
    assert e.value.field == field and "\n" not in str(e.value)


def test_251_user_classes_fit_uint8(tmp_path, shared_mocap):
    props = "    kinds: [" + ", ".join(f"{{kind: box, class: c{i}}}" for i in range(251)) + "]"
    names = JobConfig.load(_write(tmp_path, shared_mocap, props, "ok.yaml")).scene.class_names
    assert len(names) == 256 and names[255] == "c250"


@pytest.mark.slow
def test_user_class_ids_exactly_where_those_props_are_seen(tmp_path, shared_mocap):
    """The same job with and without ``class`` keys: the same frames (depth, labels,
    instances) and the same classes except on prop pixels, which hold the class of the
    prop seen there; read back with plain zarr and pyarrow."""
    import pyarrow.parquet as pq
    import zarr

    from vhgen.pipeline.driver import run_job

    run_job(JobConfig.load(_write(tmp_path, shared_mocap, WITH_CLASSES, "a.yaml")),
            tmp_path / "a.zarr")
    run_job(JobConfig.load(_write(tmp_path, shared_mocap, WITHOUT, "b.yaml")),
            tmp_path / "b.zarr")
    a = zarr.open_group(str(tmp_path / "a.zarr"), mode="r")
    b = zarr.open_group(str(tmp_path / "b.zarr"), mode="r")
    assert a.attrs["class_names"] == [*SCENE_CLASSES, "crate", "lamp"]
    assert b.attrs["class_names"] == list(SCENE_CLASSES)
    for k in ("depth", "labels", "instances"):
        np.testing.assert_array_equal(a[k][:], b[k][:])
    ca, cb = a["classes"][:], b["classes"][:]
    assert ca.dtype == np.uint8
    np.testing.assert_array_equal(ca[cb != PROP], cb[cb != PROP])
    rows = pq.read_table(tmp_path / "a.zarr" / "manifest.parquet").to_pylist()
    crate, lamp = 5, 6
    seen = set()
    for f, row in enumerate(rows):
        props = json.loads(row["scene"])["props"]
        declared = {p.get("class", "prop") for p in props}
        on_props = ca[f][cb[f] == PROP]
        ids = set(np.unique(on_props).tolist())
        # every prop pixel holds the id of a class of a prop of that frame, and only those
        assert ids <= {a.attrs["class_names"].index(c) for c in declared}
        if declared == {"lamp"}:  # one class in the frame: all its prop pixels are it
            assert (on_props == lamp).all()
        seen |= ids
        assert not np.isin(cb[f], [crate, lamp]).any()
    assert {crate, lamp} <= seen and PROP in seen  # the table stays a plain prop
    # the tools read the names from the attribute
    import vhgen.dataset
    from vhgen.cli import main
    from vhgen.store.inspect import inspect_store

    assert inspect_store(tmp_path / "a.zarr").defects == []
    assert main(["inspect", str(tmp_path / "a.zarr")]) == 0
    ds = vhgen.dataset.open(tmp_path / "a.zarr")
    np.testing.assert_array_equal(ds[len(ds) - 1]["classes"], ca[len(ds) - 1])


def test_preview_gives_every_declared_class_its_own_colour():
    from vhgen.preview import CLASS_COLORS, class_palette

    pal = class_palette(256)
    assert pal.shape == (256, 3) and pal.dtype == np.uint8
    np.testing.assert_array_equal(pal[:len(CLASS_COLORS)], CLASS_COLORS)
    assert len({tuple(c) for c in pal[:40]}) == 40  # user classes distinct from each other
    assert class_palette(3).shape == (len(CLASS_COLORS), 3)
