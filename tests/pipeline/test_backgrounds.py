"""People composited into a real background, checked against a "real" frame made by vhgen
itself with a known floor: a room (floor, walls, a table nearer the camera than the free
floor behind it) rendered by vhgen's renderer at a known camera height, pitch and roll,
sensed once by ``openni_525`` and written as an OpenNI-style PCD.

Checked: the floor found is the known one; people stand on it and never inside the table;
the table hides them exactly (a person's pixel is kept exactly where its rendered depth is
nearer than the real depth); joints behind the table are not visible; real pixels out of
the people's reach are the real frame's bytes, and people cast shadows on real ones; the
same bytes with 1 and 2 workers.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vhgen.body.skin_kernels import skin_points
from vhgen.camera import mounted_camera
from vhgen.job_config import JobConfig
from vhgen.scene.geometry import floor_mesh, room_walls
from vhgen.scene.truth import VISIBILITY_TOLERANCE_M
from vhgen.sensor.composite import reach_px, real_depth_m

EYE = np.array([0.2, 1.3, 3.6])
PITCH, ROLL = 14.0, 1.5
# a table across the view, nearer the camera than the free floor behind it: its top's x,
# y, z extents (y from the floor) and four legs; the camera sees the floor under the top
# and behind it (1.6-3.6 m away), so people stand there with the table top before their
# legs
TABLE = ((-1.0, 0.72, 1.2), (1.0, 0.76, 2.0))
LEG_M = 0.05
JOB = """
name: bg
seed: 11
motions: [builtin:demo]
sensor: openni_525
poses: {{frame_step: 8}}
avatars: {{count: 3}}
camera: {{distance_m: [1.9, 4.2]}}
scene:
  backgrounds: [{bg}]
  people: [1, 3]
  min_visible_fraction: 0.3
output: {{frames_per_shard: 4, arrays: [depth, labels, instances, classes, raw]}}
render: {{backend: osmesa}}
num_workers: {workers}
"""


def _box(lo, hi):
    import trimesh

    b = trimesh.creation.box(bounds=np.array([lo, hi], np.float64))
    return np.asarray(b.vertices, np.float64), np.asarray(b.faces, np.int64)


def _make_background(path: Path) -> np.ndarray:
    """The synthetic room through vhgen's renderer and sensor -> a PCD at ``path``;
    returns the true world_to_camera (y = 0 is the floor)."""
    from vhgen.depthfile import write_pcd
    from vhgen.render.context import create_context
    from vhgen.render.renderer import DepthLabelRenderer, Draw
    from vhgen.render.scene_renderer import merge_static
    from vhgen.scene.geometry import PROP, StaticMesh
    from vhgen.sensor.sensor_config import SensorConfig
    from vhgen.sensor.simulator import SensorModel

    sensor = SensorConfig.load("openni_525")
    ctx = create_context("osmesa")
    r = DepthLabelRenderer(ctx, sensor.intrinsics, incidence=True)
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    r.upload(tri, [[0, 1, 2]], np.zeros((3, 4), int), np.tile([1.0, 0, 0, 0], (3, 1)),
             [1], 1)  # fixes the rig size; never drawn
    corners = np.array([[-3.0, -3.0], [3.0, -3.0], [3.0, 4.5], [-3.0, 4.5]])
    (x0, y0, z0), (x1, _, z1) = TABLE
    parts = [TABLE] + [((x, 0.0, z), (x + LEG_M, y0, z + LEG_M))
                       for x in (x0, x1 - LEG_M) for z in (z0, z1 - LEG_M)]
    meshes = [floor_mesh((-3.0, 3.0), (-3.0, 4.5)), room_walls(corners, 2.7)]
    for lo, hi in parts:
        tv, tf = _box(lo, hi)
        meshes.append(StaticMesh("table", tv, tf, np.full(len(tf), PROP, np.uint8)))
    w2c = mounted_camera(EYE, PITCH, ROLL)
    view = r.draw([Draw(r.write_static(*merge_static(meshes)), w2c)])
    out = SensorModel(sensor).simulate(view.depth, np.random.default_rng(3),
                                       incidence=view.incidence)
    r.release()
    ctx.release()
    write_pcd(path, out.depth_mm, sensor.intrinsics)
    return w2c


@pytest.fixture(scope="module")
def composited(tmp_path_factory, asset_dir):
    """The job, its generator, the true camera, and per frame: the description, the
    composite before the sensor, the people alone and the output."""
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job
    from vhgen.render.renderer import DepthLabelRenderer
    from vhgen.render.scene_renderer import SceneRenderer

    tmp = tmp_path_factory.mktemp("bg")
    true_w2c = _make_background(tmp / "room.pcd")
    (tmp / "job.yaml").write_text(JOB.format(bg=tmp / "room.pcd", workers=2))
    cfg = JobConfig.load(tmp / "job.yaml")
    job = prepare_job(cfg, asset_dir=asset_dir, max_frames=24)
    gen = FrameGenerator(job)
    # the people alone: a second renderer without the background, same context
    alone = SceneRenderer(DepthLabelRenderer(gen.ctx, cfg.sensor.intrinsics,
                                             skinning=cfg.skinning), gen.describer.body)
    frames = []
    for f in range(job.plan.num_frames):
        desc = gen.describe(f)
        comp = gen.scene.render(desc).camera
        people = alone.render(replace(desc, background=None)).camera
        frames.append((desc, comp, people, gen.render(desc)))
    alone.release()
    alone.renderer.release()
    gen.close()
    return tmp, job, true_w2c, frames


def test_the_floor_is_the_known_one(composited):
    _, job, true_w2c, _ = composited
    floor = job.backgrounds.floors[0]
    angle = math.degrees(math.acos(min(1.0, float(np.dot(floor.normal, true_w2c[:3, 1])))))
    assert angle < 0.5 and abs(floor.height_m - EYE[1]) < 0.015, (angle, floor)


def _true_world(desc, true_w2c) -> np.ndarray:
    """(4, 4): the frame's world (the estimated floor at y = 0) -> the true world."""
    return np.linalg.inv(true_w2c) @ desc.camera.world_to_camera


def test_people_stand_on_the_floor_and_never_in_the_table(composited):
    _, job, true_w2c, frames = composited
    placed = 0
    for desc, _, _, out in frames:
        to_true = _true_world(desc, true_w2c)
        for p in desc.people:
            body = job.avatar_body(p.avatar_id)
            v = skin_points(body.vertices, body.joints, body.weights, p.bones)
            lowest = v[:, 1].min()
            if lowest < 1e-6:  # grounded (a jump stays in the air)
                feet = v[v[:, 1] < lowest + 0.02] @ to_true[:3, :3].T + to_true[:3, 3]
                assert abs(feet[:, 1].min()) < 0.02, (desc.frame, p.instance)
            # the body's floor footprint, in the true world, keeps out of the table
            xz = (v @ to_true[:3, :3].T + to_true[:3, 3])[:, [0, 2]]
            y = (v @ to_true[:3, :3].T + to_true[:3, 3])[:, 1]
            inside = ((xz[:, 0] > TABLE[0][0] + 0.02) & (xz[:, 0] < TABLE[1][0] - 0.02)
                      & (xz[:, 1] > TABLE[0][2] + 0.02) & (xz[:, 1] < TABLE[1][2] - 0.02)
                      & (y < TABLE[1][1]))
            assert not inside.any(), (desc.frame, p.instance)
            placed += 1
        assert out.record.num_people == len(desc.people)
    assert placed >= len(frames)


def test_the_table_hides_people_exactly(composited):
    _, job, _, frames = composited
    real_ids = job.cfg.scene.class_id("real") << 16
    hidden_total = 0
    for desc, comp, people, _ in frames:
        real = real_depth_m(desc.background.depth_mm)
        drawn = people.ids != 0
        kept = drawn & ((real == 0) | (people.depth < real))
        assert ((comp.ids != real_ids) == kept).all(), desc.frame
        assert (comp.ids[kept] == people.ids[kept]).all()
        assert (comp.depth[kept] == people.depth[kept]).all()
        assert (comp.depth[~kept] == real[~kept]).all()
        hidden_total += int((drawn & ~kept & (real > 0)).sum())
    assert hidden_total > 1000  # the table top does hide people


def test_joints_behind_real_surfaces_are_not_visible(composited):
    _, job, _, frames = composited
    intr = job.cfg.sensor.intrinsics
    behind = 0
    for desc, _, _, out in frames:
        real = desc.background.depth_mm / 1000.0
        for pr in out.record.people:
            cam = np.reshape(pr.joints_cam, (-1, 3))
            uv = np.rint(np.reshape(pr.joints_px, (-1, 2))).astype(int)
            for j, vis in enumerate(pr.joints_visible):
                u, v = uv[j]
                if 0 <= u < intr.width and 0 <= v < intr.height and cam[j, 2] > 0:
                    if 0 < real[v, u] < cam[j, 2] - VISIBILITY_TOLERANCE_M:
                        assert not vis
                        behind += 1
    assert behind > 0


def test_real_pixels_keep_their_bytes_out_of_the_peoples_reach(composited):
    _, job, _, frames = composited
    real_class = job.cfg.scene.class_id("real")
    from vhgen.sensor.simulator import SensorModel

    model = SensorModel(job.cfg.sensor)
    shadowed = 0
    far_total = 0.0
    for desc, comp, _, out in frames:
        real_mm = desc.background.depth_mm
        person = comp.classes != real_class
        rows, cols = reach_px(model, float(comp.depth[person].min()))
        ys, xs = np.nonzero(person)  # out of the people's box widened by their reach
        far = np.ones_like(person)
        far[max(ys.min() - rows, 0):ys.max() + rows + 1,
            max(xs.min() - cols, 0):xs.max() + cols + 1] = False
        far_total += far.mean()
        assert (out.depth_mm[far] == real_mm[far]).all(), desc.frame
        assert (out.classes[far] == real_class).all()
        # the people change real pixels near them: shadows and edge holes on the room
        lost = (out.classes == real_class) & (out.depth_mm == 0) & (real_mm > 0)
        assert not (lost & far).any()
        shadowed += int(lost.sum())
        holes = json.loads(out.record.holes)
        assert holes["real"] == int(((out.classes == real_class) & (out.depth_mm == 0)
                                     & (real_mm == 0)).sum())
    assert shadowed > 500
    assert far_total / len(frames) > 0.1  # the test sees real pixels out of reach


def test_manifest_records_the_background(composited):
    tmp, job, _, frames = composited
    for desc, _, _, out in frames:
        scene = json.loads(out.record.scene)
        bg = scene["background"]
        assert bg["file"] == str(tmp / "room.pcd") and bg["index"] == 0
        assert bg["floor"]["height_m"] == job.backgrounds.floors[0].height_m
        assert scene["room"] is None and scene["props"] == []
        for p, pr in zip(desc.people, out.record.people, strict=True):
            assert pr.footprint == [p.footprint.x, p.footprint.z, p.footprint.r]


def test_same_bytes_with_one_and_two_workers(composited):
    import pyarrow.parquet as pq

    from vhgen.pipeline.driver import run_job

    tmp = composited[0]
    stores = []
    for workers in (1, 2):
        (tmp / f"job{workers}.yaml").write_text(JOB.format(bg=tmp / "room.pcd",
                                                           workers=workers))
        out = tmp / f"w{workers}.zarr"
        run_job(JobConfig.load(tmp / f"job{workers}.yaml"), out, max_frames=8,
                executor="local", progress=False)
        stores.append(out)
    a, b = ({str(p.relative_to(s)): p.read_bytes() for p in sorted(s.rglob("*"))
             if p.is_file() and {"depth", "labels", "instances", "classes", "raw"}
             & set(p.parts)} for s in stores)
    assert a.keys() == b.keys() and len(a) >= 8 and all(a[k] == b[k] for k in a)
    ma, mb = (pq.read_table(s / "manifest.parquet") for s in stores)
    assert ma.equals(mb) and ma.num_rows == 8
