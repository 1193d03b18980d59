"""Sampling a room around the person and the camera (pure; its own generator)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from vhgen.scene.geometry import StaticMesh, floor_mesh, room_floor, room_walls
from vhgen.scene.scene_config import (
    CAMERA_CLEARANCE_M,
    OPEN_FLOOR_HALF_M,
    PERSON_CLEARANCE_M,
    RoomConfig,
    SceneConfig,
)


@dataclass(frozen=True, eq=False)
class Room:
    """A sampled room: floor corners (4, 2) (x, z) world metres in order, wall height,
    width (along the first edge) and depth, and its yaw about +y in degrees."""

    corners_xz: np.ndarray
    height_m: float
    width_m: float
    depth_m: float
    yaw_deg: float

    @cached_property
    def edges(self) -> tuple[float, tuple[tuple[float, float, float, float, float], ...]]:
        """The floor's orientation sign (+1 counter-clockwise) and, per edge k (corner k to
        k + 1), (a_x, a_z, e_x, e_z, |e|): its start, direction and length, for the
        signed distance of a point inside (placement asks this thousands of times)."""
        c = self.corners_xz
        area2 = sum(c[k, 0] * c[(k + 1) % 4, 1] - c[(k + 1) % 4, 0] * c[k, 1] for k in range(4))
        edges = []
        for k in range(4):
            a, b = c[k], c[(k + 1) % 4]
            e = b - a
            edges.append((float(a[0]), float(a[1]), float(e[0]), float(e[1]),
                          float(np.hypot(e[0], e[1]))))
        return (1.0 if area2 > 0 else -1.0), tuple(edges)

    def to_dict(self) -> dict:
        return {"corners_xz": np.round(self.corners_xz, 6).tolist(), "height_m": self.height_m,
                "width_m": self.width_m, "depth_m": self.depth_m, "yaw_deg": self.yaw_deg}


def _spans(theta: float, eye_xz: np.ndarray, behind_m: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Room axes (width, depth) for yaw ``theta`` and the (lo, hi) extents along each that
    keep the person (origin), the floor ``behind_m`` beyond it (seen from the camera) and
    the camera inside with their clearances."""
    wa = np.array([np.cos(theta), -np.sin(theta)])
    da = np.array([np.sin(theta), np.cos(theta)])
    cam = np.array([eye_xz @ wa, eye_xz @ da])
    far = -cam / max(float(np.hypot(*cam)), 1e-9) * behind_m
    lo = np.minimum(np.minimum(-PERSON_CLEARANCE_M, far - PERSON_CLEARANCE_M),
                    cam - CAMERA_CLEARANCE_M)
    hi = np.maximum(np.maximum(PERSON_CLEARANCE_M, far + PERSON_CLEARANCE_M),
                    cam + CAMERA_CLEARANCE_M)
    return np.stack([wa, da]), lo, hi


def sample_room(rng: np.random.Generator, cfg: RoomConfig, eye_xz: np.ndarray,
                camera_yaw_deg: float, behind_m: float = 0.0) -> Room:
    """A room containing the person (at the origin) and the camera at ``eye_xz`` (x, z),
    and ``behind_m`` of floor beyond the person (room for more people).

    The room's depth axis points along the camera's yaw turned by a sampled ``yaw_deg``;
    if that turn leaves no room of the configured size around both, the turn is dropped
    (0: the camera looks along the depth axis, which the config check guarantees fits).
    Sizes are drawn from the part of their range that fits. Always 6 draws from ``rng``.
    """
    jitter, u_w, u_d, u_h, u_x, u_z = rng.uniform(size=6)
    j = cfg.yaw_deg[0] + jitter * (cfg.yaw_deg[1] - cfg.yaw_deg[0])
    eye_xz = np.asarray(eye_xz, np.float64)
    for turn in (j, 0.0):
        theta = np.deg2rad(camera_yaw_deg + turn)
        axes, lo, hi = _spans(theta, eye_xz, behind_m)
        need = hi - lo
        if need[0] <= cfg.width_m[1] and need[1] <= cfg.depth_m[1]:
            break
    else:  # unreachable after the load-time check; a clear message if it ever is
        raise ValueError(f"no room of width {cfg.width_m}, depth {cfg.depth_m} holds the "
                         f"person and a camera at {eye_xz.tolist()}")
    w_lo = max(cfg.width_m[0], need[0])
    d_lo = max(cfg.depth_m[0], need[1])
    width = w_lo + u_w * (cfg.width_m[1] - w_lo)
    depth = d_lo + u_d * (cfg.depth_m[1] - d_lo)
    height = cfg.height_m[0] + u_h * (cfg.height_m[1] - cfg.height_m[0])
    # the room's low edge along each axis, anywhere that keeps both inside
    u0 = (hi[0] - width) + u_x * (lo[0] - (hi[0] - width))
    v0 = (hi[1] - depth) + u_z * (lo[1] - (hi[1] - depth))
    local = np.array([[u0, v0], [u0 + width, v0], [u0 + width, v0 + depth], [u0, v0 + depth]])
    corners = local @ axes  # back to world (x, z): axes rows are orthonormal
    return Room(corners, float(height), float(width), float(depth),
                float(np.rad2deg(theta) - camera_yaw_deg))


def static_geometry(cfg: SceneConfig, room: Room | None) -> tuple[StaticMesh, ...]:
    """The static meshes of a frame: the room's floor and walls, or an open floor."""
    out: list[StaticMesh] = []
    if room is not None:
        if cfg.floor:
            out.append(room_floor(room.corners_xz))
        out.append(room_walls(room.corners_xz, room.height_m))
    elif cfg.floor:
        h = OPEN_FLOOR_HALF_M
        out.append(floor_mesh((-h, h), (-h, h)))
    return tuple(out)
