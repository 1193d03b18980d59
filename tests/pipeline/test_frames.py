"""The one frame path on real data (the builtin demo motion, the real MakeHuman body)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vhgen.body.skinning import skin_vertices
from vhgen.camera import backproject
from vhgen.job_config import JobConfig
from vhgen.scene.geometry import FLOOR, PERSON, WALL

JOB = """
name: t
seed: 5
motions: [builtin:demo]
sensor: {sensor}
poses: {{frame_step: 40}}
avatars: {{count: 2}}
render: {{backend: osmesa}}
{scene}
"""


def _generator(tmp: Path, sensor: str, scene: str = ""):
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job

    p = tmp / f"{sensor}.yaml"
    p.write_text(JOB.format(sensor=sensor, scene=scene))
    cfg = JobConfig.load(p)
    job = prepare_job(cfg)
    return cfg, job.poses, job.plan, FrameGenerator(job)


def _old_path(gen, cfg, poses, plan, frame):
    """The per-frame code vhgen had before scenes (one stream: camera draws, then the
    sensor), written out again here: person-only frames must stay byte-identical to it."""
    from vhgen.body.skinning import bone_matrices
    from vhgen.camera import sample_camera
    from vhgen.render.renderer import DepthLabelRenderer
    from vhgen.sensor.simulator import SensorModel

    a, pose = int(plan.avatar_id[frame]), int(plan.pose_index[frame])
    rng = np.random.default_rng(int(plan.seeds[frame]))
    body = gen.describer.body(a)
    root = poses.roots[pose] * (body.hip_drop / gen.describer._base_hip_drop)
    root = root + np.array([-root[0], 0.0, -root[2]])
    mats = bone_matrices(body.rig, poses.rotations[pose], root)
    w2c = sample_camera(rng, cfg.camera).world_to_camera
    s = cfg.sensor
    ren = DepthLabelRenderer(gen.ctx, s.intrinsics, near=cfg.camera.near_m,
                             far=cfg.camera.far_m, incidence="incidence" in s.needs)
    ren.set_mesh(body.vertices, body.faces, body.joints, body.weights, body.face_labels,
                 body.num_bones)
    depth, labels = ren.render(w2c @ mats)
    incidence = ren.incidence
    proj = None
    if "projector_depth" in s.needs:
        w2p = w2c.copy()
        w2p[0, 3] -= s.baseline_m
        proj, _ = ren.render(w2p @ mats)
    ren.release()
    out = SensorModel(s).simulate(depth, rng, labels=labels, incidence=incidence,
                                  projector_depth=proj)
    return out.depth_mm, out.labels if out.labels is not None else labels


@pytest.mark.parametrize("sensor", ["kinect_v1_full", "kinect_v1_exact_shadows"])
def test_person_only_frames_are_byte_identical_to_the_old_path(tmp_path, sensor):
    cfg, poses, plan, gen = _generator(tmp_path, sensor)
    for f in (0, plan.num_frames - 1):
        o = gen.render_frame(f)
        d_old, l_old = _old_path(gen, cfg, poses, plan, f)
        assert o.depth_mm.dtype == np.uint16 and o.labels.dtype == np.uint8
        assert np.array_equal(o.depth_mm, d_old) and np.array_equal(o.labels, l_old)
        # one person, no geometry: instance 1 and class person exactly where the labels are
        assert ((o.instances == 1) == (o.labels > 0)).all()
        assert ((o.classes == PERSON) == (o.labels > 0)).all()
        assert o.record.num_people == 1 and json.loads(o.record.scene) is None
        assert o.record.body_pixels == int((o.labels > 0).sum()) > 3000
    gen.close()


def test_room_frame_on_real_data(tmp_path):
    """Floor + walls with the ideal sensor: floor pixels back-project onto y = 0, the
    person stands on it, walls are farther than the person, labels only on the person."""
    cfg, _, plan, gen = _generator(tmp_path, "ideal", "scene: {floor: true, room: {}}")
    intr = cfg.sensor.intrinsics
    for f in range(plan.num_frames):
        o = gen.render_frame(f)
        assert {FLOOR, WALL, PERSON} <= set(np.unique(o.classes).tolist()), f
        assert ((o.labels > 0) == (o.classes == PERSON)).all()
        assert ((o.instances == 1) == (o.classes == PERSON)).all()
        assert o.record.body_pixels > 3000
        w2c = np.asarray(o.record.world_to_camera).reshape(4, 4)
        c2w = np.linalg.inv(w2c)
        pts = backproject(intr, o.depth_mm / 1000.0)
        world = pts @ c2w[:3, :3].T + c2w[:3, 3]
        floor = (o.classes == FLOOR) & (o.depth_mm > 0)
        assert floor.sum() > 2000
        assert np.abs(world[floor][:, 1]).max() < 0.02  # mm depth quantisation, ~4 m away
        person = (o.classes == PERSON) & (o.depth_mm > 0)
        # feet on the floor: the lowest skinned vertex is on y = 0 (the demo never
        # jumps), the lowest visible person point a few cm above it (soles face down)
        p = gen.describe(f).people[0]
        b = gen.describer.body(p.avatar_id)
        lowest = skin_vertices(b.vertices, b.joints, b.weights, p.bones)[:, 1].min()
        assert abs(lowest) < 1e-9
        assert -0.02 < world[person][:, 1].min() < 0.08
        scene = json.loads(o.record.scene)
        assert scene["floor"] is True and len(scene["room"]["corners_xz"]) == 4
        wall = (o.classes == WALL) & (o.depth_mm > 0)
        assert np.median(o.depth_mm[wall]) > np.median(o.depth_mm[person])
    gen.close()


def test_scene_options_do_not_shift_the_camera_or_the_noise(tmp_path):
    """The room comes from its own stream: the same seed gives the same camera and the
    same person pixels where nothing of the room is in front of them."""
    _, _, _, g0 = _generator(tmp_path, "kinect_v1_full")
    (tmp_path / "r").mkdir()
    _, _, _, g1 = _generator(tmp_path / "r", "kinect_v1_full", "scene: {room: {}}")
    a, b = g0.describe(0), g1.describe(0)
    assert np.array_equal(a.camera.world_to_camera, b.camera.world_to_camera)
    assert a.noise_state == b.noise_state and b.room is not None
    g0.close()
    g1.close()


def test_shadows_land_on_walls_and_holes_keep_their_class(tmp_path):
    """The sensor runs on the whole scene: projector shadows fall on the wall and floor
    behind people, and a hole keeps the class (and instance) of the surface behind it."""
    _, _, plan, gen = _generator(tmp_path, "kinect_v1_exact_shadows",
                                 "scene: {floor: true, room: {depth_m: [4.5, 5]}}")
    shadow_on_scene = 0
    for f in range(0, plan.num_frames, 3):
        o = gen.render(gen.describe(f))
        holes = o.depth_mm == 0
        assert (o.classes[holes] != 0).mean() > 0.9  # a room: holes are on surfaces
        # the three id images moved together with the pixels
        assert ((o.labels > 0) == (o.classes == PERSON)).all()
        assert ((o.instances > 0) == (o.classes == PERSON)).all()
        shadow_on_scene += json.loads(o.record.holes)["shadow"]
        # shadow holes sit beside people on the wall/floor: some holes not on a person
        assert (holes & ((o.classes == WALL) | (o.classes == FLOOR))).any()
    assert shadow_on_scene > 0
    gen.close()
