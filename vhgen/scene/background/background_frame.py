"""A real background as one frame sees it (pure data, see :mod:`vhgen.scene.background`):
its floor plane and the background a frame was composited into."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FloorPlane:
    """A background's floor in its camera frame (OpenCV axes): the points X with
    ``normal . X + height_m = 0``; ``normal`` (unit) points up, towards the camera, so
    ``height_m`` is the camera's height above the floor. ``inlier_fraction``: of the
    measured points (every 4th pixel of every 4th row), those on it (within 3 sigma of
    the depth noise, facing along it: see :func:`vhgen.scene.background.floor.estimate_floor`);
    ``rms_m``: their RMS distance to it."""

    normal: tuple[float, float, float]
    height_m: float
    inlier_fraction: float
    rms_m: float

    def world_to_camera(self) -> np.ndarray:
        """(4, 4) float64 world_to_camera of the background's world frame (see the module
        docstring): the floor is y = 0, the camera at (0, height_m, 0)."""
        n = np.asarray(self.normal, np.float64)
        f = np.array([0.0, 0.0, 1.0]) - n[2] * n  # the optical axis along the floor
        f /= np.linalg.norm(f)
        x = np.cross(n, f)
        c2w = np.stack([x, n, f])  # rows: the world axes in camera coordinates
        w2c = np.eye(4)
        w2c[:3, :3] = c2w.T
        w2c[:3, 3] = -c2w.T @ np.array([0.0, self.height_m, 0.0])
        return w2c

    def to_dict(self) -> dict:
        return {"normal_cam": [float(v) for v in self.normal], "height_m": self.height_m,
                "inlier_fraction": self.inlier_fraction, "rms_m": self.rms_m}


@dataclass(frozen=True, eq=False)
class PlacedBackground:
    """The background of one frame: its index in the job's set, file, floor, real depth
    (H, W) uint16 mm (read-only, a view of the job's array) and scene class name."""

    index: int
    file: str
    floor: FloorPlane
    depth_mm: np.ndarray
    class_name: str

    def to_dict(self) -> dict:
        """The manifest's record of it (in the row's ``scene`` JSON)."""
        return {"file": self.file, "index": self.index, "floor": self.floor.to_dict(),
                "class": self.class_name}
