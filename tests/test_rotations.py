import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vhgen.rotations import (
    axis_rotation,
    euler_to_matrix,
    geodesic_angle,
    matrix_to_euler,
    min_rotation,
)

ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
angle = st.floats(-np.pi, np.pi, allow_nan=False)


def _slow_euler(angles, order):
    """Obvious reference: multiply the three axis matrices one by one."""
    r = np.eye(3)
    for a, ax in zip(angles, order, strict=True):
        c, s = np.cos(a), np.sin(a)
        m = {"X": [[1, 0, 0], [0, c, -s], [0, s, c]],
             "Y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
             "Z": [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[ax]
        r = r @ np.array(m)
    return r


@pytest.mark.parametrize("order", ORDERS)
@given(a=angle, b=angle, c=angle)
@settings(max_examples=60, deadline=None)
def test_euler_matches_reference_and_round_trips(order, a, b, c):
    r = euler_to_matrix(np.array([a, b, c]), order)
    np.testing.assert_allclose(r, _slow_euler([a, b, c], order), atol=1e-12)
    back = euler_to_matrix(matrix_to_euler(r, order), order)
    np.testing.assert_allclose(back, r, atol=1e-9)


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("middle", [np.pi / 2, -np.pi / 2])
def test_gimbal_lock_round_trips(order, middle):
    r = euler_to_matrix(np.array([0.3, middle, -0.7]), order)
    e = matrix_to_euler(r, order)
    assert np.all(np.isfinite(e))
    np.testing.assert_allclose(euler_to_matrix(e, order), r, atol=1e-9)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_euler_batch_shapes_and_dtypes(dtype):
    rng = np.random.default_rng(0)
    ang = rng.uniform(-4, 4, size=(5, 7, 3)).astype(dtype)
    r = euler_to_matrix(ang, "ZYX")
    assert r.shape == (5, 7, 3, 3) and r.dtype == np.float64
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape),
                               atol=1e-12)


def test_angles_beyond_pi_wrap():
    r1 = euler_to_matrix(np.deg2rad([370.0, -190.0, 725.0]), "ZYX")
    r2 = euler_to_matrix(np.deg2rad([10.0, 170.0, 5.0]), "ZYX")
    np.testing.assert_allclose(r1, r2, atol=1e-12)


def test_min_rotation_maps_a_to_b_including_antiparallel_and_zero():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(200, 3))
    b = rng.normal(size=(200, 3))
    a[0], b[0] = [1, 0, 0], [-1, 0, 0]  # antiparallel
    a[1], b[1] = [0, 0, 2], [0, 0, -3]
    a[2] = 0.0  # degenerate
    r, ok = min_rotation(a, b)
    assert not ok[2] and ok[[0, 1, 3]].all()
    np.testing.assert_allclose(r[2], np.eye(3))
    ua = a[ok] / np.linalg.norm(a[ok], axis=1, keepdims=True)
    ub = b[ok] / np.linalg.norm(b[ok], axis=1, keepdims=True)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", r[ok], ua), ub, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)


def test_geodesic_angle_stable_near_0_and_180():
    for deg in [0.0, 1e-7, 90.0, 179.9999, 180.0]:
        r = axis_rotation("Z", np.deg2rad(deg))
        assert abs(np.rad2deg(geodesic_angle(np.eye(3), r)) - deg) < 1e-6


def test_axis_angle_matrix_agrees_with_the_coordinate_axes_and_is_a_rotation():
    from vhgen.rotations import axis_angle_matrix, axis_rotation, geodesic_angle

    angle = np.linspace(-3.0, 3.0, 13)
    for name, axis in (("X", [1.0, 0, 0]), ("Y", [0, 1.0, 0]), ("Z", [0, 0, 1.0])):
        np.testing.assert_allclose(axis_angle_matrix(np.tile(axis, (13, 1)), angle),
                                   axis_rotation(name, angle), atol=1e-15)
    rng = np.random.default_rng(3)
    axis = rng.normal(size=(50, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0, np.pi, 50)
    r = axis_angle_matrix(axis, angle)
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape),
                               atol=1e-14)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", r, axis), axis, atol=1e-14)  # fixed
    np.testing.assert_allclose(geodesic_angle(np.eye(3), r), angle, atol=1e-12)
