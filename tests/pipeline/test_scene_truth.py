"""Pose ground truth of scene frames on real data: 2D joints, visibility, people, props."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_frames import _generator  # same folder (pytest puts it on sys.path)

from vhgen.camera import Intrinsics, project
from vhgen.errors import ConfigError
from vhgen.job_config import JobConfig
from vhgen.scene.geometry import PERSON, PROP
from vhgen.scene.truth import VISIBILITY_TOLERANCE_M, joint_visibility

SCENE = """scene:
  floor: true
  room: {width_m: [4, 6], depth_m: [5.5, 7]}
  people: [2, 3]
  props: {count: [2, 3], occlusion: [0.6, 1.0]}"""


@pytest.fixture(scope="module")
def scene_frames(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("truth")
    cfg, _, plan, gen = _generator(tmp, "kinect_v1_full", SCENE)
    frames = []
    for f in range(0, plan.num_frames, 2):
        desc = gen.describe(f)
        clean = gen.scene.render(desc).camera  # the render before the sensor
        frames.append((desc, clean, gen.render(desc)))
    gen.close()
    return cfg, frames


def test_2d_joints_reproject_the_3d_joints(scene_frames):
    _, frames = scene_frames
    for desc, _, out in frames:
        rec = out.record
        w2c = np.asarray(rec.world_to_camera).reshape(4, 4)
        assert len(rec.people) == rec.num_people == len(desc.people) >= 1
        for person, pr in zip(desc.people, rec.people, strict=True):
            # from the description's world joints, independently of the record code
            cam = person.joints @ w2c[:3, :3].T + w2c[:3, 3]
            np.testing.assert_allclose(np.reshape(pr.joints_cam, (-1, 3)), cam, atol=1e-5)
            uv = np.reshape(pr.joints_px, (-1, 2))
            in_front = cam[:, 2] > 0
            np.testing.assert_allclose(uv[in_front, 0], rec.fx * cam[in_front, 0] /
                                       cam[in_front, 2] + rec.cx, atol=1e-3)
            np.testing.assert_allclose(uv[in_front, 1], rec.fy * cam[in_front, 1] /
                                       cam[in_front, 2] + rec.cy, atol=1e-3)
            assert pr.instance == person.instance
        # person 1 is the frame's own columns
        assert rec.people[0].joints_cam == rec.joints_cam
        assert rec.people[0].motion_file == rec.motion_file


def test_visibility_agrees_with_the_depth_buffer(scene_frames):
    cfg, frames = scene_frames
    intr = cfg.sensor.intrinsics
    seen = hidden = 0
    for desc, clean, out in frames:
        for pr in out.record.people:
            cam = np.reshape(pr.joints_cam, (-1, 3)).astype(np.float64)
            uv = np.rint(np.reshape(pr.joints_px, (-1, 2))).astype(int)
            for j, vis in enumerate(pr.joints_visible):
                u, v = uv[j]
                inside = 0 <= u < intr.width and 0 <= v < intr.height and cam[j, 2] > 0
                if not inside:
                    assert not vis
                    continue
                mine = clean.instances[v, u] == pr.instance
                front = clean.depth[v, u] >= cam[j, 2] - VISIBILITY_TOLERANCE_M - 1e-4
                assert vis == (mine and front), (desc.frame, pr.instance, j)
                seen += vis
                hidden += not vis
            assert pr.visible_fraction == pytest.approx(np.mean(pr.joints_visible))
    assert seen > 0 and hidden > 0  # both cases occur in these frames


def test_joint_visibility_synthetic():
    intr = Intrinsics(8, 6, 10.0, 10.0, 3.5, 2.5)
    depth = np.full((6, 8), 2.0, np.float32)
    inst = np.ones((6, 8), np.uint8)
    depth[:, 4:] = 1.0  # something nearer on the right half...
    inst[:, 4:] = 2  # ...that is person 2
    pts = np.array([[-0.1, 0.0, 2.1],  # behind its own surface by 0.1 m: visible
                    [-0.1, 0.0, 2.3],  # 0.3 m behind (own arm in front): hidden
                    [0.1, 0.0, 2.1],  # behind person 2: hidden
                    [5.0, 0.0, 2.0],  # outside the image
                    [0.0, 0.0, -1.0]])  # behind the camera
    assert joint_visibility(intr, pts, 1, depth, inst).tolist() == [True, False, False,
                                                                    False, False]
    assert np.isnan(project(intr, pts)[4]).all()


def test_scene_frames_have_props_people_and_occlusion(scene_frames):
    _, frames = scene_frames
    multi = occluded = 0
    for desc, clean, out in frames:
        assert ((out.labels > 0) == (out.classes == PERSON)).all()
        k = len(desc.people)
        assert set(np.unique(out.instances).tolist()) <= set(range(k + 1))
        scene = json.loads(out.record.scene)
        assert len(scene["props"]) == len(desc.props)
        multi += k > 1
        occluded += any(p.occluder for p in desc.props) and (clean.classes == PROP).any()
    assert multi > len(frames) // 2 and occluded > 0


def _cfg(tmp_path, props: str):
    p = tmp_path / "job.yaml"
    p.write_text(f"name: t\nmotions: [builtin:demo]\nscene: {{floor: true, props: {props}}}\n")
    return p


def test_prop_mesh_files(tmp_path):
    import trimesh

    trimesh.creation.icosphere(radius=0.3).export(tmp_path / "ball.obj")
    cfg = JobConfig.load(_cfg(tmp_path, "{meshes: [ball.obj, {path: ball.obj, scale: 2}]}"))
    assert cfg.scene.props is not None
    a, b = cfg.scene.props.meshes
    assert a.radius == pytest.approx(0.3, abs=0.01) and b.radius == pytest.approx(0.6, abs=0.02)
    assert a.vertices[:, 1].min() == 0.0
    with pytest.raises(ConfigError, match=r"scene\.props\.meshes\[0\]\.path.*does not exist"):
        JobConfig.load(_cfg(tmp_path, "{meshes: [nothere.obj]}"))
    (tmp_path / "junk.ply").write_bytes(b"ply\nthis is not a mesh\n")
    with pytest.raises(ConfigError, match=r"scene\.props\.meshes\[0\]\.path"):
        JobConfig.load(_cfg(tmp_path, "{meshes: [junk.ply]}"))
    with pytest.raises(ConfigError, match=r"scene\.props\.kinds"):
        JobConfig.load(_cfg(tmp_path, "{kinds: [piano]}"))
    with pytest.raises(ConfigError, match=r"scene\.props\.occlusion"):
        JobConfig.load(_cfg(tmp_path, "{occlusion: [0.5, 2]}"))


def test_room_too_small_for_the_people_and_props(tmp_path):
    p = tmp_path / "job.yaml"
    p.write_text("name: t\nmotions: [builtin:demo]\ncamera: {distance_m: 2.5}\n"
                 "scene: {room: {width_m: 1.5, depth_m: 5}, people: [1, 6], "
                 "props: {count: 8}}\n")
    with pytest.raises(ConfigError, match=r"scene\.room: room too small for 6 people"):
        JobConfig.load(p)
