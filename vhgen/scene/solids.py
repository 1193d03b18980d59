"""Footprints that are not circles: vertical prisms over convex polygons (pure NumPy).

A bookcase against a wall, a door leaf open at 40 degrees or a staircase along a wall is
badly bounded by a circle (a 1.2 m bookcase's circle would keep it 0.6 m off the wall).
Clutter therefore keeps, per part of an item, a :class:`Solid`: a convex polygon on the
floor and the height range [y0, y1] it fills. Two solids are apart when their height
ranges do not overlap (a picture above a radiator) or when a separating axis puts their
polygons at least ``gap`` apart: the separating-axis test over the polygons' edge normals,
which only ever proves a true distance of at least ``gap`` (it may refuse a pair that is
apart only along a corner-to-corner direction: conservative). People and props keep
their circles, seen here as circumscribed octagons.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

DISC_SIDES = 8


@dataclass(frozen=True, eq=False)
class Solid:
    """A prism: ``poly`` (P, 2) float64 (x, z) world metres, convex, counter-clockwise in
    (x, z); heights ``y0`` .. ``y1``. ``inside``: it must lie inside the room (false for a
    door's corridor beyond the wall)."""

    poly: np.ndarray
    y0: float
    y1: float
    inside: bool = True
    centre: np.ndarray = field(init=False)
    radius: float = field(init=False)
    box: np.ndarray = field(init=False)  # (4,) x min, z min, x max, z max
    normals: np.ndarray = field(init=False)  # (P, 2) unit edge normals

    def __post_init__(self) -> None:
        # ufunc reductions, not the ndarray methods (p.mean(0) is this same sum over the
        # same count): on a few corners their Python wrappers cost more than the arithmetic,
        # and clutter placement makes a dozen solids a frame
        p = np.asarray(self.poly, np.float64)
        c = np.add.reduce(p, 0) / len(p)
        d = p - c
        object.__setattr__(self, "poly", p)
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "radius", float(np.sqrt(np.maximum.reduce(
            d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]))))
        object.__setattr__(self, "box", np.concatenate([np.minimum.reduce(p, 0),
                                                        np.maximum.reduce(p, 0)]))
        object.__setattr__(self, "normals", edge_normals(p))


def disc_polygon(x: float, z: float, r: float, sides: int = DISC_SIDES) -> np.ndarray:
    """(sides, 2) the regular polygon circumscribed about the circle (it contains it)."""
    cos, sin = _unit_polygon(sides)
    rr = r / math.cos(math.pi / sides)
    return np.column_stack([x + rr * cos, z + rr * sin])


@lru_cache(maxsize=8)
def _unit_polygon(sides: int) -> tuple[np.ndarray, np.ndarray]:
    """The cosines and sines (sides,) of a regular polygon's corner angles (read-only:
    every disc shares them)."""
    a = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    cos, sin = np.cos(a), np.sin(a)
    cos.setflags(write=False)
    sin.setflags(write=False)
    return cos, sin


def disc_solid(x: float, z: float, r: float, y1: float = math.inf) -> Solid:
    """A circle's solid from the floor up to ``y1`` (people: unbounded)."""
    return Solid(disc_polygon(x, z, r), 0.0, y1)


def rect(x0: float, x1: float, z0: float, z1: float) -> np.ndarray:
    """(4, 2) the rectangle [x0, x1] x [z0, z1], counter-clockwise in (x, z)."""
    return np.array([[x0, z0], [x1, z0], [x1, z1], [x0, z1]], np.float64)


_FLIP = np.array([1.0, -1.0])  # an edge (x, z), swapped, to its normal (z, -x)
_FLIP.setflags(write=False)


def edge_normals(poly: np.ndarray) -> np.ndarray:
    """(..., P, 2) unit edge normals of polygons (..., P, 2) (degenerate edges: 0)."""
    e = np.concatenate([poly[..., 1:, :], poly[..., :1, :]], -2) - poly
    n = e[..., ::-1] * _FLIP
    length = np.sqrt((n * n).sum(-1, keepdims=True))
    return n * np.where(length > 1e-12, 1.0 / np.maximum(length, 1e-12), 0.0)


def separated(a: np.ndarray, b: np.ndarray, gap: float,
              b_normals: np.ndarray | None = None) -> np.ndarray:
    """(K,) bool: polygon a[k] (K, P, 2) at least ``gap`` from polygon ``b`` (Q, 2), by
    the separating-axis test over both polygons' edge normals (``b_normals``: b's, if
    known)."""
    a = np.asarray(a, np.float64)
    k = len(a)
    nb = edge_normals(b) if b_normals is None else b_normals
    axes = np.concatenate([edge_normals(a), np.broadcast_to(nb, (k,) + nb.shape)], 1)
    pa = np.einsum("kpd,kad->kap", a, axes)
    pb = np.einsum("qd,kad->kaq", b, axes)
    sep = ((pa.min(-1) - pb.max(-1) >= gap) | (pb.min(-1) - pa.max(-1) >= gap))
    # a zero axis (degenerate edge) proves nothing
    sep &= np.linalg.norm(axes, axis=-1) > 0
    return sep.any(-1)


def angular_span(eye_xz: np.ndarray, poly: np.ndarray, toward: float) -> tuple[float, float]:
    """(lo, hi) bearings of a convex polygon seen from ``eye_xz`` (outside it), radians
    relative to the bearing ``toward`` (the convention of
    :func:`vhgen.scene.placement.visible_fraction`: atan2(dx, dz)). The span is taken
    about the polygon's own centre, so a polygon behind the eye spans little, not 2 pi."""
    d = np.asarray(poly, np.float64) - np.asarray(eye_xz, np.float64)
    c = d.mean(0)
    mid = math.atan2(c[0], c[1])
    a = np.angle(np.exp(1j * (np.arctan2(d[:, 0], d[:, 1]) - mid)))
    rel = float(np.angle(np.exp(1j * (mid - toward))))
    return rel + float(a.min()), rel + float(a.max())


def nearest_distance(eye_xz: np.ndarray, poly: np.ndarray) -> float:
    """Distance from a point outside a convex polygon to it (to its nearest edge)."""
    p = np.asarray(poly, np.float64)
    a, b = p, np.roll(p, -1, 0)
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", np.asarray(eye_xz) - a, ab)
                / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18), 0.0, 1.0)
    q = a + t[:, None] * ab
    return float(np.hypot(*(q - eye_xz).T).min())


def visible_fraction_with(eye_xz: np.ndarray, target_xz: np.ndarray, target_r: float,
                          discs: list[tuple[float, float, float]], polys: list[np.ndarray],
                          samples: int = 64) -> float:
    """The fraction of a target circle's angular width seen from ``eye_xz`` past nearer
    circles (x, z, r) and nearer convex polygons (a polygon is nearer when its nearest
    point is nearer than the target's centre): the floor-plan bound of
    :func:`vhgen.scene.placement.visible_fraction` with polygon occluders added."""
    ex, ez = float(eye_xz[0]), float(eye_xz[1])
    dx, dz = float(target_xz[0]) - ex, float(target_xz[1]) - ez
    tdist = math.hypot(dx, dz)
    tc = math.atan2(dx, dz)
    th = math.asin(min(1.0, target_r / max(tdist, 1e-9)))
    angles = tc + np.linspace(-th, th, samples)
    covered = np.zeros(samples, bool)
    for x, z, r in discs:
        ox, oz = x - ex, z - ez
        odist = math.hypot(ox, oz)
        if odist >= tdist:
            continue
        oh = math.asin(min(1.0, r / max(odist, 1e-9)))
        covered |= np.abs(np.angle(np.exp(1j * (angles - math.atan2(ox, oz))))) <= oh
    for p in polys:
        if nearest_distance(np.array([ex, ez]), p) >= tdist:
            continue
        lo, hi = angular_span(np.array([ex, ez]), p, tc)
        rel = angles - tc
        covered |= (rel >= lo) & (rel <= hi)
    return float(1.0 - covered.mean())


def visible_fraction_compiled(eye_xz: np.ndarray, target_xz: np.ndarray, target_r: float,
                              discs: list[tuple[float, float, float]],
                              polys: list[np.ndarray], samples: int = 64) -> float:
    """:func:`visible_fraction_with` in one compiled call
    (:func:`vhgen.scene.placement_kernels.visible_with`; the function above is its
    reference, and tests compare the two): a shared layout asks it of every person for
    every spot it tries, about 1 ms a frame in NumPy."""
    from vhgen.scene.placement_kernels import visible_with

    d = np.asarray(discs, np.float64).reshape(-1, 3)
    verts = (np.concatenate([np.asarray(q, np.float64) for q in polys]) if polys
             else np.zeros((0, 2)))
    starts = np.zeros(len(polys) + 1, np.int64)
    starts[1:] = np.cumsum([len(q) for q in polys])
    return float(visible_with(float(eye_xz[0]), float(eye_xz[1]), float(target_xz[0]),
                              float(target_xz[1]), float(target_r), d, verts, starts, samples))
