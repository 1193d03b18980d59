"""Mounted cameras: presets, pitch and roll, and the load-time check that a person can be
seen."""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.camera import mounted_camera, project, sample_camera
from vhgen.errors import ConfigError
from vhgen.job_config import CAMERA_PRESETS, JobConfig


def _load(tmp_path, camera: str) -> JobConfig:
    p = tmp_path / "job.yaml"
    p.write_text(f"name: t\nmotions: [builtin:demo]\ncamera: {camera}\n")
    return JobConfig.load(p)


def test_mounted_camera_pitch_and_roll():
    eye = np.array([1.0, 1.5, 2.0])
    w2c = mounted_camera(eye, 15.0, 4.0)
    r = w2c[:3, :3]
    assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    assert np.allclose(w2c[:3, :3] @ eye + w2c[:3, 3], 0)  # the eye is the origin
    assert np.degrees(np.arcsin(-w2c[2, 1])) == pytest.approx(15.0)
    assert np.degrees(np.arctan2(w2c[0, 1], -w2c[1, 1])) == pytest.approx(4.0)
    # the optical axis points at the world's y axis (turned towards the subject)
    f = w2c[2, :3]
    assert f[0] * -eye[2] - f[2] * -eye[0] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("preset", sorted(CAMERA_PRESETS))
def test_presets_see_the_subject(tmp_path, preset):
    cfg = _load(tmp_path, f"{{preset: {preset}}}")
    cam = cfg.camera
    assert cam.pitch_deg is not None and cam.pitch_deg == tuple(
        float(x) for x in CAMERA_PRESETS[preset]["pitch_deg"])
    intr = cfg.sensor.intrinsics
    for seed in range(500):
        pose = sample_camera(np.random.default_rng(seed), cam)
        w2c = pose.world_to_camera
        pts = np.array([[0, 0.9, 0], [0, 0.0, 0]]) @ w2c[:3, :3].T + w2c[:3, 3]
        u, v = project(intr, pts)[0]
        assert 0 <= u < intr.width and 0 <= v < intr.height, seed  # body centre in view
        assert pose.pitch_deg is not None
        assert cam.pitch_deg[0] <= pose.pitch_deg <= cam.pitch_deg[1]
    # explicit keys override the preset's
    assert _load(tmp_path, f"{{preset: {preset}, height_m: 1.2}}").camera.height_m == (1.2, 1.2)


def test_camera_errors_name_the_field(tmp_path):
    with pytest.raises(ConfigError, match=r"camera\.pitch_deg.*never see a person"):
        _load(tmp_path, "{height_m: 1.0, distance_m: 3, pitch_deg: [60, 70]}")
    with pytest.raises(ConfigError, match=r"camera\.distance_m.*never see a person"):
        _load(tmp_path, "{distance_m: [30, 40], far_m: 20}")
    with pytest.raises(ConfigError, match=r"camera\.preset.*tv_top_kinect"):
        _load(tmp_path, "{preset: ceiling}")
    with pytest.raises(ConfigError, match=r"camera\.roll_deg.*pitch_deg"):
        _load(tmp_path, "{roll_deg: [-2, 2]}")
