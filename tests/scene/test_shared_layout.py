"""Frames sharing a layout (``scene.layout_frames``): consecutive frames keep the camera,
room, props and clutter while the people change; nothing intersects and every person
stays in view over many seeds; any frame is made again alone, by any worker; the render
step keeps a shared layout on the GPU and draws what it would draw afresh; bad values are
one error naming the field."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from test_clutter import _people_visible, _things

from vhgen.errors import ConfigError
from vhgen.job_config import JobConfig
from vhgen.scene.solids import separated

SHARED = 4  # frames a layout
SCENE = f"""
name: shared_test
seed: 5
motions: [builtin:demo]
avatars: {{count: 3}}
poses: {{frame_step: 20}}
camera: {{preset: tv_top_kinect, distance_m: [1.6, 2.8]}}
scene:
  floor: true
  room: {{width_m: [3, 5], depth_m: [3.5, 5.5]}}
  people: [1, 3]
  props: {{count: [1, 2], occlusion: [0.5, 1.0]}}
  clutter: {{count: [8, 12], variants: 8}}
  layout_frames: {SHARED}
"""


@pytest.fixture(scope="module")
def describer(tmp_path_factory, asset_dir):
    """A describer of 96 frames (24 layouts) with seeds of their own."""
    from vhgen.pipeline.describe import FrameDescriber
    from vhgen.pipeline.job import prepare_job
    from vhgen.pipeline.plan import frame_seed

    p = tmp_path_factory.mktemp("shared") / "scene.yaml"
    p.write_text(SCENE)
    job = prepare_job(JobConfig.load(p), asset_dir=asset_dir)
    n = 96
    plan = replace(job.plan, num_frames=n, avatar_id=np.arange(n) % 3,
                   pose_index=(7 * np.arange(n)) % job.poses.num_poses,
                   seeds=np.array([frame_seed(21, 0, k) for k in range(n)], np.uint64))
    return FrameDescriber(replace(job, plan=plan))


def test_frames_of_a_layout_share_camera_room_props_and_clutter(describer):
    from vhgen.scene.layout import SLOT_M

    descs, firsts, narrow = [], [], 0
    for f in range(describer.job.plan.num_frames):
        desc = describer.describe(f)
        shared = describer.shared_layout(f // SHARED)  # the one the frame was made from
        assert desc.layout == f // SHARED
        # the same objects, not equal copies: the render step keeps them on the GPU
        assert desc.camera is shared.camera and desc.room is shared.layout.room
        if desc.people[0].footprint.r <= SLOT_M:  # fits its slot: leaves nothing out
            narrow += 1
            firsts.append(desc.people[0].bones[0, :3, 3])  # at a spot of its own in the slot
            assert desc.static is shared.layout.static
            assert desc.clutter is shared.layout.clutter and desc.props is shared.layout.props
        else:  # wider: what its footprint touches is left out, the rest is the layout's
            assert set(desc.clutter) <= set(shared.layout.clutter)
            assert set(desc.props) <= set(shared.layout.props)
            assert desc.static[:shared.room_meshes] == shared.layout.static[:shared.room_meshes]
        descs.append(desc)
    assert narrow >= len(descs) // 2
    # layouts differ from one another; people differ from frame to frame
    rooms = {tuple(np.round(d.room.corners_xz.ravel(), 6)) for d in descs}
    assert len(rooms) == len(descs) // SHARED
    assert len({tuple(np.round(x, 6)) for x in firsts}) == narrow
    counts = np.bincount([len(d.people) for d in descs], minlength=4)
    assert counts[1] > 0 and counts[2] > 0 and counts[3] > 0  # people: [1, 3] per frame


def test_nothing_intersects_and_people_stay_in_view(describer):
    """The clutter test's checks on every frame: people (skinned), props and clutter
    (rebuilt from the manifest records) apart, inside the room; every person keeps
    min_visible_fraction of its width in view; the people asked for are there or
    counted."""
    placed = asked = 0
    for f in range(describer.job.plan.num_frames):
        desc = describer.describe(f)
        things = _things(describer, desc)
        for i in range(len(things)):
            for j in range(i):
                a, b = things[i], things[j]
                if a[0] == b[0] or a[2] >= b[3] or b[2] >= a[3]:
                    continue
                assert separated(a[1][None], b[1], 0.0)[0], (f, a[0], b[0])
        _people_visible(describer, desc)
        placed += len(desc.people)
        asked += len(desc.people) + desc.dropped["people"]
    assert placed >= 0.9 * asked


def test_any_frame_is_made_again_alone(describer):
    """A frame described by a fresh describer (a worker whose shard starts there) is the
    frame described after its neighbours."""
    from vhgen.pipeline.describe import FrameDescriber

    for f in (1, 6, 11, 95):
        alone = FrameDescriber(describer.job).describe(f)
        after = describer.describe(f)
        assert np.array_equal(alone.camera.world_to_camera, after.camera.world_to_camera)
        assert len(alone.people) == len(after.people)
        for p, q in zip(alone.people, after.people, strict=True):
            assert (p.avatar_id, p.pose_index) == (q.avatar_id, q.pose_index)
            assert np.array_equal(p.bones, q.bones)
        assert len(alone.static) == len(after.static)
        for m, n in zip(alone.static, after.static, strict=True):
            assert np.array_equal(m.vertices, n.vertices)
        assert alone.noise_state == after.noise_state


def test_render_keeps_a_shared_layout_and_draws_it_as_afresh(tmp_path, asset_dir):
    """Frames of one layout draw the static geometry written once; each is what a fresh
    generator draws for that frame alone."""
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job

    p = tmp_path / "s.yaml"
    p.write_text(SCENE.replace("motions:", "render: {backend: osmesa}\nmotions:"))
    job = prepare_job(JobConfig.load(p), asset_dir=asset_dir)
    gen = FrameGenerator(job)
    writes = []
    write = gen.scene.renderer.write_static
    gen.scene.renderer.write_static = lambda *a, **k: writes.append(1) or write(*a, **k)
    try:
        outs = [gen.render(gen.describe(f)) for f in range(SHARED + 2)]
    finally:
        gen.close()
    assert len(writes) < SHARED + 2  # written once a layout, unless a frame left clutter out
    for f in (SHARED - 1, SHARED + 1):
        fresh = FrameGenerator(job)
        try:
            alone = fresh.render(fresh.describe(f))
        finally:
            fresh.close()
        assert np.array_equal(alone.depth_mm, outs[f].depth_mm)
        assert np.array_equal(alone.classes, outs[f].classes)


def test_job_with_shared_layouts_same_bytes_with_one_and_two_workers(tmp_path):
    """Layouts of 3 frames over shards of 2: workers make the frames of a layout in
    different shards, and the store is the one a single worker writes; the manifest
    names each frame's layout."""
    import pyarrow.parquet as pq
    from test_clutter_render import _files

    from vhgen.pipeline.driver import run_job

    p = tmp_path / "job.yaml"
    p.write_text(SCENE.replace(f"layout_frames: {SHARED}", "layout_frames: 3")
                 + "output: {frames_per_shard: 2}\nrender: {backend: osmesa}\nnum_workers: 2\n")
    run_job(JobConfig.load(p), tmp_path / "two.zarr", max_frames=8, executor="local")
    run_job(JobConfig.load(p, num_workers=1), tmp_path / "one.zarr", max_frames=8,
            executor="local")
    a, b = _files(tmp_path / "two.zarr"), _files(tmp_path / "one.zarr")
    assert a.keys() == b.keys() and len(a) >= 16 and all(a[k] == b[k] for k in a)
    rows = pq.read_table(tmp_path / "two.zarr" / "manifest.parquet").to_pylist()
    assert [json.loads(r["scene"])["layout"] for r in rows] == [f // 3 for f in range(8)]
    rooms = [json.dumps(json.loads(r["scene"])["room"]) for r in rows]
    assert rooms[0] == rooms[1] == rooms[2] != rooms[3]


@pytest.mark.parametrize("value, needs", [
    ("0", "outside"), ("2.5", "integer"), ("true", "integer"),
])
def test_bad_layout_frames_is_one_error(tmp_path, value, needs):
    p = tmp_path / "bad.yaml"
    p.write_text(SCENE.replace(f"layout_frames: {SHARED}", f"layout_frames: {value}"))
    with pytest.raises(ConfigError, match=rf"scene\.layout_frames.*{needs}"):
        JobConfig.load(p)


def test_layout_frames_needs_a_room_or_props(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("name: x\nmotions: [builtin:demo]\nscene: {floor: true, layout_frames: 4}\n")
    with pytest.raises(ConfigError, match=r"scene\.layout_frames.*scene\.room or scene\.props"):
        JobConfig.load(p)
    bg = tmp_path / "room.png"  # the parser only asks that it exists
    bg.write_bytes(b"")
    p.write_text(f"name: x\nmotions: [builtin:demo]\nscene: {{backgrounds: [{bg}], "
                 f"layout_frames: 4}}\n")
    with pytest.raises(ConfigError, match=r"scene\.layout_frames.*scene\.backgrounds"):
        JobConfig.load(p)
