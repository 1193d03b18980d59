"""Placing people and props on the floor (pure; the scene stream's generator).

Everything stands on the floor, so two objects intersect only if their footprints do;
each footprint is bounded by a circle (:class:`Disc`), and placement keeps the discs
disjoint (and inside the room, and clear of the camera). Every placement draws
``CANDIDATES x tries`` spots at once, screens them for the room and the other discs with
NumPy, asks the costlier ``accept`` test (visibility) of at most ``tries`` feasible ones
in drawing order, and returns None when nothing fits; the caller drops that object and
counts it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from vhgen.scene.room import Room
from vhgen.scene.scene_config import CAMERA_CLEARANCE_M
from vhgen.scene.solids import edge_normals

PLACEMENT_TRIES = 30
CANDIDATES = 8  # spots drawn per try: screened for room and overlap together (cheap),
# only the feasible ones reach the costly accept() test (at most PLACEMENT_TRIES of them)
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


def wall_clearance(room: Room, xz: np.ndarray) -> np.ndarray:
    """(K,) signed distance of (K, 2) floor points to the nearest wall, metres (positive
    inside the room)."""
    sign, edges = room.edges
    return np.min([sign * (ex * (xz[:, 1] - az) - ez * (xz[:, 0] - ax)) / length
                   for ax, az, ex, ez, length in edges], axis=0)


def inside(room: Room | None, d: Disc, gap: float = WALL_GAP_M) -> bool:
    """Whether the disc lies inside the room's floor with ``gap`` to every wall (no room:
    always)."""
    return room is None or bool(wall_clearance(room, np.array([[d.x, d.z]]))[0]
                                >= d.r + gap)


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


def all_visible(eye_xz: np.ndarray, discs: list[Disc], targets: int,
                min_visible: float, samples: int = 64) -> bool:
    """Whether each of the first ``targets`` of ``discs`` keeps at least ``min_visible``
    of its width in view past all the other discs: ``all(visible_fraction(eye_xz, t,
    [o for o in discs if o is not t]) >= min_visible for t in discs[:targets])`` in one
    compiled call (:mod:`vhgen.scene.placement_kernels`)."""
    from vhgen.scene.placement_kernels import all_visible as kernel

    rows = np.array([(d.x, d.z, d.r) for d in discs], np.float64).reshape(-1, 3)
    return bool(kernel(float(eye_xz[0]), float(eye_xz[1]), rows, targets,
                       float(min_visible), samples))


def _free_many(xz: np.ndarray, radius: float, others: list[Disc],
               room: Room | None) -> np.ndarray:
    """Which of the (K, 2) candidate centres give a disc of ``radius`` inside the room
    (:func:`inside`) and at least GAP_M from every disc of ``others``: (K,) bool."""
    ok = np.ones(len(xz), bool)
    if room is not None:
        ok &= wall_clearance(room, xz) >= radius + WALL_GAP_M
    for o in others:
        ok &= np.hypot(xz[:, 0] - o.x, xz[:, 1] - o.z) >= radius + o.r + GAP_M
    return ok


def is_free(d: Disc, others: list[Disc], room: Room | None) -> bool:
    """Whether the disc ``d`` is inside the room and GAP_M from every disc of ``others``
    (:func:`_free_many` for one disc)."""
    return bool(_free_many(np.array([[d.x, d.z]]), d.r, others, room)[0])


def _first_accepted(xz: np.ndarray, feasible: np.ndarray, radius: float,
                    accept: Callable[[Disc], bool] | None, tries: int) -> Disc | None:
    """The first candidate, in drawing order, that is feasible and passes ``accept``;
    ``accept`` (the costly test) is asked at most ``tries`` times."""
    for k in np.flatnonzero(feasible)[:tries]:
        d = Disc(float(xz[k, 0]), float(xz[k, 1]), radius)
        if accept is None or accept(d):
            return d
    return None


def place_in_view(rng: np.random.Generator, eye_xz: np.ndarray, forward_xz: np.ndarray,
                  half_fov_rad: float, distance_m: tuple[float, float], radius: float,
                  others: list[Disc], room: Room | None,
                  accept: Callable[[Disc], bool] | None = None,
                  tries: int = PLACEMENT_TRIES) -> Disc | None:
    """A footprint of ``radius`` whose whole circle is inside the horizontal field of view,
    at a distance from the camera in ``distance_m``, free of ``others``, in the room, and
    passing ``accept``. ``CANDIDATES x tries`` spots are drawn at once (uniform in
    distance and bearing) and screened together; ``accept`` sees at most ``tries``."""
    base = np.arctan2(forward_xz[0], forward_xz[1])
    u = rng.uniform(size=(CANDIDATES * tries, 2))
    dist = distance_m[0] + u[:, 0] * (distance_m[1] - distance_m[0])
    margin = np.arcsin(np.minimum(1.0, radius / np.maximum(dist, 1e-9)))
    bearing = base + (2 * u[:, 1] - 1) * (half_fov_rad - margin)
    xz = np.column_stack([eye_xz[0] + dist * np.sin(bearing),
                          eye_xz[1] + dist * np.cos(bearing)])
    feasible = (margin < half_fov_rad) & _free_many(xz, radius, others, room)
    return _first_accepted(xz, feasible, radius, accept, tries)


@dataclass(frozen=True, eq=False)
class Beside:
    """Where :func:`place_beside` put a person: the footprint (its circle's centre moved),
    the heading it stands at, the end of the line it joined (0 left, 1 right) and its
    outline there."""

    disc: Disc
    heading: float
    side: int
    outline: np.ndarray


def floor_outline(xz: np.ndarray) -> np.ndarray:
    """The convex hull (K, 2), counter-clockwise, of floor points ``xz`` (N, 2) (qhull:
    about 3 ms for a skinned body's 15,000 points)."""
    from scipy.spatial import ConvexHull

    xz = np.asarray(xz, np.float64)
    return np.ascontiguousarray(xz[ConvexHull(xz).vertices])


def turned(shape: np.ndarray, heading: float) -> np.ndarray:
    """(..., 2) floor points (x, z) turned about the origin as :func:`yaw_transform`
    turns them."""
    c, s = math.cos(heading), math.sin(heading)
    return np.stack([c * shape[..., 0] + s * shape[..., 1],
                     -s * shape[..., 0] + c * shape[..., 1]], -1)


def place_beside(rng: np.random.Generator, eye_xz: np.ndarray, forward_xz: np.ndarray,
                 half_fov_rad: float, ends: tuple[tuple[Disc, np.ndarray], ...],
                 across: np.ndarray, shape: np.ndarray, radius: float,
                 facing: Callable[[np.ndarray], float], gap_m: tuple[float, float],
                 depth_m: float, people: list[np.ndarray], others: list[Disc],
                 room: Room | None, accept: Callable[[Disc], bool] | None = None,
                 steps: int = 32) -> Beside | None:
    """A person standing beside one end of a line of people, as close as their bodies
    allow.

    ends : the line's left and right end, each a person's footprint and outline (the
        first person's to begin with); across : the line's unit floor direction from
        left to right; shape : the new person's outline (K, 2) about its footprint
        centre at heading 0, and radius its footprint circle's; facing : the heading the
        person stands at, given its centre; people : the outlines of everyone placed;
        others : the circles of everything else (the camera).

    The person is moved out from the end's centre along the line (and up to
    ``depth_m`` along the line of sight) to the first of ``steps`` distances where its
    outline keeps a gap drawn in ``gap_m`` from every outline of ``people`` (separating
    axes), at most to where the footprint circles are that far apart; then its outline
    must be inside the horizontal field of view, its circle free of ``others`` and in
    the room, and it must pass ``accept``. Draws three numbers (the end first tried, the
    gap, the move); the other end is tried when the first has no room. None when neither
    has."""
    u = rng.uniform(size=3)
    first = int(u[0] < 0.5)
    gap = gap_m[0] + u[1] * (gap_m[1] - gap_m[0])
    for side in (first, 1 - first):
        end = ends[side][0]
        sign = 1.0 if side else -1.0
        reach = end.r + radius + gap
        far = np.array([end.x, end.z]) + sign * reach * across
        sight = far - eye_xz
        move = (2 * u[2] - 1) * depth_m * sight / max(float(np.hypot(*sight)), 1e-9)
        heading = facing(far + move)
        out = turned(shape, heading)
        s = np.linspace(0.0, reach, steps + 1)
        centres = (np.array([end.x, end.z]) + move)[None] + sign * s[:, None] * across
        ok = np.ones(len(s), bool)
        for q in people:
            ok &= _clear_of(out, centres, q, radius, gap)
        if not ok.any():
            continue
        k = int(np.argmax(ok))
        d = Disc(float(centres[k, 0]), float(centres[k, 1]), radius)
        poly = out + centres[k]
        if (_outline_in_view(eye_xz, forward_xz, half_fov_rad, poly)
                and bool(_free_many(centres[k][None], radius, others, room)[0])
                and (accept is None or accept(d))):
            return Beside(d, heading, side, poly)
    return None


def _clear_of(shape: np.ndarray, centres: np.ndarray, q: np.ndarray, radius: float,
              gap: float) -> np.ndarray:
    """(K,) bool: the convex polygon ``shape`` (P, 2, about the origin, within
    ``radius`` of it) moved to each of ``centres`` (K, 2) lies at least ``gap`` from the
    convex polygon ``q`` (Q, 2) along one of their edge normals (the separating-axis test
    of :func:`vhgen.scene.solids.separated`; the moved polygons share their normals, so
    each axis is projected once). Centres whose circle clears ``q``'s circle need no
    axes."""
    cq = q.mean(0)
    far = np.hypot(*(centres - cq).T) >= radius + float(np.hypot(*(q - cq).T).max()) + gap
    if far.all():
        return far
    axes = np.concatenate([edge_normals(shape), edge_normals(q)])
    axes = axes[(axes != 0).any(1)]  # a repeated corner's edge proves nothing
    ps, pq, pc = shape @ axes.T, q @ axes.T, centres @ axes.T  # (P, A), (Q, A), (K, A)
    apart = ((ps.min(0) + pc - pq.max(0) >= gap) | (pq.min(0) - ps.max(0) - pc >= gap))
    return far | apart.any(1)


def _outline_in_view(eye_xz: np.ndarray, forward_xz: np.ndarray, half_fov_rad: float,
                     outline: np.ndarray) -> bool:
    """Whether every point of a floor outline (K, 2) lies in front of the camera inside
    the horizontal field of view."""
    d = outline - eye_xz
    off = np.arctan2(d[:, 0], d[:, 1]) - math.atan2(float(forward_xz[0]), float(forward_xz[1]))
    off = (off + np.pi) % (2 * np.pi) - np.pi
    return bool((np.abs(off) <= half_fov_rad).all() and (d @ forward_xz > 0).all())


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
    u = rng.uniform(size=(CANDIDATES * tries, 2))
    t = lo + u[:, 0] * (hi - lo)
    # off the line by up to the target's radius: partial, not always central, cover
    side = (2 * u[:, 1] - 1) * target.r
    n = np.array([to[1], -to[0]]) / length
    xz = eye_xz + np.outer(t, to / length) + np.outer(side, n)
    feasible = _free_many(xz, radius, [target, *others], room)
    return _first_accepted(xz, feasible, radius, accept, tries)


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
    xz = lo + rng.uniform(size=(CANDIDATES * tries, 2)) * (hi - lo)
    feasible = _free_many(xz, radius, [cam, *others], room)
    return _first_accepted(xz, feasible, radius, accept, tries)


def yaw_transform(yaw_rad: float, x: float, z: float, y: float = 0.0) -> np.ndarray:
    """(4, 4) float64: rotate about +y by ``yaw_rad``, then translate to (x, y, z)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, 0, s, x], [0, 1, 0, y], [-s, 0, c, z], [0, 0, 0, 1.0]])
