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

import numpy as np

from vhgen.scene.clutter.items import ClutterShape, build, sample_params, variant
from vhgen.scene.clutter.kinds import KINDS
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
    and the footprints of what it placed."""

    items: tuple[PlacedClutter, ...]
    meshes: tuple[StaticMesh, ...]
    openings: dict[int, list[tuple[float, float, float, float]]]
    dropped: int
    solids: tuple[Solid, ...]


def _rotate(yaw: np.ndarray, xz: np.ndarray) -> np.ndarray:
    """(K, P, 2): local floor points (P, 2) turned by each yaw (K,) (the convention of
    :func:`~vhgen.scene.placement.yaw_transform`)."""
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    return np.stack([c * xz[None, :, 0] + s * xz[None, :, 1],
                     -s * xz[None, :, 0] + c * xz[None, :, 1]], -1)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


class _Frame:
    """The frame's placement state: walls, where the camera looks, the obstacles as
    padded arrays (grown as items are placed), and how much of each person the
    obstacles placed so far already hide."""

    def __init__(self, room: Room, eye: np.ndarray, forward: np.ndarray, half_fov: float,
                 obstacles: list[Obstacle], people: list[Disc], tall_discs: list[Disc],
                 min_visible: float):
        self.room, self.eye, self.half_fov = room, np.asarray(eye, np.float64), half_fov
        self.base = math.atan2(forward[0], forward[1])
        self.walls = wall_frames(room)
        self.min_visible = min_visible
        # wall cells whose middle the camera sees (or nearly: items at the edge of the view)
        s = (np.arange(WALL_CELLS) + 0.5) / WALL_CELLS
        lengths = np.array([w.length for w in self.walls])
        mids = (np.stack([w.a for w in self.walls])[:, None]
                + (s[None, :, None] * lengths[:, None, None])
                * np.stack([w.e for w in self.walls])[:, None])
        d = mids - self.eye
        seen = np.abs(_wrap(np.arctan2(d[..., 0], d[..., 1]) - self.base)) <= half_fov + 0.15
        weight = seen * lengths[:, None]
        if not weight.any():
            weight = np.broadcast_to(lengths[:, None], seen.shape).copy()
        self.seen_weight = weight
        self.lengths = lengths
        self.cells = np.arange(WALL_CELLS + 1) / WALL_CELLS * lengths[:, None]  # (4, C + 1)
        self.wall_a = np.stack([w.a for w in self.walls])
        self.wall_e = np.stack([w.e for w in self.walls])
        self.wall_n = np.stack([w.n for w in self.walls])
        self.wall_yaw = np.array([w.yaw for w in self.walls])
        self.wall_sign = np.array([w.sign for w in self.walls])
        # signed distance to each wall as one product: [x, z, 1] @ planes, (3, 4)
        self.planes = np.vstack([self.wall_n.T, -(self.wall_n * self.wall_a).sum(1)])
        self.polys = np.zeros((0, DISC_SIDES, 2))
        self.normals = np.zeros((0, DISC_SIDES, 2))
        self.boxes = np.zeros((0, 4))
        self.heights = np.zeros((0, 2))
        self.gaps = np.zeros(0)
        self.add([o.solid for o in obstacles], [o.gap for o in obstacles])
        # people: sample bearings across each one's width, and what already hides them
        self.people = people
        self.samples: list[np.ndarray] = []
        self.dist: list[float] = []
        self.covered: list[np.ndarray] = []
        for t in people:
            dx, dz = t.x - self.eye[0], t.z - self.eye[1]
            tdist = math.hypot(dx, dz)
            half = math.asin(min(1.0, t.r / max(tdist, 1e-9)))
            self.samples.append(math.atan2(dx, dz) + np.linspace(-half, half, 64))
            self.dist.append(tdist)
            self.covered.append(np.zeros(64, bool))
            for o in people + tall_discs:  # as placement.visible_fraction counts them
                if o is not t:
                    ox, oz = o.x - self.eye[0], o.z - self.eye[1]
                    odist = math.hypot(ox, oz)
                    if odist < tdist:
                        oh = math.asin(min(1.0, o.r / max(odist, 1e-9)))
                        rel = _wrap(self.samples[-1] - math.atan2(ox, oz))
                        self.covered[-1] |= np.abs(rel) <= oh

    def wall_cdf(self, width: float, depth: float, y0: float, y1: float) -> np.ndarray | None:
        """(4 * C,) cumulative weights of the wall cells an item of ``width`` (along the
        wall), ``depth`` (from it) and heights [y0, y1] may be centred in: cells the camera
        sees, whose stretch of wall (widened by half the item) no obstacle within the
        item's depth of that wall takes. None if there is none."""
        sel = (self.heights[:, 0] < y1) & (self.heights[:, 1] > y0)
        weight = self.seen_weight
        if sel.any():
            p, g = self.polys[sel], self.gaps[sel]
            off = (self.wall_n * self.wall_a).sum(1)
            dist = np.einsum("mpd,kd->kmp", p, self.wall_n) - off[:, None, None]
            along = (np.einsum("mpd,kd->kmp", p, self.wall_e)
                     - (self.wall_e * self.wall_a).sum(1)[:, None, None])
            near = dist.min(2) < depth + g  # (4, M)
            s0, s1 = along.min(2) - g, along.max(2) + g
            lo, hi = self.cells[:, :-1] - width / 2, self.cells[:, 1:] + width / 2  # (4, C)
            blocked = (near[:, None] & (s0[:, None] < hi[..., None])
                       & (s1[:, None] > lo[..., None])).any(2)
            weight = weight * ~blocked
        total = weight.sum()
        return None if total <= 0 else np.cumsum(weight.ravel()) / total

    def add(self, solids: list[Solid], gaps: list[float]) -> None:
        """Obstacles placed: padded to :data:`DISC_SIDES` corners (repeated corners give
        zero-length edges, which the separating-axis test ignores)."""
        if not solids:
            return
        pad = np.stack([np.concatenate([s.poly, np.repeat(s.poly[-1:], DISC_SIDES - len(s.poly),
                                                          0)]) for s in solids])
        nrm = np.stack([np.concatenate([s.normals, np.zeros((DISC_SIDES - len(s.poly), 2))])
                        for s in solids])
        self.polys = np.concatenate([self.polys, pad])
        self.normals = np.concatenate([self.normals, nrm])
        self.boxes = np.concatenate([self.boxes, np.stack([s.box for s in solids])])
        self.heights = np.concatenate([self.heights, [[s.y0, s.y1] for s in solids]])
        self.gaps = np.concatenate([self.gaps, gaps])

    def _cover(self, i: int, poly: np.ndarray) -> None:
        """Mark person i's bearings hidden by ``poly`` if it is nearer than them."""
        if _distance(self.eye, poly[None])[0] >= self.dist[i]:
            return
        d = poly - self.eye
        mid = math.atan2(*d.mean(0))
        a = _wrap(np.arctan2(d[:, 0], d[:, 1]) - mid)
        rel = _wrap(self.samples[i] - mid)
        self.covered[i] |= (rel >= a.min()) & (rel <= a.max())

    def hide(self, polys: list[np.ndarray]) -> None:
        """Tall footprints placed: they hide people from now on."""
        for p in polys:
            for i in range(len(self.people)):
                self._cover(i, p)

    def visible(self, polys: list[np.ndarray]) -> np.ndarray:
        """(K,) bool: every person keeps ``min_visible`` of its width past what hides it
        already and candidate k's tall footprints polys[j][k] (K, P, 2) for every j."""
        k = len(polys[0])
        ok = np.ones(k, bool)
        if not k:
            return ok
        spans = []
        for p in polys:
            d = p - self.eye
            mid = np.arctan2(d[..., 0].mean(1), d[..., 1].mean(1))
            a = _wrap(np.arctan2(d[..., 0], d[..., 1]) - mid[:, None])
            spans.append((_distance(self.eye, p), mid, a.min(1), a.max(1)))
        for i in range(len(self.people)):
            cover = np.broadcast_to(self.covered[i], (k, 64)).copy()
            for near, mid, lo, hi in spans:
                rel = _wrap(self.samples[i][None] - mid[:, None])  # (K, 64)
                cover |= ((rel >= lo[:, None]) & (rel <= hi[:, None])
                          & (near < self.dist[i])[:, None])
            ok &= 1.0 - cover.mean(1) >= self.min_visible
        return ok


def _distance(eye: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """(K,) distance from ``eye`` (2,) to each convex polygon (K, P, 2) (0 inside)."""
    a = polys
    b = np.concatenate([polys[:, 1:], polys[:, :1]], 1)
    ab = b - a
    ea = eye - a
    t = np.clip((ea * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18), 0.0, 1.0)
    q = a + t[..., None] * ab - eye
    d = np.sqrt((q * q).sum(-1)).min(1)
    cross = ab[..., 0] * ea[..., 1] - ab[..., 1] * ea[..., 0]
    inside = (cross >= 0).all(1) | (cross <= 0).all(1)
    return np.where(inside, 0.0, d)


def _candidates(rng: np.random.Generator, shape: ClutterShape, fr: _Frame
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:data:`CANDIDATES` placements: yaw (K,), origin (K, 2), mode index (K,) into the
    kind's modes, wall (K,) (-1 on the floor), and whether each is possible (K,). Wall
    spots are drawn where the camera looks; corners at the end of the wall nearer to a
    drawn spot; floor spots in the camera's view."""
    modes = KINDS[shape.kind].modes
    u = rng.uniform(size=(CANDIDATES, 5))
    mode_cdf, mode_names = _MODE_CDF[shape.kind]
    mode = np.minimum(np.searchsorted(mode_cdf, u[:, 0], side="right"), len(modes) - 1)
    names = mode_names[mode]
    x0, x1 = shape.x_extent
    cdf = fr.wall_cdf(x1 - x0, float(shape.inner_box[1, 1]), *shape.inner_heights)
    if cdf is None:  # no free wall in view: only floor spots can work
        cdf = np.cumsum(fr.seen_weight.ravel()) / fr.seen_weight.sum()
        names = np.where(names == "floor", names, "none")
    cell = np.minimum(np.searchsorted(cdf, u[:, 1], side="right"), 4 * WALL_CELLS - 1)
    wall = cell // WALL_CELLS
    length = fr.lengths[wall]
    spot = ((cell % WALL_CELLS) + u[:, 2]) / WALL_CELLS * length
    sign = fr.wall_sign[wall]
    lo_off, hi_off = np.minimum(sign * x0, sign * x1), np.maximum(sign * x0, sign * x1)
    s_lo = CORNER_GAP_M - lo_off
    s_hi = length - CORNER_GAP_M - hi_off
    # the item's middle on the spot, moved along the wall to fit
    s = np.clip(spot - (lo_off + hi_off) / 2, s_lo, s_hi)
    s = np.where(names == "corner", np.where(spot < length / 2, s_lo, s_hi), s)
    yaw = fr.wall_yaw[wall]
    origin = fr.wall_a[wall] + s[:, None] * fr.wall_e[wall] + FLUSH_M * fr.wall_n[wall]
    ok = (s_hi >= s_lo) & (names != "none")
    on_floor = names == "floor"
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
    fr = _Frame(room, eye, forward, half_fov, obstacles, people, tall_discs,
                sc.min_visible_fraction)
    n_items = int(rng.integers(cfg.count[0], cfg.count[1] + 1))
    weights = np.array(cfg.weights, np.float64)
    repeat = np.array([KINDS[k].repeat for k in cfg.kinds])
    same = np.array([[a == b for b in cfg.kinds] for a in cfg.kinds])
    roles = sc.clutter_roles
    items: list[PlacedClutter] = []
    meshes: list[StaticMesh] = []
    openings: dict[int, list[tuple[float, float, float, float]]] = {}
    placed: list[Solid] = []
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
    for pick, shape in drawn:
        kind = shape.kind
        yaw, origin, mode, wall, ok = _candidates(rng, shape, fr)
        found = _first_fit(shape, yaw, origin, ok, wall, fr)
        if found is None:
            dropped += 1
            continue
        k, solids = found
        t = _transform(float(yaw[k]), origin[k])
        mode_name = KINDS[kind].modes[int(mode[k])][0]
        items.append(PlacedClutter(kind, cfg.classes[pick], t, shape.params, mode_name,
                                   int(wall[k])))
        meshes.append(StaticMesh(f"clutter:{kind}", shape.vertices @ t[:3, :3].T + t[:3, 3],
                                 shape.faces, roles[cfg.classes[pick]][shape.roles]))
        fr.add(solids, [CLUTTER_GAP_M] * len(solids))
        fr.hide([s.poly for s in solids if _hides(s)])
        placed += solids
        if shape.opening is not None and wall[k] >= 0:
            w = fr.walls[int(wall[k])]
            s_mid = float((origin[k] - w.a) @ w.e)
            ends = sorted((s_mid + w.sign * shape.opening[0], s_mid + w.sign * shape.opening[1]))
            openings.setdefault(int(wall[k]), []).append(
                (ends[0], ends[1], shape.opening[2], shape.opening[3]))
    return ClutterLayout(tuple(items), tuple(meshes), openings, dropped, tuple(placed))


# per kind: the cumulative weights of its modes and their names
_MODE_CDF = {k.name: (np.cumsum([w for _, w in k.modes]) / sum(w for _, w in k.modes),
                      np.array([n for n, _ in k.modes])) for k in KINDS.values()}


def _floor_area(shape: ClutterShape) -> float:
    """The area of the box round an item's footprints inside the room, m^2."""
    return float(np.prod(shape.inner_box[1] - shape.inner_box[0]))


def _hides(s: Solid) -> bool:
    """A footprint tall enough, from low enough, to hide a standing person."""
    return s.inside and s.y1 >= HIDES_ABOVE_M and s.y0 < HIDES_FROM_M


def _transform(yaw: float, origin: np.ndarray) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, 0, s, origin[0]], [0, 1, 0, 0.0], [-s, 0, c, origin[1]],
                     [0, 0, 0, 1.0]])


def _first_fit(shape: ClutterShape, yaw: np.ndarray, origin: np.ndarray, ok: np.ndarray,
               wall: np.ndarray, fr: _Frame) -> tuple[int, list[Solid]] | None:
    """The first candidate, in drawing order, that passes every test, and its solids."""
    room = fr.room
    if not KINDS[shape.kind].pierces_ceiling and shape.top > room.height_m:
        return None
    idx = np.flatnonzero(ok)
    yaw, origin, wall = yaw[idx], origin[idx], wall[idx]
    polys = [_rotate(yaw, p) + origin[:, None, :] for p, *_ in shape.solids]
    keep = np.ones(len(idx), bool)
    inner = [polys[j] for j, s in enumerate(shape.solids) if s[3]]
    margin = np.where(wall < 0, WALL_GAP_M, 0.0)
    for p in inner:
        clear = (p @ fr.planes[:2] + fr.planes[2]).min(axis=(1, 2))
        keep &= (clear >= margin - 1e-9) & (_distance(fr.eye, p) >= MIN_RANGE_M)
    # at least VISIBLE_SHARE of the item's bearings inside the horizontal view
    allp = np.concatenate(inner, axis=1) - fr.eye
    b = _wrap(np.arctan2(allp[..., 0], allp[..., 1]) - fr.base)
    mid = _wrap(np.arctan2(allp[..., 0].mean(1), allp[..., 1].mean(1)) - fr.base)
    rel = _wrap(b - mid[:, None])
    lo, hi = mid + rel.min(1), mid + rel.max(1)
    seen = np.minimum(hi, fr.half_fov) - np.maximum(lo, -fr.half_fov)
    keep &= seen >= VISIBLE_SHARE * np.maximum(hi - lo, 1e-9)
    if len(fr.gaps) and keep.any():
        # boxes first (all pairs at once), the separating-axis test on the close ones
        g = fr.gaps
        for p, (_, y0, y1, _) in zip(polys, shape.solids, strict=True):
            box = np.concatenate([p.min(1), p.max(1)], 1)  # (K, 4)
            ob = fr.boxes
            near = ((fr.heights[:, 0] < y1) & (fr.heights[:, 1] > y0))[None] & keep[:, None] & (
                (box[:, None, 0] < ob[None, :, 2] + g) & (ob[None, :, 0] < box[:, None, 2] + g)
                & (box[:, None, 1] < ob[None, :, 3] + g) & (ob[None, :, 1] < box[:, None, 3] + g))
            kk, mm = np.nonzero(near)
            if len(kk):
                a = p[kk]  # (N, P, 2)
                na = np.concatenate([a[:, 1:], a[:, :1]], 1) - a
                na = np.stack([na[..., 1], -na[..., 0]], -1)
                na /= np.maximum(np.linalg.norm(na, axis=-1, keepdims=True), 1e-12)
                axes = np.concatenate([na, fr.normals[mm]], 1)  # (N, A, 2)
                b = fr.polys[mm]
                ax, az = axes[..., 0, None], axes[..., 1, None]
                pa = a[:, None, :, 0] * ax + a[:, None, :, 1] * az  # (N, A, P)
                pb = b[:, None, :, 0] * ax + b[:, None, :, 1] * az  # (N, A, Q)
                sep = (((pa.min(-1) - pb.max(-1) >= g[mm, None])
                        | (pb.min(-1) - pa.max(-1) >= g[mm, None]))
                       & (np.abs(axes).sum(-1) > 0)).any(-1)
                clash = np.zeros(len(idx), bool)
                np.logical_or.at(clash, kk, ~sep)
                keep &= ~clash
    tall = [j for j, (_, y0, y1, inside) in enumerate(shape.solids)
            if inside and y1 >= HIDES_ABOVE_M and y0 < HIDES_FROM_M]
    if tall and fr.people:  # the costly test, on the first TRIES candidates left
        cand = np.flatnonzero(keep)[:TRIES]
        hit = cand[fr.visible([polys[j][cand] for j in tall])]
    else:
        hit = np.flatnonzero(keep)
    if not len(hit):
        return None
    k = int(hit[0])
    return int(idx[k]), [Solid(polys[j][k], s[1], s[2], s[3]) for j, s in enumerate(shape.solids)]
