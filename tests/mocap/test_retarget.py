import numpy as np
import pytest

from vhgen.body.skinning import bone_matrices, posed_heads, skin_vertices
from vhgen.errors import ConfigError, RetargetError
from vhgen.mocap.bvh import read_bvh
from vhgen.mocap.retarget import (
    RetargetMap,
    build_retargeter,
    local_rotations,
    world_rotations,
)


def _dir(rig, rot, name):
    k = rig.index(name)
    d = rot[..., k, :, :] @ (rig.tails[k] - rig.heads[k])
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


@pytest.mark.parametrize("clip", ["01_01.bvh", "cmu_12_01_walk.bvh", "09_01.bvh"])
def test_tpose_frame_poses_mesh_into_tpose(shared_mocap, body, cmu_map, clip):
    """cgspeed files start with a T-pose frame; the mesh must follow into a T-pose."""
    m = read_bvh(shared_mocap / clip)
    rot, _ = build_retargeter(m, body.rig, cmu_map).apply(m, frames=np.array([0]))
    for name, axis, tol in [("LeftArm", [1, 0, 0], 10), ("LeftForeArm", [1, 0, 0], 10),
                            ("RightArm", [-1, 0, 0], 10), ("RightForeArm", [-1, 0, 0], 10),
                            ("LeftUpLeg", [0, -1, 0], 5), ("LeftLeg", [0, -1, 0], 5),
                            ("RightUpLeg", [0, -1, 0], 5), ("RightLeg", [0, -1, 0], 5)]:
        cos = _dir(body.rig, rot[0], name) @ np.array(axis, float)
        assert np.rad2deg(np.arccos(np.clip(cos, -1, 1))) < tol, name


def test_straightened_bones_follow_source_bones_every_frame(shared_mocap, body, cmu_map):
    m = read_bvh(shared_mocap / "05_06.bvh")
    rot, _ = build_retargeter(m, body.rig, cmu_map).apply(m)
    g, p = m.world_transforms()
    pairs = [("LeftArm", "LeftArm", "LeftForeArm"), ("RightLeg", "RightLeg", "RightFoot"),
             ("LeftForeArm", "LeftForeArm", "LeftHand")]
    for bone, joint, child in pairs:
        src = p[:, m.index(child)] - p[:, m.index(joint)]
        src /= np.linalg.norm(src, axis=1, keepdims=True)
        np.testing.assert_allclose(_dir(body.rig, rot, bone), src, atol=1e-9)


def test_poses_are_finite_rotations_on_hard_clips(shared_mocap, body, cmu_map):
    for clip in ("05_06.bvh", "49_06.bvh", "16_27.bvh", "10_06.bvh"):
        m = read_bvh(shared_mocap / clip)
        rot, root = build_retargeter(m, body.rig, cmu_map).apply(m)
        assert np.isfinite(rot).all() and np.isfinite(root).all()
        eye = np.broadcast_to(np.eye(3), rot.shape)
        np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), eye, atol=1e-9)


def test_root_scaled_to_target_feet_near_floor(shared_mocap, body, cmu_map):
    m = read_bvh(shared_mocap / "cmu_12_01_walk.bvh")
    rot, root = build_retargeter(m, body.rig, cmu_map).apply(m, frames=np.arange(0, 500, 50))
    v = skin_vertices(body.vertices, body.joints, body.weights, bone_matrices(body.rig, rot, root))
    lowest = v[..., 1].min(axis=-1)
    assert np.all(np.abs(lowest) < 0.06), lowest  # CMU's floor is y = 0; feet within 6 cm


def test_local_world_round_trip(shared_mocap, body, cmu_map):
    m = read_bvh(shared_mocap / "02_01.bvh")
    rot, root = build_retargeter(m, body.rig, cmu_map).apply(m, frames=np.arange(10))
    np.testing.assert_allclose(world_rotations(body.rig, local_rotations(body.rig, rot)), rot,
                               atol=1e-12)
    heads = posed_heads(body.rig, rot, root)
    assert heads.shape == (10, len(body.rig.names), 3)


def test_unknown_dialect_names_unmapped_joints(shared_mocap, body, cmu_map):
    m = read_bvh(shared_mocap / "10_01.bvh")
    with pytest.raises(RetargetError) as ei:
        build_retargeter(m, body.rig, cmu_map)
    msg = str(ei.value)
    assert "10_01.bvh" in msg and "LeftHip" in msg and "cmu_mb" in msg


def test_map_config_errors_name_the_field(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("name: x\ntarget_rig: cmu_mb\nunits: m\njoints: {Hips: Hips}\nbogus: 1\n")
    with pytest.raises(ConfigError, match="bogus: unknown key"):
        RetargetMap.load(p)
    p.write_text("name: x\ntarget_rig: cmu_mb\nunits: furlong\njoints: {Hips: Hips}\n")
    with pytest.raises(ConfigError, match="units"):
        RetargetMap.load(p)
