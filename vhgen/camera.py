"""Camera math in NumPy, in one place: intrinsics, projection and back-projection,
extrinsics (look-at, a mounted camera, the projector beside it) and the per-frame camera
placement a job samples.

Conventions: camera frame as OpenCV (x right, y down, z forward), world frame Y up.
Pixel (u, v) = (column, row) has its centre at integer coordinates; image row 0 is the
top row. Depth ``z`` is planar depth along the optical axis (not range), metres. A point
on or behind the camera plane (z <= 0) has no projection: NaN.
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
    """Camera-frame points (..., 3) -> pixel coordinates (..., 2) float64 (u, v), pixel
    centres at integers; a point with z <= 0 (on or behind the camera) gives NaN."""
    p = np.asarray(points_cam, np.float64)
    z = np.where(p[..., 2] > 0, p[..., 2], np.nan)
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


def mounted_camera(eye: np.ndarray, pitch_deg: float, roll_deg: float) -> np.ndarray:
    """world_to_camera (4, 4) of a camera at ``eye`` turned towards the world's y axis,
    tilted down by ``pitch_deg`` and rolled by ``roll_deg`` about its optical axis."""
    level = np.array([-eye[0], 0.0, -eye[2]])
    level /= np.linalg.norm(level)
    p = np.deg2rad(pitch_deg)
    forward = np.cos(p) * level + np.array([0.0, -np.sin(p), 0.0])
    w2c = look_at(eye, eye + forward)
    c, s = np.cos(np.deg2rad(roll_deg)), np.sin(np.deg2rad(roll_deg))
    rz = np.eye(4)
    rz[:2, :2] = [[c, -s], [s, c]]
    return rz @ w2c


def pitch_roll_deg(world_to_camera: np.ndarray) -> tuple[float, float]:
    """The pitch (degrees down from level) and roll (about the optical axis) of a camera
    in a Y-up world: the inverse of :func:`mounted_camera`'s tilt."""
    w2c = np.asarray(world_to_camera, np.float64)
    return (float(np.degrees(np.arcsin(np.clip(-w2c[2, 1], -1, 1)))),
            float(np.degrees(np.arctan2(w2c[0, 1], -w2c[1, 1]))))


def world_to_projector(world_to_camera: np.ndarray, baseline_m: float) -> np.ndarray:
    """world_to_projector (4, 4) of a structured-light sensor's projector, at
    +``baseline_m`` along the camera's x axis (a rectified rig)."""
    w2p = np.array(world_to_camera, dtype=np.float64)
    w2p[0, 3] -= baseline_m
    return w2p


@dataclass(frozen=True)
class CameraConfig:
    """Camera placement, sampled per frame: the camera circles the subject's root."""

    distance_m: tuple[float, float] = (2.2, 3.2)
    height_m: tuple[float, float] = (0.9, 1.3)
    yaw_deg: tuple[float, float] = (-60.0, 60.0)  # 0 = camera in front of the subject
    look_at_height_m: tuple[float, float] = (0.85, 1.0)
    near_m: float = 0.1
    far_m: float = 20.0
    # a mounted camera (set by pitch_deg or a preset): level, turned towards the subject,
    # tilted down by pitch (degrees, + = towards the floor) and rolled about its axis;
    # look_at_height_m is then unused. None = the camera looks at the subject (above).
    pitch_deg: tuple[float, float] | None = None
    roll_deg: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True, eq=False)
class CameraPose:
    """world_to_camera (4, 4) float64 (OpenCV axes: x right, y down, z forward) and the
    sampled mount: yaw about the subject (deg), distance and height (m), and for a
    mounted camera its pitch and roll (deg; None when it looks at the subject)."""

    world_to_camera: np.ndarray
    yaw_deg: float
    distance_m: float
    height_m: float
    pitch_deg: float | None = None
    roll_deg: float | None = None

    @property
    def eye(self) -> np.ndarray:
        """(3,) float64 the camera centre in the world."""
        w2c = self.world_to_camera
        return -w2c[:3, :3].T @ w2c[:3, 3]


def sample_camera(rng: np.random.Generator, cfg: CameraConfig) -> CameraPose:
    """Camera placement around the subject's root (the first draws of the frame's
    stream, in this order: yaw, distance, height, then look-at height; or, for a mounted
    camera (``pitch_deg`` set), pitch and roll)."""
    yaw = rng.uniform(*cfg.yaw_deg)
    dist = rng.uniform(*cfg.distance_m)
    height = rng.uniform(*cfg.height_m)
    a = np.deg2rad(yaw)
    eye = np.array([dist * np.sin(a), height, dist * np.cos(a)])
    if cfg.pitch_deg is None:
        target_h = rng.uniform(*cfg.look_at_height_m)
        w2c = look_at(eye, np.array([0.0, target_h, 0.0]))
        return CameraPose(w2c, float(yaw), float(dist), float(height))
    pitch = float(rng.uniform(*cfg.pitch_deg))
    roll = float(rng.uniform(*cfg.roll_deg))
    w2c = mounted_camera(eye, pitch, roll)
    return CameraPose(w2c, float(yaw), float(dist), float(height), pitch, roll)


def skip_camera(rng: np.random.Generator, cfg: CameraConfig) -> None:
    """Advance ``rng`` past the draws of :func:`sample_camera` without placing a camera
    (a frame of a shared layout takes the layout's camera; its stream goes on from where
    it would): one double for each of them, as ``Generator.uniform`` draws one each."""
    rng.random(4 if cfg.pitch_deg is None else 5)
