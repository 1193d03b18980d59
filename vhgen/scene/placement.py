"""Placing people and props on the floor (pure; the scene stream's generator).

Everything stands on the floor, so two objects intersect only if their footprints do;
each footprint is bounded by a circle (:class:`Disc`), and placement keeps the discs
disjoint (and inside the room, and clear of the camera). Every placement tries at most
``tries`` times and returns None when nothing fits; the caller drops that object and
counts it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from vhgen.scene.config import CAMERA_CLEARANCE_M
from vhgen.scene.room import Room

PLACEMENT_TRIES = 30
GAP_M = 0.05  # free space kept between two footprints
WALL_GAP_M = 0.05
MIN_PROP_RANGE_M = 1.2  # a prop nearer the camera than this would fill the view
TALL_PROP_M = 1.2  # props at least this tall can hide a whole person (doors)


@dataclass(frozen=True)
class Disc:
    """A footprint circle on the floor: centre (x, z) and radius, metres."""

    x: float
    z: float
    r: float

    def clear_of(self, other: Disc, gap: float = GAP_M) -> bool:
        # math, not NumPy: called thousands of times per frame on Python floats
        return math.hypot(self.x - other.x, self.z - other.z) >= self.r + other.r + gap


def inside(room: Room | None, d: Disc, gap: float = WALL_GAP_M) -> bool:
    """Whether the disc lies inside the room's floor with ``gap`` to every wall (no room:
    always)."""
    if room is None:
        return True
    sign, edges = room.edges
    for ax, az, ex, ez, length in edges:
        if sign * (ex * (d.z - az) - ez * (d.x - ax)) / length < d.r + gap:
            return False
    return True


def free(d: Disc, others: list[Disc], room: Room | None) -> bool:
    return inside(room, d) and all(d.clear_of(o) for o in others)


def visible_fraction(eye_xz: np.ndarray, target: Disc, occluders: list[Disc],
                     samples: int = 64) -> float:
    """The fraction of ``target``'s angular width, seen from the camera, not covered by
    the angular width of a nearer occluder (a floor-plan bound on how much of a standing
    person stays in view: occluders are treated as tall as the target)."""
    def interval(d: Disc) -> tuple[float, float, float]:
        dx, dz = d.x - ex, d.z - ez
        dist = math.hypot(dx, dz)
        half = math.asin(min(1.0, d.r / max(dist, 1e-9)))
        return math.atan2(dx, dz), half, dist

    ex, ez = float(eye_xz[0]), float(eye_xz[1])

    tc, th, tdist = interval(target)
    angles = tc + np.linspace(-th, th, samples)
    covered = np.zeros(samples, bool)
    for o in occluders:
        oc, oh, odist = interval(o)
        if odist >= tdist:
            continue
        diff = np.angle(np.exp(1j * (angles - oc)))  # wrapped to (-pi, pi]
        covered |= np.abs(diff) <= oh
    return float(1.0 - covered.mean())


def place_in_view(rng: np.random.Generator, eye_xz: np.ndarray, forward_xz: np.ndarray,
                  half_fov_rad: float, distance_m: tuple[float, float], radius: float,
                  others: list[Disc], room: Room | None,
                  accept: Callable[[Disc], bool] | None = None,
                  tries: int = PLACEMENT_TRIES) -> Disc | None:
    """A footprint of ``radius`` whose whole circle is inside the horizontal field of view,
    at a distance from the camera in ``distance_m``, free of ``others``, in the room, and
    passing ``accept``."""
    base = np.arctan2(forward_xz[0], forward_xz[1])
    for _ in range(tries):
        u_d, u_b = rng.uniform(size=2)
        dist = distance_m[0] + u_d * (distance_m[1] - distance_m[0])
        margin = np.arcsin(min(1.0, radius / max(dist, 1e-9)))
        if margin >= half_fov_rad:
            continue
        bearing = base + (2 * u_b - 1) * (half_fov_rad - margin)
        d = Disc(float(eye_xz[0] + dist * np.sin(bearing)),
                 float(eye_xz[1] + dist * np.cos(bearing)), radius)
        if free(d, others, room) and (accept is None or accept(d)):
            return d
    return None


def place_between(rng: np.random.Generator, eye_xz: np.ndarray, target: Disc, radius: float,
                  others: list[Disc], room: Room | None,
                  accept: Callable[[Disc], bool] | None = None,
                  tries: int = PLACEMENT_TRIES) -> Disc | None:
    """A footprint on the line of sight from the camera to ``target`` (so it hides part
    of it), clear of the target, the camera and ``others``."""
    to = np.array([target.x, target.z]) - eye_xz
    length = float(np.hypot(*to))
    lo = MIN_PROP_RANGE_M + radius
    hi = length - target.r - radius - GAP_M
    if hi <= lo:
        return None
    for _ in range(tries):
        u_t, u_s = rng.uniform(size=2)
        t = lo + u_t * (hi - lo)
        # off the line by up to the target's radius: partial, not always central, cover
        side = (2 * u_s - 1) * target.r
        n = np.array([to[1], -to[0]]) / length
        p = eye_xz + to / length * t + n * side
        d = Disc(float(p[0]), float(p[1]), radius)
        if free(d, [target, *others], room) and (accept is None or accept(d)):
            return d
    return None


def place_anywhere(rng: np.random.Generator, eye_xz: np.ndarray, radius: float,
                   others: list[Disc], room: Room | None, spread_m: float = 4.0,
                   accept: Callable[[Disc], bool] | None = None,
                   tries: int = PLACEMENT_TRIES) -> Disc | None:
    """A footprint anywhere on the room's floor (no room: within ``spread_m`` of the
    origin), clear of the camera and ``others``."""
    cam = Disc(float(eye_xz[0]), float(eye_xz[1]), CAMERA_CLEARANCE_M + MIN_PROP_RANGE_M)
    if room is not None:
        lo, hi = room.corners_xz.min(0), room.corners_xz.max(0)
    else:
        lo, hi = np.array([-spread_m, -spread_m]), np.array([spread_m, spread_m])
    for _ in range(tries):
        u = rng.uniform(size=2)
        p = lo + u * (hi - lo)
        d = Disc(float(p[0]), float(p[1]), radius)
        if free(d, [cam, *others], room) and (accept is None or accept(d)):
            return d
    return None


def yaw_transform(yaw_rad: float, x: float, z: float, y: float = 0.0) -> np.ndarray:
    """(4, 4) float64: rotate about +y by ``yaw_rad``, then translate to (x, y, z)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, 0, s, x], [0, 1, 0, y], [-s, 0, c, z], [0, 0, 0, 1.0]])
