"""Pinhole camera math in NumPy: intrinsics, extrinsics, projection, back-projection.

Conventions: camera frame as OpenCV (x right, y down, z forward), world frame Y up.
Pixel (u, v) = (column, row) has its centre at integer coordinates; image row 0 is the
top row. Depth ``z`` is planar depth along the optical axis (not range), metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels for a ``width`` x ``height`` image."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def matrix(self) -> np.ndarray:
        """(3, 3) float64 K."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def gl_projection(self, near: float, far: float) -> np.ndarray:
        """(4, 4) float64 clip matrix for a camera-frame point (x, y, z), z > 0.

        Maps pixel centres exactly: GL window x = u + 0.5 and window y = v + 0.5, so the
        framebuffer read back from row 0 upward *is* the image with row 0 on top.
        (The flip reverses triangle winding, which back-face culling accounts for: see
        ``DepthLabelRenderer._cull_ranges``.)
        """
        w, h = self.width, self.height
        return np.array([
            [2 * self.fx / w, 0, 2 * (self.cx + 0.5) / w - 1, 0],
            [0, 2 * self.fy / h, 2 * (self.cy + 0.5) / h - 1, 0],
            [0, 0, (far + near) / (far - near), -2 * far * near / (far - near)],
            [0, 0, 1, 0]], dtype=np.float64)

    def to_dict(self) -> dict:
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy}


def project(intr: Intrinsics, points_cam: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) -> pixel coordinates (..., 2) float64 (u, v)."""
    p = np.asarray(points_cam, np.float64)
    z = p[..., 2]
    return np.stack([intr.fx * p[..., 0] / z + intr.cx, intr.fy * p[..., 1] / z + intr.cy], -1)


def backproject(intr: Intrinsics, depth: np.ndarray) -> np.ndarray:
    """Planar depth (H, W) metres -> camera-frame points (H, W, 3) float64; X=(u-cx)z/fx."""
    z = np.asarray(depth, np.float64)
    v, u = np.mgrid[0:intr.height, 0:intr.width].astype(np.float64)
    return np.stack([(u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z], -1)


def pixel_rays(intr: Intrinsics) -> np.ndarray:
    """(H, W, 3) float64 camera-frame rays with z = 1 through every pixel centre."""
    return backproject(intr, np.ones((intr.height, intr.width)))


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """World-to-camera (4, 4) float64 for a camera at ``eye`` looking at ``target``.

    The camera's +z points at the target, +y (image down) points against world ``up``.
    """
    eye = np.asarray(eye, np.float64)
    target = np.asarray(target, np.float64)
    z = target - eye
    nz = np.linalg.norm(z)
    if nz < 1e-12:
        raise ValueError("camera eye and target coincide")
    z /= nz
    x = np.cross(z, np.asarray(up, np.float64))  # image right
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("camera looks along the up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])  # rows: camera axes in world coordinates
    out = np.eye(4)
    out[:3, :3] = r
    out[:3, 3] = -r @ eye
    return out
