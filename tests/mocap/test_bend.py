"""Poses bent forward at the hips (``poses.bend``): the geometry on real CMU poses, the
draw, the config and what a store records."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from vhgen.body.skinning import posed_heads
from vhgen.errors import ConfigError, VhgenError
from vhgen.job_config import JobConfig
from vhgen.mocap.bend import bend_forward, choose_bends, kept_bones
from vhgen.mocap.bvh import read_bvh
from vhgen.mocap.retarget import build_retargeter
from vhgen.rotations import geodesic_angle, min_rotation


@pytest.fixture(scope="module")
def poses(shared_mocap, body, cmu_map):
    """Jumps in a playground, a kick and a dance from the shared corpus: (rig, rotations,
    roots)."""
    rots, roots = [], []
    for clip in ("01_01.bvh", "10_06.bvh", "05_06.bvh"):
        m = read_bvh(shared_mocap / clip)
        rot, root = build_retargeter(m, body.rig, cmu_map).apply(
            m, frames=np.linspace(1, m.num_frames - 1, 12).astype(int))
        rots.append(rot)
        roots.append(root)
    return body.rig, np.concatenate(rots), np.concatenate(roots)


def _facing(rig, rot):
    """Level unit vectors the way each pose's pelvis faces: the rest pose's heel-to-toe
    direction turned by the Hips bone (the bend's axis is the rest hip-to-hip line turned
    by it: this checks the handedness, that left x up is backwards)."""
    h = rig.heads
    rest = (h[rig.index("LeftToeBase")] - h[rig.index("LeftFoot")]
            + h[rig.index("RightToeBase")] - h[rig.index("RightFoot")])
    rest[1] = 0
    f = rot[:, rig.index("Hips")] @ rest
    f[:, 1] = 0
    return f / np.linalg.norm(f, axis=1, keepdims=True)


def _lean(rig, rot, heads):
    """Degrees the trunk (hips to neck) leans forward, in the plane across the pelvis."""
    left = rot[:, rig.index("Hips")] @ (rig.heads[rig.index("LeftUpLeg")]
                                        - rig.heads[rig.index("RightUpLeg")])
    left[:, 1] = 0
    forward = np.cross(left / np.linalg.norm(left, axis=1, keepdims=True), [0.0, 1, 0])
    trunk = heads[:, rig.index("Neck")] - heads[:, rig.index("Hips")]
    return np.rad2deg(np.arctan2((trunk * forward).sum(1), trunk[:, 1]))


def test_bend_leans_the_trunk_forward_and_leaves_the_feet(poses):
    rig, rot, root = poses
    h0 = posed_heads(rig, rot, root)
    lean0 = _lean(rig, rot, h0)
    head = rig.index("Head")
    feet = [rig.index(n) for n in ("LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase")]
    assert lean0.max() > 30  # the jumps of 01_01 start leaning forward
    upright = np.abs(lean0) < 60
    assert (~upright).any()  # and the dance has a pose upside down
    for deg in (30.0, 60.0, 90.0):
        r, o, turn = bend_forward(rig, rot, root, np.full(len(rot), deg))
        h = posed_heads(rig, r, o)
        # the trunk leans as far as asked, or as it did when it leaned further; a pose
        # that is not upright stays
        want = np.where(upright, np.maximum(lean0, deg), lean0)
        # (measured in the plane of the pose before: the turn is about its level axis)
        np.testing.assert_allclose(_lean(rig, rot, h), want, atol=1e-6)
        np.testing.assert_allclose(turn, np.where(upright, np.maximum(deg - lean0, 0), 0),
                                   atol=1e-6)
        np.testing.assert_array_equal(r[~upright], rot[~upright])
        # the ankles stay (on average over the two), so the clip's grounding holds
        np.testing.assert_allclose(h[:, feet[:2]].mean(1), h0[:, feet[:2]].mean(1),
                                   atol=1e-9)
        assert np.abs(h[:, feet] - h0[:, feet]).max() < 0.05  # each foot within 5 cm
        # the head goes the way the pelvis faces, and down
        ahead = ((h[:, head] - h0[:, head]) * _facing(rig, rot)).sum(1)
        assert (ahead[turn > 1] > 0.01).all() and (ahead > -1e-9).all()
        assert (h[:, head, 1] <= h0[:, head, 1] + 1e-9).all()
    # at 90 degrees the upright people's heads are under a metre above their feet (some
    # jump): the people the detector missed
    assert (h[upright, head, 1] - h[upright][:, feet, 1].min(1)).max() < 1.0


def test_bend_turns_the_trunk_rigidly_and_keeps_legs_and_arms(poses):
    rig, rot, root = poses
    deg = np.linspace(0.0, 110.0, len(rot))
    r, _, turn = bend_forward(rig, rot, root, deg)
    assert turn.max() > 80 and not turn[0]
    keep = kept_bones(rig)
    names = [rig.names[b] for b in np.flatnonzero(keep)]
    assert {"LeftFoot", "RightHand", "LeftForeArm"} <= set(names)
    assert not {"Hips", "Spine", "Head", "LeftShoulder"} & set(names)
    np.testing.assert_array_equal(r[:, keep], rot[:, keep])
    # every turned bone turned by the same rotation, of the pose's turn, about a level axis
    t = r[:, ~keep] @ np.swapaxes(rot[:, ~keep], -1, -2)
    np.testing.assert_allclose(t, np.broadcast_to(t[:, :1], t.shape), atol=1e-12)
    angle = np.rad2deg(geodesic_angle(np.eye(3), t[:, 0]))
    np.testing.assert_allclose(angle, turn, atol=1e-9)
    np.testing.assert_allclose(t[:, 0, 1, 1], np.cos(np.deg2rad(turn)), atol=1e-12)
    eye = np.broadcast_to(np.eye(3), r.shape)
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), eye, atol=1e-12)
    # no bend is no change, bit for bit
    r0, o0, t0 = bend_forward(rig, rot, root, np.zeros(len(rot)))
    np.testing.assert_array_equal(r0, rot)
    np.testing.assert_array_equal(o0, root)
    assert not t0.any()


def test_bend_refuses_a_rig_without_the_bones_and_leaves_a_pose_on_its_side(poses):
    rig, rot, root = poses
    from dataclasses import replace

    other = replace(rig, names=[n.replace("LeftUpLeg", "thigh_l") for n in rig.names])
    with pytest.raises(VhgenError, match="lacks LeftUpLeg"):
        kept_bones(other)
    # the hips one above the other (lying on a side): no level axis across them, no bend
    hips = rig.heads[rig.index("LeftUpLeg")] - rig.heads[rig.index("RightUpLeg")]
    up, _ = min_rotation(hips, np.array([0.0, 1, 0]))  # the hip line straight up
    side = np.einsum("ij,nbjk->nbik", up, np.broadcast_to(np.eye(3), rot[:1].shape))
    r, o, turn = bend_forward(rig, side, root[:1], np.array([45.0]))
    np.testing.assert_array_equal(r, side)
    np.testing.assert_array_equal(o, root[:1])
    assert not turn.any()


def test_choose_bends_is_a_seeded_share_in_range():
    a = choose_bends(20000, 0.2, (30.0, 100.0), seed=7)
    assert abs((a > 0).mean() - 0.2) < 0.01
    assert a[a > 0].min() >= 30 and a.max() <= 100
    np.testing.assert_array_equal(a, choose_bends(20000, 0.2, (30.0, 100.0), seed=7))
    assert not np.array_equal(a, choose_bends(20000, 0.2, (30.0, 100.0), seed=8))
    assert not choose_bends(100, 0.0, (30.0, 100.0), seed=7).any()


@pytest.mark.parametrize("bend, field", [
    ("{share: 1.5}", "poses.bend.share"),
    ("{share: 0.2, degrees: [100, 30]}", "poses.bend.degrees"),
    ("{share: 0.2, degrees: [30, 150]}", "poses.bend.degrees"),
    ("{share: 0.2, angle: 40}", "poses.bend"),
    ("0.2", "poses.bend"),
])
def test_bend_config_errors_name_the_field(tmp_path, bend, field):
    p = tmp_path / "c.yaml"
    p.write_text(f"name: c\nmotions: [builtin:demo]\nposes: {{bend: {bend}}}\n")
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        JobConfig.load(p)


@pytest.mark.gl
def test_a_job_records_its_bent_poses(tmp_path):
    from vhgen.pipeline.driver import run_job

    p = tmp_path / "c.yaml"
    p.write_text("name: c\nseed: 5\nmotions: [builtin:demo]\nposes: {frame_step: 8, bend: "
                 "{share: 0.5, degrees: [40, 80]}}\navatars: {count: 1}\nsensor: ideal\n"
                 "output: {frames_per_shard: 4}\nrender: {backend: osmesa}\nnum_workers: 1\n")
    cfg = JobConfig.load(p)
    run_job(cfg, tmp_path / "s.zarr", max_frames=4, executor="local")
    attrs = zarr.open_group(str(tmp_path / "s.zarr"), mode="r").attrs
    assert attrs["poses_bend"] == {"share": 0.5, "degrees": [40.0, 80.0]}
    bent = {int(k): v for k, v in attrs["bent_poses"].items()}
    chosen = choose_bends(sum(m["poses_kept"] for m in attrs["motions"]), 0.5, (40.0, 80.0),
                          seed=5)
    # the poses drawn, each turned to its draw's lean (less where it leaned already)
    assert bent and set(bent) <= set(np.flatnonzero(chosen).tolist())
    assert all(0 < v < chosen[i] + 60 for i, v in bent.items())  # + a lean back
    # a config without poses.bend writes neither attribute (its store is as before)
    p.write_text(p.read_text().replace(", bend: {share: 0.5, degrees: [40, 80]}", ""))
    run_job(JobConfig.load(p), tmp_path / "t.zarr", max_frames=4, executor="local")
    attrs = zarr.open_group(str(tmp_path / "t.zarr"), mode="r").attrs
    assert "poses_bend" not in attrs and "bent_poses" not in attrs
