"""Placing clutter in a room: against walls, in corners, on walls and on the floor (pure).

The frame's items are drawn first (kind by weight, fewer repeats of a kind; parameters
and mesh: :mod:`vhgen.scene.clutter.items`) and placed largest first, as furniture comes
before the things between it. For each, :data:`CANDIDATES` placements are drawn at once,
each in one of the modes of its kind's record (:mod:`vhgen.scene.clutter.kinds`): ``wall``:
its back :data:`FLUSH_M` off a wall, centred on a stretch of wall the camera sees and no
obstacle takes (:meth:`_Frame.wall_cdf`); ``corner``: the same, moved to the nearer end of
that wall; ``floor``: anywhere in the camera's view, any heading. They are screened together:
the footprints (:class:`~vhgen.scene.solids.Solid`, one per part of the item) inside the
room, the item no higher than the walls (unless its record says it pierces the ceiling:
stairs to an upper floor), at
least :data:`VISIBLE_SHARE` of its bearings inside the camera's horizontal view and its
nearest point :data:`MIN_RANGE_M` from the camera (clutter goes where the camera sees it,
so ``count`` is what a frame shows), and apart from everything placed before (people and
props by their circles, the camera, other clutter). An item that hides people
(:data:`HIDES_ABOVE_M`) must also leave every person ``min_visible_fraction`` of its width
in view. The first candidate that passes, in drawing order, is taken; an item with none is
left out and counted (``dropped["clutter"]``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from vhgen.scene.clutter.items import ClutterShape, build, sample_params, variant
from vhgen.scene.clutter.kinds import KINDS, PLACEMENT_MODES
from vhgen.scene.description import PlacedClutter
from vhgen.scene.geometry import StaticMesh
from vhgen.scene.placement import WALL_GAP_M, Disc
from vhgen.scene.room import Room
from vhgen.scene.scene_config import SceneConfig
from vhgen.scene.solids import DISC_SIDES, Solid

CANDIDATES = 48  # placements drawn per item, screened together
TRIES = 30  # at most this many reach the visibility test
WALL_CELLS = 32  # cells per wall to draw wall spots from, those in view
FLOOR_REACH_M = 7.0  # floor spots: up to this far from the camera
VISIBLE_SHARE = 0.3  # of an item's bearings inside the camera's horizontal view
FLUSH_M = 0.005  # a wall item's back off the wall: no coplanar faces
CORNER_GAP_M = 0.01  # a corner item's side off the next wall
CLUTTER_GAP_M = 0.02  # between two clutter items (people and props keep GAP_M)
MIN_RANGE_M = 1.0  # nearest point of an item from the camera
# clutter at least this tall, from below HIDES_FROM_M, hides a standing person (bookcases,
# stairs, doors, lamps, plants, curtains); lower clutter (a desk and its monitor, a
# cabinet) hides at most legs and hips, as props under TALL_PROP_M do
HIDES_ABOVE_M = 1.5
HIDES_FROM_M = 1.0

# where each wall cell starts / ends and its middle, as fractions of the wall (C + 1,), (C,)
_CELL_ENDS = np.arange(WALL_CELLS + 1) / WALL_CELLS
_CELL_MIDS = (np.arange(WALL_CELLS) + 0.5) / WALL_CELLS
# the compiled candidates sum the cells' weights as NumPy does up to 128 values
# (place_kernels.PAIRWISE_MAX)
assert 4 * WALL_CELLS <= 128
_CELL_ENDS.setflags(write=False)
_CELL_MIDS.setflags(write=False)
# The hot loops' reductions as ufuncs: the arithmetic of the ndarray methods (x.min(1) is
# _min(x, 1); x.mean(1) is _sum(x, 1) / n) without their Python wrappers, a few
# microseconds a call and hundreds of calls a frame.
_min, _max, _sum = np.minimum.reduce, np.maximum.reduce, np.add.reduce
_any, _all = np.logical_or.reduce, np.logical_and.reduce


@dataclass(frozen=True)
class WallFrame:
    """Wall k of a room (corner k to k + 1): start ``a`` (x, z), unit direction ``e``,
    inward normal ``n``, ``length``; ``yaw``: the heading (radians, about +y) that turns
    an item's own +z onto ``n``; ``sign``: +1 when the item's own +x runs along ``e``."""

    a: np.ndarray
    e: np.ndarray
    n: np.ndarray
    length: float
    yaw: float
    sign: float


def wall_frames(room: Room) -> tuple[WallFrame, ...]:
    """The room's four walls as :class:`WallFrame` s."""
    c = room.corners_xz
    mid = c.mean(0)
    out = []
    for k in range(4):
        a, b = c[k], c[(k + 1) % 4]
        length = float(np.hypot(*(b - a)))
        e = (b - a) / length
        n = np.array([-e[1], e[0]])
        if (mid - a) @ n < 0:
            n = -n
        yaw = math.atan2(n[0], n[1])
        u = np.array([math.cos(yaw), -math.sin(yaw)])  # the item's +x in the world
        out.append(WallFrame(a, e, n, length, yaw, float(np.sign(u @ e))))
    return tuple(out)


@dataclass(frozen=True, eq=False)
class Obstacle:
    """Something clutter must keep clear of: its solid and the gap it asks for."""

    solid: Solid
    gap: float


@dataclass(frozen=True, eq=False)
class ClutterLayout:
    """What :func:`place_clutter` placed: the items, their meshes (world, classes per
    face), the wall openings (wall -> [(s0, s1, y0, y1)]), how many items found no place,
    and the footprints of what it placed (all, and per item)."""

    items: tuple[PlacedClutter, ...]
    meshes: tuple[StaticMesh, ...]
    openings: dict[int, list[tuple[float, float, float, float]]]
    dropped: int
    item_solids: tuple[tuple[Solid, ...], ...]

    @property
    def solids(self) -> tuple[Solid, ...]:
        """Every item's footprints, in order."""
        return tuple(s for item in self.item_solids for s in item)


def _rotate(yaw: np.ndarray, xz: np.ndarray) -> np.ndarray:
    """(K, P, 2): local floor points (P, 2) turned by each yaw (K,) (the convention of
    :func:`~vhgen.scene.placement.yaw_transform`)."""
    return _turn(np.cos(yaw)[:, None], np.sin(yaw)[:, None], xz)


def _turn(c: np.ndarray, s: np.ndarray, xz: np.ndarray,
          origin: np.ndarray | None = None) -> np.ndarray:
    """:func:`_rotate` by the yaws of cosines ``c`` and sines ``s`` (K, 1), then moved
    by ``origin`` (K, 2) if given."""
    out = np.empty((len(c), len(xz), 2))
    np.add(c * xz[:, 0], s * xz[:, 1], out=out[..., 0])
    np.add(-s * xz[:, 0], c * xz[:, 1], out=out[..., 1])
    if origin is not None:
        out += origin[:, None, :]
    return out


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


class _Frame:
    """The frame's placement state: walls, where the camera looks, the obstacles as
    padded arrays (filled in as items are placed: ``capacity`` is how many solids the
    frame's items may add), and how much of each person the obstacles placed so far
    already hide."""

    def __init__(self, room: Room, eye: np.ndarray, forward: np.ndarray, half_fov: float,
                 obstacles: list[Obstacle], people: list[Disc], tall_discs: list[Disc],
                 min_visible: float, capacity: int = 0):
        self.room, self.eye, self.half_fov = room, np.asarray(eye, np.float64), half_fov
        self.base = math.atan2(forward[0], forward[1])
        self.walls = wall_frames(room)
        self.min_visible = min_visible
        self.wall_a = np.stack([w.a for w in self.walls])
        self.wall_e = np.stack([w.e for w in self.walls])
        self.wall_n = np.stack([w.n for w in self.walls])
        # wall cells whose middle the camera sees (or nearly: items at the edge of the view)
        lengths = np.array([w.length for w in self.walls])
        mids = (self.wall_a[:, None]
                + (_CELL_MIDS[None, :, None] * lengths[:, None, None]) * self.wall_e[:, None])
        d = mids - self.eye
        seen = np.abs(_wrap(np.arctan2(d[..., 0], d[..., 1]) - self.base)) <= half_fov + 0.15
        weight = seen * lengths[:, None]
        if not weight.any():
            weight = np.broadcast_to(lengths[:, None], seen.shape).copy()
        self.seen_weight = weight
        self.lengths = lengths
        self.cells = _CELL_ENDS * lengths[:, None]  # (4, C + 1)
        self.wall_yaw = np.array([w.yaw for w in self.walls])
        self.wall_sign = np.array([w.sign for w in self.walls])
        # each wall's offset along its normal and along itself (wall_cdf's distances)
        self.wall_off = (self.wall_n * self.wall_a).sum(1)
        self.wall_start = (self.wall_e * self.wall_a).sum(1)
        # signed distance to each wall as one product: [x, z, 1] @ planes, (3, 4)
        self.planes = np.ascontiguousarray(np.vstack([self.wall_n.T, -self.wall_off]))
        self.wall_flush = FLUSH_M * self.wall_n  # a wall item's origin off its wall
        # the obstacles, rows 0 .. count - 1 of arrays sized for the frame's items
        # (polys, normals, boxes, heights and gaps are views of those rows)
        self.count = 0
        self._rows(len(obstacles) + max(capacity, 1))
        self.add([o.solid for o in obstacles], [o.gap for o in obstacles])
        # people: sample bearings across each one's width, and what already hides them
        self.people = people
        self.samples = np.zeros((len(people), 64))
        self.dist = np.zeros(len(people))
        self.covered = np.zeros((len(people), 64), bool)
        for i, t in enumerate(people):
            dx, dz = t.x - self.eye[0], t.z - self.eye[1]
            tdist = math.hypot(dx, dz)
            half = math.asin(min(1.0, t.r / max(tdist, 1e-9)))
            self.samples[i] = math.atan2(dx, dz) + np.linspace(-half, half, 64)
            self.dist[i] = tdist
            for o in people + tall_discs:  # as placement.visible_fraction counts them
                if o is not t:
                    ox, oz = o.x - self.eye[0], o.z - self.eye[1]
                    odist = math.hypot(ox, oz)
                    if odist < tdist:
                        oh = math.asin(min(1.0, o.r / max(odist, 1e-9)))
                        rel = _wrap(self.samples[i] - math.atan2(ox, oz))
                        self.covered[i] |= np.abs(rel) <= oh

    def _rows(self, n: int) -> None:
        """Arrays for ``n`` obstacles in all (polys, normals, boxes, heights, gaps), the
        rows so far copied over."""
        m = self.count
        rows = (np.zeros((n, DISC_SIDES, 2)), np.zeros((n, DISC_SIDES, 2)), np.zeros((n, 4)),
                np.zeros((n, 2)), np.zeros(n))
        for new, old in zip(rows, getattr(self, "_all_rows", ()), strict=False):
            new[:m] = old[:m]
        self._all_rows = rows
        self._views()

    def _views(self) -> None:
        self.polys, self.normals, self.boxes, self.heights, self.gaps = (
            a[:self.count] for a in self._all_rows)

    def wall_cdf(self, width: float, depth: float, y0: float, y1: float) -> np.ndarray | None:
        """(4 * C,) cumulative weights of the wall cells an item of ``width`` (along the
        wall), ``depth`` (from it) and heights [y0, y1] may be centred in: cells the camera
        sees, whose stretch of wall (widened by half the item) no obstacle within the
        item's depth of that wall takes. None if there is none."""
        sel = (self.heights[:, 0] < y1) & (self.heights[:, 1] > y0)
        weight = self.seen_weight
        if _any(sel):
            p, g = self.polys[sel], self.gaps[sel]
            dist = np.einsum("mpd,kd->kmp", p, self.wall_n) - self.wall_off[:, None, None]
            along = (np.einsum("mpd,kd->kmp", p, self.wall_e)
                     - self.wall_start[:, None, None])
            near = _min(dist, 2) < depth + g  # (4, M)
            s0, s1 = _min(along, 2) - g, _max(along, 2) + g
            lo, hi = self.cells[:, :-1] - width / 2, self.cells[:, 1:] + width / 2  # (4, C)
            blocked = _any(near[:, None] & (s0[:, None] < hi[..., None])
                           & (s1[:, None] > lo[..., None]), 2)
            weight = weight * ~blocked
        total = weight.sum()
        return None if total <= 0 else np.cumsum(weight.ravel()) / total

    def add(self, solids: list[Solid], gaps: list[float]) -> None:
        """Obstacles placed: padded to :data:`DISC_SIDES` corners (repeated corners give
        zero-length edges, which the separating-axis test ignores)."""
        m = self.count
        if m + len(solids) > len(self._all_rows[0]):
            self._rows(2 * (m + len(solids)))
        polys, normals, boxes, heights, all_gaps = self._all_rows
        for j, (s, gap) in enumerate(zip(solids, gaps, strict=True), m):
            p = len(s.poly)
            polys[j, :p] = s.poly
            polys[j, p:] = s.poly[-1]
            normals[j, :p] = s.normals  # the padding's normals stay zero
            boxes[j] = s.box
            heights[j] = s.y0, s.y1
            all_gaps[j] = gap
        self.count = m + len(solids)
        self._views()

    def hide(self, polys: list[np.ndarray], ranges: list[float]) -> None:
        """Tall footprints placed, their nearest points ``ranges`` from the camera: they
        hide, from now on, the people they are nearer than (the bearings within their
        angular span)."""
        for poly, near in zip(polys, ranges, strict=True):
            closer = near < self.dist
            if not _any(closer):
                continue
            d = poly - self.eye
            mid = math.atan2(*(_sum(d, 0) / len(d)))
            a = _wrap(np.arctan2(d[:, 0], d[:, 1]) - mid)
            rel = _wrap(self.samples[closer] - mid)
            self.covered[closer] |= (rel >= _min(a)) & (rel <= _max(a))

    def visible(self, polys: list[np.ndarray], ranges: list[np.ndarray]) -> np.ndarray:
        """(K,) bool: every person keeps ``min_visible`` of its width past what hides it
        already and candidate k's tall footprints polys[j][k] (K, P, 2) for every j, their
        nearest points ranges[j][k] from the camera."""
        k = len(polys[0])
        if not k or not len(self.people):
            return np.ones(k, bool)
        cover = np.repeat(self.covered[:, None], k, 1)  # (people, K, 64)
        for p, near in zip(polys, ranges, strict=True):
            d = p - self.eye
            n = d.shape[1]
            mid = np.arctan2(_sum(d[..., 0], 1) / n, _sum(d[..., 1], 1) / n)
            a = _wrap(np.arctan2(d[..., 0], d[..., 1]) - mid[:, None])
            nearer = near[None] < self.dist[:, None]  # (people, K)
            rel = _wrap(self.samples[:, None] - mid[:, None])  # (people, K, 64)
            cover |= ((rel >= _min(a, 1)[:, None]) & (rel <= _max(a, 1)[:, None])
                      & nearer[..., None])
        return _all(1.0 - cover.mean(2) >= self.min_visible, 0)


def _distance(eye: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """(K,) distance from ``eye`` (2,) to each convex polygon (K, P, 2) (0 inside)."""
    a = polys
    b = np.concatenate([polys[:, 1:], polys[:, :1]], 1)
    ab = b - a
    ea = eye - a
    # the products' sums over x and z written out: the same two-term sums as .sum(-1)
    abx, abz, eax, eaz = ab[..., 0], ab[..., 1], ea[..., 0], ea[..., 1]
    t = np.clip((eax * abx + eaz * abz) / np.maximum(abx * abx + abz * abz, 1e-18), 0.0, 1.0)
    q = a + t[..., None] * ab - eye
    qx, qz = q[..., 0], q[..., 1]
    d = _min(np.sqrt(qx * qx + qz * qz), 1)
    cross = abx * eaz - abz * eax
    inside = _all(cross >= 0, 1) | _all(cross <= 0, 1)
    return np.where(inside, 0.0, d)


def _candidates(rng: np.random.Generator, shape: ClutterShape, fr: _Frame
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:data:`CANDIDATES` placements: yaw (K,), origin (K, 2), mode index (K,) into the
    kind's modes, wall (K,) (-1 on the floor), and whether each is possible (K,). Wall
    spots are drawn where the camera looks; corners at the end of the wall nearer to a
    drawn spot; floor spots in the camera's view. :func:`_candidates_reference`'s values
    bit for bit, from :func:`vhgen.scene.clutter.place_kernels.candidates` (NumPy still
    takes the sines and cosines)."""
    from vhgen.scene.clutter.place_kernels import candidates

    u = rng.uniform(size=(CANDIDATES, 5))
    mode_cdf, mode_places = _MODE_CDF[shape.kind]
    x0, x1 = shape.x_extent
    bearing = fr.base + (2 * u[:, 2] - 1) * fr.half_fov
    fyaw = u[:, 4] * 2 * np.pi
    yaw, origin = np.empty(CANDIDATES), np.empty((CANDIDATES, 2))
    mode, wall = np.empty(CANDIDATES, np.int64), np.empty(CANDIDATES, np.int64)
    ok = np.empty(CANDIDATES, bool)
    candidates(u, mode_cdf, mode_places, x0, x1, float(shape.inner_box[1, 1]),
               *shape.inner_heights, shape.centre, fyaw, np.cos(fyaw), np.sin(fyaw),
               np.sin(bearing), np.cos(bearing), fr.seen_weight, fr.cells, fr.lengths,
               fr.wall_a, fr.wall_e, fr.wall_n, fr.wall_off, fr.wall_start, fr.wall_yaw,
               fr.wall_sign, fr.wall_flush, fr.eye, fr.polys, fr.heights, fr.gaps,
               CORNER_GAP_M, MIN_RANGE_M, FLOOR_REACH_M, _NOWHERE, _CORNER, _FLOOR,
               yaw, origin, mode, wall, ok)
    return yaw, origin, mode, wall, ok


def _candidates_reference(rng: np.random.Generator, shape: ClutterShape, fr: _Frame
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                     np.ndarray]:
    """:func:`_candidates` as NumPy arrays (the reference the compiled one is tested
    against)."""
    u = rng.uniform(size=(CANDIDATES, 5))
    mode_cdf, mode_places = _MODE_CDF[shape.kind]
    mode = np.minimum(np.searchsorted(mode_cdf, u[:, 0], side="right"), len(mode_cdf) - 1)
    place = mode_places[mode]
    x0, x1 = shape.x_extent
    cdf = fr.wall_cdf(x1 - x0, float(shape.inner_box[1, 1]), *shape.inner_heights)
    if cdf is None:  # no free wall in view: only floor spots can work
        cdf = np.cumsum(fr.seen_weight.ravel()) / fr.seen_weight.sum()
        place = np.where(place == _FLOOR, place, _NOWHERE)
    cell = np.minimum(np.searchsorted(cdf, u[:, 1], side="right"), 4 * WALL_CELLS - 1)
    wall, cell = np.divmod(cell, WALL_CELLS)
    length = fr.lengths[wall]
    spot = (cell + u[:, 2]) / WALL_CELLS * length
    sign = fr.wall_sign[wall]
    off0, off1 = sign * x0, sign * x1
    lo_off, hi_off = np.minimum(off0, off1), np.maximum(off0, off1)
    s_lo = CORNER_GAP_M - lo_off
    s_hi = length - CORNER_GAP_M - hi_off
    # the item's middle on the spot, moved along the wall to fit
    s = np.clip(spot - (lo_off + hi_off) / 2, s_lo, s_hi)
    corner = place == _CORNER
    if _any(corner):
        s = np.where(corner, np.where(spot < length / 2, s_lo, s_hi), s)
    yaw = fr.wall_yaw[wall]
    origin = fr.wall_a[wall] + s[:, None] * fr.wall_e[wall] + fr.wall_flush[wall]
    ok = (s_hi >= s_lo) & (place != _NOWHERE)
    on_floor = place == _FLOOR
    if on_floor.any():
        dist = MIN_RANGE_M + u[:, 3] * (FLOOR_REACH_M - MIN_RANGE_M)
        bearing = fr.base + (2 * u[:, 2] - 1) * fr.half_fov
        at = fr.eye + dist[:, None] * np.column_stack([np.sin(bearing), np.cos(bearing)])
        fyaw = u[:, 4] * 2 * np.pi
        origin = np.where(on_floor[:, None], at - _rotate(fyaw, shape.centre[None])[:, 0],
                          origin)
        yaw = np.where(on_floor, fyaw, yaw)
        wall = np.where(on_floor, -1, wall)
        ok |= on_floor
    return yaw, origin, mode, wall, ok


def place_clutter(rng: np.random.Generator, sc: SceneConfig, room: Room, eye: np.ndarray,
                  forward: np.ndarray, half_fov: float, obstacles: list[Obstacle],
                  people: list[Disc], tall_discs: list[Disc],
                  library_seed: int = 0) -> ClutterLayout:
    """Draw and place the frame's clutter (see the module docstring).

    eye, forward : the camera's floor position (x, z) and unit view direction;
    half_fov : half the horizontal field of view, radians; obstacles : what is placed
    already; people : every person's footprint, kept visible; tall_discs : props that
    hide people (as in :func:`vhgen.scene.layout.layout_scene`); library_seed : the seed
    of the job's variants of each kind (see :func:`vhgen.scene.clutter.items.variant`).
    """
    cfg = sc.clutter
    assert cfg is not None
    n_items = int(rng.integers(cfg.count[0], cfg.count[1] + 1))
    weights = np.array(cfg.weights, np.float64)
    repeat, same = _repeats(cfg.kinds)
    roles = sc.clutter_roles
    items: list[PlacedClutter] = []
    meshes: list[StaticMesh] = []
    openings: dict[int, list[tuple[float, float, float, float]]] = {}
    item_solids: list[tuple[Solid, ...]] = []
    dropped = 0
    drawn = []
    for _ in range(n_items):
        cum = np.cumsum(weights)
        pick = min(int(np.searchsorted(cum / cum[-1], rng.uniform(), side="right")),
                   len(cfg.kinds) - 1)
        kind = cfg.kinds[pick]
        weights = np.where(same[pick], weights * repeat, weights)  # fewer repeats
        if cfg.variants:
            shape = variant(kind, cfg.fill, library_seed, int(rng.integers(cfg.variants)))
        else:
            shape = build(kind, sample_params(kind, rng, float(rng.uniform(*cfg.fill))))
        drawn.append((pick, shape))
    # the largest footprints first, as furniture comes before the things between it
    drawn.sort(key=lambda d: -_floor_area(d[1]))
    fr = _Frame(room, eye, forward, half_fov, obstacles, people, tall_discs,
                sc.min_visible_fraction, sum(len(shape.solids) for _, shape in drawn))
    for pick, shape in drawn:
        kind = shape.kind
        yaw, origin, mode, wall, ok = _candidates(rng, shape, fr)
        found = _first_fit(shape, yaw, origin, ok, wall, fr)
        if found is None:
            dropped += 1
            continue
        k, solids, ranges = found
        t = _transform(float(yaw[k]), origin[k])
        mode_name = KINDS[kind].modes[int(mode[k])][0]
        items.append(PlacedClutter(kind, cfg.classes[pick], t, shape.params, mode_name,
                                   int(wall[k])))
        meshes.append(StaticMesh(f"clutter:{kind}", shape.vertices @ t[:3, :3].T + t[:3, 3],
                                 shape.faces, roles[cfg.classes[pick]][shape.roles]))
        fr.add(solids, [CLUTTER_GAP_M] * len(solids))
        fr.hide([s.poly for s in solids if hides(s)], ranges)
        item_solids.append(tuple(solids))
        if shape.opening is not None and wall[k] >= 0:
            w = fr.walls[int(wall[k])]
            s_mid = float((origin[k] - w.a) @ w.e)
            ends = sorted((s_mid + w.sign * shape.opening[0], s_mid + w.sign * shape.opening[1]))
            openings.setdefault(int(wall[k]), []).append(
                (ends[0], ends[1], shape.opening[2], shape.opening[3]))
    return ClutterLayout(tuple(items), tuple(meshes), openings, dropped, tuple(item_solids))


# where a candidate stands: PLACEMENT_MODES' positions, and nowhere (no free wall for it)
_CORNER, _FLOOR = PLACEMENT_MODES.index("corner"), PLACEMENT_MODES.index("floor")
_NOWHERE = -1
# per kind: the cumulative weights of its modes and where each stands
_MODE_CDF = {k.name: (np.cumsum([w for _, w in k.modes]) / sum(w for _, w in k.modes),
                      np.array([PLACEMENT_MODES.index(n) for n, _ in k.modes]))
             for k in KINDS.values()}


@lru_cache(maxsize=64)
def _repeats(kinds: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per entry of a config's ``kinds``: its kind's ``repeat`` (N,), and which entries
    are the same kind (N, N) (read-only: every frame of a job shares them)."""
    repeat = np.array([KINDS[k].repeat for k in kinds])
    same = np.array([[a == b for b in kinds] for a in kinds])
    repeat.setflags(write=False)
    same.setflags(write=False)
    return repeat, same


def _floor_area(shape: ClutterShape) -> float:
    """The area of the box round an item's footprints inside the room, m^2."""
    return float(np.prod(shape.inner_box[1] - shape.inner_box[0]))


def hides(s: Solid) -> bool:
    """A footprint tall enough, from low enough, to hide a standing person."""
    return s.inside and s.y1 >= HIDES_ABOVE_M and s.y0 < HIDES_FROM_M


def _transform(yaw: float, origin: np.ndarray) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, 0, s, origin[0]], [0, 1, 0, 0.0], [-s, 0, c, origin[1]],
                     [0, 0, 0, 1.0]])


def _first_fit(shape: ClutterShape, yaw: np.ndarray, origin: np.ndarray, ok: np.ndarray,
               wall: np.ndarray, fr: _Frame
               ) -> tuple[int, list[Solid], list[float]] | None:
    """The first candidate, in drawing order, that passes every test, its solids, and
    the distances from the camera of its solids that hide people (:func:`hides`):
    :func:`_first_fit_reference`'s answer, from the compiled screening
    (:func:`vhgen.scene.clutter.place_kernels.first_fit`), which stops at the first fit."""
    from vhgen.scene.clutter.place_kernels import first_fit

    if not KINDS[shape.kind].pierces_ceiling and shape.top > fr.room.height_m:
        return None
    idx = np.flatnonzero(ok)
    yaw, origin, wall = yaw[idx], origin[idx], wall[idx]
    cos, sin = np.cos(yaw), np.sin(yaw)
    least = np.where(wall < 0, WALL_GAP_M, 0.0) - 1e-9
    corners, counts, y0, y1, inside = shape.solid_table
    tall = inside & (y1 >= HIDES_ABOVE_M) & (y0 < HIDES_FROM_M)
    ranges = np.zeros(len(counts))
    k = first_fit(cos, sin, origin, least, corners, counts, y0, y1, inside, tall,
                  fr.planes, fr.eye, fr.base, fr.half_fov, MIN_RANGE_M, VISIBLE_SHARE, TRIES,
                  fr.polys, fr.normals, fr.boxes, fr.heights, fr.gaps, fr.samples, fr.dist,
                  fr.covered, fr.min_visible, ranges)
    if k < 0:
        return None
    # the footprints turned as the reference turns them, for the one candidate
    c, s, at = cos[k:k + 1, None], sin[k:k + 1, None], origin[k:k + 1]
    return (int(idx[k]),
            [Solid(_turn(c, s, poly, at)[0], lo, hi, into)
             for poly, lo, hi, into in shape.solids],
            [float(ranges[j]) for j in np.flatnonzero(tall)])


def _first_fit_reference(shape: ClutterShape, yaw: np.ndarray, origin: np.ndarray,
                         ok: np.ndarray, wall: np.ndarray, fr: _Frame
                         ) -> tuple[int, list[Solid], list[float]] | None:
    """:func:`_first_fit` as NumPy arrays, every test on every candidate at once (the
    reference the compiled screening is tested against)."""
    if not KINDS[shape.kind].pierces_ceiling and shape.top > fr.room.height_m:
        return None
    idx = np.flatnonzero(ok)
    yaw, origin, wall = yaw[idx], origin[idx], wall[idx]
    cos, sin = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    polys = [_turn(cos, sin, p, origin) for p, *_ in shape.solids]
    inner = [polys[j] for j, s in enumerate(shape.solids) if s[3]]
    least = np.where(wall < 0, WALL_GAP_M, 0.0) - 1e-9
    keep = np.ones(len(idx), bool)
    ranges = {}  # inner solid -> (K,) its nearest point's distance from the camera
    for j, (p, (*_, inside)) in enumerate(zip(polys, shape.solids, strict=True)):
        if inside:
            clear = _min(p @ fr.planes[:2] + fr.planes[2], (1, 2))
            ranges[j] = _distance(fr.eye, p)
            keep &= (clear >= least) & (ranges[j] >= MIN_RANGE_M)
    if not _any(keep):
        return None
    # at least VISIBLE_SHARE of the item's bearings inside the horizontal view
    allp = (np.concatenate(inner, axis=1) if len(inner) > 1 else inner[0]) - fr.eye
    n = allp.shape[1]
    b = _wrap(np.arctan2(allp[..., 0], allp[..., 1]) - fr.base)
    mid = _wrap(np.arctan2(_sum(allp[..., 0], 1) / n, _sum(allp[..., 1], 1) / n) - fr.base)
    rel = _wrap(b - mid[:, None])
    lo, hi = mid + _min(rel, 1), mid + _max(rel, 1)
    seen = np.minimum(hi, fr.half_fov) - np.maximum(lo, -fr.half_fov)
    keep &= seen >= VISIBLE_SHARE * np.maximum(hi - lo, 1e-9)
    if not _any(keep):
        return None
    if fr.count:
        # boxes first (all pairs at once), the separating-axis test on the close ones
        g, ob = fr.gaps, fr.boxes
        x1, z1 = ob[:, 2] + g, ob[:, 3] + g
        for p, (_, y0, y1, _) in zip(polys, shape.solids, strict=True):
            lo, hi = _min(p, 1), _max(p, 1)  # (K, 2)
            near = ((fr.heights[:, 0] < y1) & (fr.heights[:, 1] > y0))[None] & keep[:, None] & (
                (lo[:, None, 0] < x1) & (ob[:, 0] < hi[:, None, 0] + g)
                & (lo[:, None, 1] < z1) & (ob[:, 1] < hi[:, None, 1] + g))
            kk, mm = np.nonzero(near)
            if len(kk):
                keep[kk[~_separated(p[kk], fr.polys[mm], fr.normals[mm], g[mm])]] = False
    tall = [j for j, (_, y0, y1, inside) in enumerate(shape.solids)
            if inside and y1 >= HIDES_ABOVE_M and y0 < HIDES_FROM_M]
    if tall and fr.people:  # the costly test, on the first TRIES candidates left
        cand = np.flatnonzero(keep)[:TRIES]
        hit = cand[fr.visible([polys[j][cand] for j in tall], [ranges[j][cand] for j in tall])]
    else:
        hit = np.flatnonzero(keep)
    if not len(hit):
        return None
    k = int(hit[0])
    return (int(idx[k]), [Solid(polys[j][k], s[1], s[2], s[3]) for j, s in enumerate(shape.solids)],
            [ranges[j][k] for j in tall])


def _separated(a: np.ndarray, b: np.ndarray, b_normals: np.ndarray, gap: np.ndarray
               ) -> np.ndarray:
    """(N,) bool: polygon a[n] (N, P, 2) at least gap[n] from polygon b[n] (N, Q, 2) of
    unit edge normals ``b_normals`` (N, Q, 2) (zero: a repeated corner), by the
    separating-axis test over both polygons' edge normals (a zero axis proves nothing).

    Corners and axes are the leading axes and pairs the last, so that the extremes over
    the corners are elementwise (a reduction over a short last axis loops per row)."""
    at = a.transpose(2, 1, 0)  # (2, P, N)
    e = np.concatenate([at[:, 1:], at[:, :1]], 1) - at
    nx, nz = e[1], -e[0]  # a's edge normals, then unit
    length = np.maximum(np.sqrt(nx * nx + nz * nz), 1e-12)
    ax = np.concatenate([nx / length, b_normals[..., 0].T])  # (A, N)
    az = np.concatenate([nz / length, b_normals[..., 1].T])
    corners = np.concatenate([a, b], 1).transpose(2, 1, 0).copy()  # (2, P + Q, N)
    proj = corners[0][:, None] * ax + corners[1][:, None] * az  # (P + Q, A, N)
    p = a.shape[1]
    lo_a, hi_a, lo_b, hi_b = _min(proj[:p]), _max(proj[:p]), _min(proj[p:]), _max(proj[p:])
    sep = ((lo_a - hi_b >= gap) | (lo_b - hi_a >= gap)) & ((ax != 0) | (az != 0))
    return _any(sep)
