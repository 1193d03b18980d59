"""People side by side (``scene.lineup``): beside the line's ends, facing the camera,
never inside each other, and bad settings refused with the field named."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from vhgen.body.skinning import skin_vertices
from vhgen.errors import ConfigError
from vhgen.job_config import JobConfig
from vhgen.scene.placement import Disc, place_beside
from vhgen.scene.solids import separated

SCENE = """
name: t
seed: 5
motions: [builtin:demo]
avatars: {count: 3}
poses: {frame_step: 20}
camera: {preset: tv_top_kinect, distance_m: [3.5, 4.5]}
scene:
  floor: true
  room: {width_m: [7, 9], depth_m: [7.5, 9]}
  people: [3, 4]
  LINEUP
"""
FACING_DEG = 20.0


def _describer(tmp_path, asset_dir, lineup: str, n: int):
    from vhgen.pipeline.describe import FrameDescriber
    from vhgen.pipeline.job import prepare_job
    from vhgen.pipeline.plan import avatar_params, frame_seed

    p = tmp_path / "scene.yaml"
    p.write_text(SCENE.replace("LINEUP", lineup))
    cfg = JobConfig.load(p)
    job = prepare_job(cfg, asset_dir=asset_dir)
    plan = replace(job.plan, num_frames=n, avatar_id=np.arange(n) % 3,
                   pose_index=np.arange(n) % job.poses.num_poses,
                   seeds=np.array([frame_seed(7, 0, k) for k in range(n)], np.uint64),
                   avatars=[avatar_params(cfg.seed, a, cfg.avatars) for a in range(3)])
    return FrameDescriber(replace(job, plan=plan))


def _facing_error_deg(person, eye_xz: np.ndarray) -> float:
    """How far (degrees) the person's hips face away from the camera on the floor."""
    f = person.bones[0][[0, 2], 2]  # the root's rest +z (the body's front), posed
    to = eye_xz - np.array([person.footprint.x, person.footprint.z])
    a = np.arctan2(f[0], f[1]) - np.arctan2(to[0], to[1])
    return float(np.rad2deg(abs((a + np.pi) % (2 * np.pi) - np.pi)))


def _further_people(d, n: int):
    """(facing errors, gaps to the nearest other person) of every further person, and
    whether any two people's bodies overlap on the floor."""
    errors, gaps, overlaps = [], [], 0
    for f in range(n):
        desc = d.describe(f)
        eye = desc.camera.eye[[0, 2]]
        hulls = []
        for p in desc.people:
            b = d.body(p.avatar_id)
            v = skin_vertices(b.vertices, b.joints, b.weights, p.bones)[:, [0, 2]]
            hulls.append(v[ConvexHull(v).vertices])
        for k, p in enumerate(desc.people[1:], 1):
            errors.append(_facing_error_deg(p, eye))
            gaps.append(min(np.hypot(p.footprint.x - o.footprint.x,
                                     p.footprint.z - o.footprint.z)
                            - p.footprint.r - o.footprint.r
                            for j, o in enumerate(desc.people) if j != k))
        for i in range(len(hulls)):
            for j in range(i):
                overlaps += not separated(hulls[i][None], hulls[j], 0.0)[0]
    return np.array(errors), np.array(gaps), overlaps


def test_lineup_stands_people_side_by_side_facing_the_camera(tmp_path, asset_dir):
    n = 40
    line = _describer(tmp_path, asset_dir, f"lineup: {{share: 1.0, gap_m: [0.0, 0.2], "
                      f"depth_m: 0.2, facing_deg: {FACING_DEG}}}", n)
    err, gap, overlaps = _further_people(line, n)
    free = _describer(tmp_path, asset_dir, "", n)
    err0, gap0, overlaps0 = _further_people(free, n)
    assert overlaps == 0 and overlaps0 == 0
    # in a line: beside a neighbour (its gap, plus the move along the line of sight) and
    # turned to the camera; a person with no room at either end is placed as without one
    # (facing: the heading is set where the person would stand with circles apart; the
    # slide towards the neighbour turns the line of sight by a few degrees)
    in_line = (gap <= 0.2 + 0.2 + 1e-9) & (err <= FACING_DEG + 8)
    assert in_line.mean() > 0.8, (in_line.mean(), len(err))
    assert (err0 <= FACING_DEG + 8).mean() < 0.4  # without a line, headings are free
    # closer than their circles allow (the bodies, not the circles, keep apart)
    assert np.median(gap) < 0 < np.median(gap0)


def test_lineup_share_zero_keeps_the_frame_as_without_but_for_the_draws(tmp_path, asset_dir):
    """share 0: no line, yet the two draws of scene.lineup are taken (the streams of a
    config do not depend on the share)."""
    n = 12
    zero = _describer(tmp_path, asset_dir, "lineup: {share: 0.0}", n)
    err, gap, _ = _further_people(zero, n)
    assert (err <= FACING_DEG).mean() < 0.5 and np.median(gap) > 0.5


def _box(x: float, z: float, hx: float = 0.2, hz: float = 0.15) -> np.ndarray:
    return np.array([[x - hx, z - hz], [x + hx, z - hz], [x + hx, z + hz], [x - hx, z + hz]])


def test_place_beside_puts_people_at_the_ends_as_close_as_their_outlines_allow():
    rng = np.random.default_rng(0)
    eye, forward, across = np.zeros(2), np.array([0.0, 1.0]), np.array([1.0, 0.0])
    first = (Disc(0.0, 3.0, 0.3), _box(0.0, 3.0))
    shape, radius = _box(0.0, 0.0), 0.25

    def beside(people, half_fov_deg=29.0, ends=(first, first)):
        return place_beside(rng, eye, forward, np.deg2rad(half_fov_deg), ends, across,
                            shape, radius, lambda xz: 0.0, (0.1, 0.1), 0.0, people, [],
                            None, steps=32)

    step = (0.3 + 0.25 + 0.1) / 32
    seen = set()
    for _ in range(20):
        out = beside([first[1]])
        assert out is not None
        seen.add(out.side)
        # the boxes 0.1 apart (0.2 + 0.2 + 0.1 between centres), to the next step out;
        # their circles (0.3 + 0.25) overlap
        assert out.disc.z == pytest.approx(3.0)
        assert 0.5 <= abs(out.disc.x) <= 0.5 + step + 1e-9
        assert np.sign(out.disc.x) == (1 if out.side else -1)
        np.testing.assert_allclose(out.outline, _box(out.disc.x, 3.0))
    assert seen == {0, 1}
    # someone standing at the right end: the left end, or beyond them on the right
    right = _box(0.5, 3.0)
    for _ in range(10):
        out = beside([first[1], right])
        assert out is not None and out.side == 0
    # both ends outside a narrow field of view: none
    assert beside([first[1]], half_fov_deg=8.0) is None


@pytest.mark.parametrize(("lineup", "people", "field", "words"), [
    ("{share: 2}", "[2, 4]", "scene.lineup.share", "outside"),
    ("{gap: 0.1}", "[2, 4]", "scene.lineup.gap", "unknown key"),
    ("true", "[1, 1]", "scene.lineup", "more than one person"),
    ("[1, 2]", "[2, 4]", "scene.lineup", "must be a mapping"),
])
def test_lineup_errors_name_the_field(tmp_path, lineup, people, field, words):
    p = tmp_path / "bad.yaml"
    p.write_text(SCENE.replace("people: [3, 4]", f"people: {people}")
                 .replace("LINEUP", f"lineup: {lineup}"))
    with pytest.raises(ConfigError) as e:
        JobConfig.load(p)
    assert field in str(e.value) and words in str(e.value)
