"""Rotation math over arrays with arbitrary leading batch dimensions.

Conventions: rotation matrices act on column vectors (``v' = R @ v``), right-handed
frames, angles in radians unless a name ends in ``_deg``.
"""

from __future__ import annotations

import numpy as np

_AXES = {"X": 0, "Y": 1, "Z": 2}


def axis_rotation(axis: str, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices about one coordinate axis.

    angle : (...) float64, radians.  Returns (..., 3, 3) float64.
    """
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(angle.shape + (3, 3), dtype=np.float64)
    i = _AXES[axis]
    j, k = (i + 1) % 3, (i + 2) % 3
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., k, k] = c
    out[..., j, k] = -s
    out[..., k, j] = s
    return out


def axis_angle_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices by ``angle`` (...) radians about unit vectors ``axis`` (..., 3).

    Returns (..., 3, 3) float64 (Rodrigues' formula, written out)."""
    axis = np.asarray(axis, dtype=np.float64)
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    t = 1.0 - c
    return np.stack([
        np.stack([c + t * x * x, t * x * y - s * z, t * x * z + s * y], -1),
        np.stack([t * x * y + s * z, c + t * y * y, t * y * z - s * x], -1),
        np.stack([t * x * z - s * y, t * y * z + s * x, c + t * z * z], -1)], -2)


def euler_to_matrix(angles: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles to matrices, BVH convention.

    angles : (..., n) float64 radians, one column per letter of ``order``.
    order  : axes in channel order, e.g. ``"ZYX"``; R = R_order[0] @ R_order[1] @ ...
    Returns (..., 3, 3) float64.
    """
    angles = np.asarray(angles, dtype=np.float64)
    if angles.shape[-1] != len(order):
        raise ValueError(f"{angles.shape[-1]} angles for order {order!r}")
    out = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for n, axis in enumerate(order):
        out = out @ axis_rotation(axis, angles[..., n])
    return out


def matrix_to_euler(matrix: np.ndarray, order: str) -> np.ndarray:
    """Inverse of :func:`euler_to_matrix` for the six Tait-Bryan orders.

    matrix : (..., 3, 3).  Returns (..., 3) radians with the middle angle in [-pi/2, pi/2].
    At gimbal lock (middle angle +-90 deg) the third angle is set to 0 and the first
    absorbs the whole rotation about the locked axis.
    """
    m = np.asarray(matrix, dtype=np.float64)
    i, j, k = (_AXES[a] for a in order)
    if len({i, j, k}) != 3:
        raise ValueError(f"only Tait-Bryan orders are supported, got {order!r}")
    # sign of the permutation (i, j, k): +1 for XYZ, YZX, ZXY
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    sin_b = np.clip(sign * m[..., i, k], -1.0, 1.0)
    b = np.arcsin(sin_b)
    cos_b = np.sqrt(np.maximum(0.0, 1.0 - sin_b * sin_b))
    locked = cos_b < 1e-9
    a = np.arctan2(-sign * m[..., j, k], m[..., k, k])
    c = np.arctan2(-sign * m[..., i, j], m[..., i, i])
    # gimbal lock: rotation about the first axis only, from the k-row/j-col block
    a_locked = np.arctan2(sign * m[..., k, j], m[..., j, j])
    a = np.where(locked, a_locked, a)
    c = np.where(locked, 0.0, c)
    return np.stack([a, b, c], axis=-1)


def min_rotation(a: np.ndarray, b: np.ndarray, eps: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Smallest rotation taking direction ``a`` onto direction ``b``.

    a, b : (..., 3) float64, need not be unit length.
    Returns (R, valid): R (..., 3, 3) with R @ a_hat = b_hat; valid (...) bool is False
    where either vector is shorter than ``eps`` (R is the identity there). For opposite
    vectors the rotation is 180 deg about an axis perpendicular to ``a``.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    valid = (na[..., 0] > eps) & (nb[..., 0] > eps)
    ua = np.where(na > eps, a / np.where(na > eps, na, 1.0), 0.0)
    ub = np.where(nb > eps, b / np.where(nb > eps, nb, 1.0), 0.0)
    v = np.cross(ua, ub)
    c = np.sum(ua * ub, axis=-1)
    # Rodrigues with axis v (|v| = sin): R = I + [v]x + [v]x^2 / (1 + c)
    vx = skew(v)
    eye = np.broadcast_to(np.eye(3), vx.shape)
    denom = np.where(1.0 + c > 1e-12, 1.0 + c, 1.0)[..., None, None]
    r = eye + vx + vx @ vx / denom
    # antiparallel: 180 deg about any axis perpendicular to a
    anti = valid & (1.0 + c <= 1e-12)
    if np.any(anti):
        helper = np.where(np.abs(ua[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        axis = np.cross(ua, helper)
        axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), eps)
        r180 = 2.0 * axis[..., :, None] * axis[..., None, :] - eye
        r = np.where(anti[..., None, None], r180, r)
    r = np.where(valid[..., None, None], r, eye)
    return r, valid


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices: skew(v) @ w == cross(v, w).  v : (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=np.float64)
    out = np.zeros(v.shape[:-1] + (3, 3), dtype=np.float64)
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def geodesic_angle(r1: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """Angle in radians of the rotation r1^T r2, computed stably near 0 and 180 deg.

    r1, r2 : (..., 3, 3).  Returns (...) in [0, pi].
    """
    r = np.swapaxes(np.asarray(r1, np.float64), -1, -2) @ np.asarray(r2, np.float64)
    cos = (np.trace(r, axis1=-2, axis2=-1) - 1.0) / 2.0
    sin = 0.5 * np.linalg.norm(
        np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                  r[..., 1, 0] - r[..., 0, 1]], axis=-1), axis=-1)
    return np.arctan2(sin, cos)


def rigid(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Stack rotations (..., 3, 3) and translations (..., 3) into (..., 4, 4) transforms."""
    rotation = np.asarray(rotation, np.float64)
    translation = np.asarray(translation, np.float64)
    shape = np.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1])
    out = np.zeros(shape + (4, 4), dtype=np.float64)
    out[..., :3, :3] = rotation
    out[..., :3, 3] = translation
    out[..., 3, 3] = 1.0
    return out


def matrix_to_quaternion(matrix: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4) as (x, y, z, w), w >= 0.

    Shepperd's method: the largest of the four candidate pivots is used, so it is stable
    near 180 degrees.
    """
    m = np.asarray(matrix, np.float64)
    tr = np.trace(m, axis1=-2, axis2=-1)
    cand = np.stack([m[..., 0, 0], m[..., 1, 1], m[..., 2, 2], tr], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(m.shape[:-2] + (4,), dtype=np.float64)
    # w pivot
    s = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2
    qw = np.stack([(m[..., 2, 1] - m[..., 1, 2]) / s, (m[..., 0, 2] - m[..., 2, 0]) / s,
                   (m[..., 1, 0] - m[..., 0, 1]) / s, 0.25 * s], axis=-1)
    s0 = np.sqrt(np.maximum(1.0 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2], 1e-300)) * 2
    qx = np.stack([0.25 * s0, (m[..., 0, 1] + m[..., 1, 0]) / s0,
                   (m[..., 0, 2] + m[..., 2, 0]) / s0, (m[..., 2, 1] - m[..., 1, 2]) / s0], axis=-1)
    s1 = np.sqrt(np.maximum(1.0 + m[..., 1, 1] - m[..., 0, 0] - m[..., 2, 2], 1e-300)) * 2
    qy = np.stack([(m[..., 0, 1] + m[..., 1, 0]) / s1, 0.25 * s1,
                   (m[..., 1, 2] + m[..., 2, 1]) / s1, (m[..., 0, 2] - m[..., 2, 0]) / s1], axis=-1)
    s2 = np.sqrt(np.maximum(1.0 + m[..., 2, 2] - m[..., 0, 0] - m[..., 1, 1], 1e-300)) * 2
    qz = np.stack([(m[..., 0, 2] + m[..., 2, 0]) / s2, (m[..., 1, 2] + m[..., 2, 1]) / s2,
                   0.25 * s2, (m[..., 1, 0] - m[..., 0, 1]) / s2], axis=-1)
    q[...] = qw
    for idx, cand_q in ((0, qx), (1, qy), (2, qz)):
        q = np.where((k == idx)[..., None], cand_q, q)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)
