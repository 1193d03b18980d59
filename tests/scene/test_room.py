"""Room sampling (pure): the person and the camera are always inside, with clearance."""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.errors import ConfigError
from vhgen.job_config import JobConfig
from vhgen.scene.geometry import FLOOR, WALL
from vhgen.scene.room import sample_room, static_geometry
from vhgen.scene.scene_config import CAMERA_CLEARANCE_M, PERSON_CLEARANCE_M, RoomConfig, SceneConfig


def _inside(corners: np.ndarray, p: np.ndarray) -> float:
    """Signed distance from p to the nearest edge of a convex polygon (> 0 inside)."""
    d = np.inf
    area = 0.0
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        area += a[0] * b[1] - a[1] * b[0]
    sign = 1.0 if area > 0 else -1.0
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        e = b - a
        cross = e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])
        d = min(d, sign * cross / np.hypot(*e))
    return d


def test_person_and_camera_always_inside_over_seeds():
    cfg = RoomConfig(width_m=(2.0, 6.0), depth_m=(3.0, 6.0), yaw_deg=(-40, 40))
    for seed in range(3000):
        rng = np.random.default_rng(seed)
        yaw = rng.uniform(-180, 180)
        behind = 1.5 * (seed % 2)  # room for more people beyond the first
        dist = rng.uniform(1.0, 4.5 - behind)
        a = np.deg2rad(yaw)
        eye = np.array([dist * np.sin(a), dist * np.cos(a)])
        room = sample_room(rng, cfg, eye, yaw, behind)
        c = room.corners_xz
        assert _inside(c, np.zeros(2)) >= PERSON_CLEARANCE_M - 1e-9, seed
        assert _inside(c, -eye / dist * behind) >= PERSON_CLEARANCE_M - 1e-9, seed
        assert _inside(c, eye) >= CAMERA_CLEARANCE_M - 1e-9, seed
        assert cfg.width_m[0] - 1e-9 <= room.width_m <= cfg.width_m[1] + 1e-9
        assert cfg.depth_m[0] - 1e-9 <= room.depth_m <= cfg.depth_m[1] + 1e-9
        # a rectangle: opposite sides equal, right angles
        e = np.diff(np.vstack([c, c[:1]]), axis=0)
        assert abs(e[0] @ e[1]) < 1e-9 and np.allclose(e[0], -e[2]) and np.allclose(e[1], -e[3])


def test_static_geometry_classes():
    rng = np.random.default_rng(0)
    room = sample_room(rng, RoomConfig(), np.array([0.0, 3.0]), 0.0)
    meshes = static_geometry(SceneConfig(floor=True, room=RoomConfig()), room)
    assert [m.name for m in meshes] == ["floor", "walls"]
    assert set(meshes[0].face_classes) == {FLOOR} and set(meshes[1].face_classes) == {WALL}
    assert np.allclose(meshes[0].vertices[:, 1], 0.0)  # the floor is y = 0
    assert meshes[1].vertices[:, 1].max() == pytest.approx(room.height_m)
    assert static_geometry(SceneConfig(), None) == ()
    (open_floor,) = static_geometry(SceneConfig(floor=True), None)
    assert open_floor.name == "floor"


def _cfg(tmp_path, scene: str):
    p = tmp_path / "job.yaml"
    p.write_text(f"name: t\nmotions: [builtin:demo]\ncamera: {{distance_m: [2, 3.5]}}\n"
                 f"scene: {scene}\n")
    return p


def test_scene_config_errors_name_the_field(tmp_path):
    with pytest.raises(ConfigError, match=r"scene\.room\.depth_m.*room too small"):
        JobConfig.load(_cfg(tmp_path, "{room: {depth_m: [2, 3]}}"))
    with pytest.raises(ConfigError, match=r"scene\.room\.width_m.*room too small"):
        JobConfig.load(_cfg(tmp_path, "{room: {width_m: 1.0}}"))
    with pytest.raises(ConfigError, match=r"scene\.floor"):
        JobConfig.load(_cfg(tmp_path, "{floor: yes please}"))
    with pytest.raises(ConfigError, match=r"scene\.room\.colour"):
        JobConfig.load(_cfg(tmp_path, "{room: {colour: red}}"))
    cfg = JobConfig.load(_cfg(tmp_path, "{floor: true, room: {depth_m: [4, 6]}}"))
    assert cfg.scene.floor and cfg.scene.room is not None
    assert cfg.scene.room.depth_m == (4.0, 6.0)
