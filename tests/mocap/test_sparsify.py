import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vhgen.mocap.sparsify import remove_heading, sparsify, sparsify_naive
from vhgen.rotations import axis_rotation, euler_to_matrix, geodesic_angle


def _walk(n, joints, step, seed):
    rng = np.random.default_rng(seed)
    return euler_to_matrix(np.cumsum(rng.normal(0, step, size=(n, joints, 3)), axis=0), "ZYX")


@pytest.mark.parametrize("deg", [2.0, 5.0, 20.0])
@pytest.mark.parametrize("batch", [7, 2048])
def test_same_kept_set_as_naive_loop(deg, batch):
    poses = _walk(1500, 6, 0.03, 1)
    fast = sparsify(poses, np.deg2rad(deg), batch=batch)
    np.testing.assert_array_equal(fast, sparsify_naive(poses, np.deg2rad(deg)))


@given(seed=st.integers(0, 10_000), deg=st.floats(1.0, 60.0), batch=st.integers(1, 64))
@settings(max_examples=25, deadline=None)
def test_property_equal_to_naive(seed, deg, batch):
    poses = _walk(300, 3, 0.08, seed)
    np.testing.assert_array_equal(sparsify(poses, np.deg2rad(deg), batch=batch),
                                  sparsify_naive(poses, np.deg2rad(deg)))


def test_kept_set_satisfies_the_definition():
    """Independent check with arccos-free geodesic angles: kept poses are pairwise at least
    the threshold apart, and every dropped pose has an earlier kept pose within it."""
    poses = _walk(600, 4, 0.05, 3)
    th = np.deg2rad(8)
    kept = sparsify(poses, th)
    ang = geodesic_angle(poses[:, None], poses[None, :]).max(axis=-1)  # (N, N) max over joints
    k = np.asarray(kept)
    sub = ang[np.ix_(k, k)] + np.eye(len(k)) * 10
    assert sub.min() >= th - 1e-12
    dropped = np.setdiff1d(np.arange(len(poses)), k)
    for d in dropped:
        earlier = k[k < d]
        assert (ang[d, earlier] < th + 1e-12).any()


def test_near_180_degree_rotations_are_double_cover_safe():
    """179.9 deg about +z and 180.1 deg about +z are 0.2 deg apart although their
    quaternions have opposite signs: the second must be dropped."""
    a = axis_rotation("Z", np.deg2rad(179.9))
    b = axis_rotation("Z", np.deg2rad(180.1))
    c = axis_rotation("Z", np.deg2rad(-179.95))
    poses = np.stack([a, b, c])[:, None]
    assert sparsify(poses, np.deg2rad(1)).tolist() == [0]
    assert sparsify_naive(poses, np.deg2rad(1)).tolist() == [0]


def test_identical_and_single_poses():
    p = np.broadcast_to(np.eye(3), (50, 5, 3, 3))
    assert sparsify(p, 0.01).tolist() == [0]
    assert sparsify(p[:1], 0.01).tolist() == [0]
    assert sparsify(p[:0], 0.01).tolist() == []


def test_position_metric_equals_naive():
    rng = np.random.default_rng(5)
    pos = np.cumsum(rng.normal(0, 0.01, size=(2000, 10, 3)), axis=0)
    for d in (0.02, 0.05):
        np.testing.assert_array_equal(sparsify(pos, d, "position"),
                                      sparsify_naive(pos, d, "position"))


def test_bad_inputs():
    p = np.broadcast_to(np.eye(3), (3, 2, 3, 3)).copy()
    p[1, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        sparsify(p, 0.1)
    with pytest.raises(ValueError, match="threshold"):
        sparsify(np.broadcast_to(np.eye(3), (3, 2, 3, 3)), 4.0)
    with pytest.raises(ValueError, match="metric"):
        sparsify(np.zeros((3, 2, 3)), 0.1, "manhattan")


def test_remove_heading_is_yaw_invariant_and_total():
    rng = np.random.default_rng(2)
    r = euler_to_matrix(rng.uniform(-np.pi, np.pi, size=(200, 3)), "ZYX")
    yaw = axis_rotation("Y", rng.uniform(-np.pi, np.pi, size=200))
    np.testing.assert_allclose(remove_heading(yaw @ r), remove_heading(r), atol=1e-9)
    # forward axis straight up or down (handstand): defined, a rotation
    for tilt in (np.pi / 2, -np.pi / 2):
        v = remove_heading(axis_rotation("Y", 0.7) @ axis_rotation("X", tilt))
        np.testing.assert_allclose(v @ v.T, np.eye(3), atol=1e-12)
        assert np.isfinite(v).all()
