import numpy as np
import pytest

from vhgen.body.skinning import (
    bone_matrices,
    dual_quaternions,
    posed_heads,
    skin_vertices,
    skin_vertices_dqs,
)
from vhgen.mocap.bvh import read_bvh
from vhgen.mocap.retarget import build_retargeter, detect_dialect, load_all_maps
from vhgen.rotations import axis_rotation, euler_to_matrix, matrix_to_quaternion, rigid


def test_quaternions_round_trip_near_180():
    rng = np.random.default_rng(0)
    r = euler_to_matrix(rng.uniform(-np.pi, np.pi, size=(500, 3)), "XYZ")
    r[0] = axis_rotation("X", np.pi)
    r[1] = axis_rotation("Z", np.pi - 1e-9)
    q = matrix_to_quaternion(r)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    x, y, z, w = q.T
    back = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)
    np.testing.assert_allclose(back, r, atol=1e-12)


def test_dqs_equals_lbs_for_a_single_rigid_bone():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(50, 3))
    m = rigid(euler_to_matrix(np.array([0.3, -1.2, 2.0]), "ZYX"), [0.5, -2, 3])[None]
    j = np.zeros((50, 4), int)
    w = np.tile([1.0, 0, 0, 0], (50, 1))
    np.testing.assert_allclose(skin_vertices_dqs(v, j, w, m), skin_vertices(v, j, w, m),
                               atol=1e-12)
    real, dual = dual_quaternions(m)
    assert real.shape == (1, 4) and dual.shape == (1, 4)


def _ring(radius=0.05, n=32):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([np.zeros(n), radius * np.cos(a), radius * np.sin(a)])


@pytest.mark.parametrize("deg", [90.0, 179.0, 180.0])
def test_twist_candy_wrapper(deg):
    """A ring around the x axis bound 50/50 to a fixed and a twisted bone: LBS collapses
    it (at 180 deg to a point), DQS keeps its radius; neither produces NaN."""
    v = _ring()
    j = np.tile([0, 1, 0, 0], (len(v), 1))
    w = np.tile([0.5, 0.5, 0, 0], (len(v), 1))
    mats = np.stack([np.eye(4), rigid(axis_rotation("X", np.deg2rad(deg)), [0, 0, 0])])
    lbs = skin_vertices(v, j, w, mats)
    dqs = skin_vertices_dqs(v, j, w, mats)
    assert np.isfinite(lbs).all() and np.isfinite(dqs).all()
    r_lbs = np.linalg.norm(lbs[:, 1:], axis=1)
    r_dqs = np.linalg.norm(dqs[:, 1:], axis=1)
    np.testing.assert_allclose(r_dqs, 0.05, rtol=1e-9)
    assert r_lbs.max() <= 0.05 * abs(np.cos(np.deg2rad(deg) / 2)) + 1e-12


@pytest.mark.parametrize("mode", ["lbs", "dqs"])
@pytest.mark.parametrize("clip", ["05_06.bvh", "01_03.bvh", "49_06.bvh"])
def test_gpu_skinning_within_0_1_mm_of_float64(gl_ctx, body, shared_mocap, mode, clip):
    from vhgen.render.renderer import GPUSkinner

    m = read_bvh(shared_mocap / clip)
    rot, root = build_retargeter(m, body.rig, detect_dialect(m, load_all_maps())).apply(
        m, frames=np.arange(0, m.num_frames, max(1, m.num_frames // 12)))
    ref = skin_vertices if mode == "lbs" else skin_vertices_dqs
    gpu = GPUSkinner(gl_ctx, body.vertices, body.joints, body.weights, body.num_bones, mode)
    worst = 0.0
    for f in range(len(rot)):
        mats = bone_matrices(body.rig, rot[f], root[f])
        got = gpu.positions(mats)
        assert np.isfinite(got).all()
        worst = max(worst, float(np.abs(got - ref(body.vertices, body.joints, body.weights,
                                                  mats)).max()))
    gpu.release()
    assert worst < 1e-4  # metres: 0.1 mm


def test_export_formats(tmp_path, body):
    import trimesh

    from vhgen.body.export import export_mesh, posed_mesh

    mesh = posed_mesh(body)
    for suffix in (".glb", ".ply", ".obj"):
        out = export_mesh(mesh, tmp_path / f"a{suffix}")
        back = trimesh.load(out, force="mesh", process=False)
        assert len(back.faces) == len(body.faces), suffix
    colors = mesh.visual.face_colors[:, :3]
    np.testing.assert_array_equal(colors, body.scheme.palette[body.face_labels])


@pytest.mark.parametrize("clip", ["05_06.bvh", "49_06.bvh"])
def test_compiled_cpu_skinning_equals_the_float64_reference(body, shared_mocap, clip):
    """skin_points (placement, floor contact) against skin_vertices on real poses: same
    points up to float64 rounding, whatever the order of the sums."""
    from vhgen.body.skin_kernels import skin_points

    m = read_bvh(shared_mocap / clip)
    rot, root = build_retargeter(m, body.rig, detect_dialect(m, load_all_maps())).apply(
        m, frames=np.arange(0, m.num_frames, max(1, m.num_frames // 6)))
    for f in range(len(rot)):
        mats = bone_matrices(body.rig, rot[f], root[f])
        ref = skin_vertices(body.vertices, body.joints, body.weights, mats)
        np.testing.assert_allclose(skin_points(body.vertices, body.joints, body.weights,
                                               mats), ref, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="matrices must be"):
        skin_points(body.vertices, body.joints, body.weights, mats[None])


def _posed_heads_bone_by_bone(rig, rotations, root):
    """The obvious reference: parents first, one bone at a time."""
    out = np.empty(rotations.shape[:-2] + (3,))
    for k, par in enumerate(rig.parents):
        out[..., k, :] = root if par < 0 else out[..., par, :] + np.einsum(
            "...ij,j->...i", rotations[..., par, :, :], rig.heads[k] - rig.heads[par])
    return out


@pytest.mark.parametrize("clip", ["05_06.bvh", "49_06.bvh"])
def test_posed_heads_by_tree_level_equal_bone_by_bone_bit_for_bit(body, shared_mocap, clip):
    """The level-vectorised heads are the same float64 sums: identical bytes, per pose and
    batched, so frames stay reproducible across the change."""
    m = read_bvh(shared_mocap / clip)
    rot, root = build_retargeter(m, body.rig, detect_dialect(m, load_all_maps())).apply(
        m, frames=np.arange(0, m.num_frames, max(1, m.num_frames // 8)))
    np.testing.assert_array_equal(posed_heads(body.rig, rot, root),
                                  _posed_heads_bone_by_bone(body.rig, rot, root))
    for f in range(len(rot)):
        np.testing.assert_array_equal(posed_heads(body.rig, rot[f], root[f] + 0.37),
                                      _posed_heads_bone_by_bone(body.rig, rot[f],
                                                                root[f] + 0.37))
