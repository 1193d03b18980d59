"""Loose parts: closed solids that hang off the body (skirts, coat hems, long hair), fitted
to a shaped body and bound to its rig.

Every part is a closed, consistently wound (outward) triangle mesh, so the renderer culls
its far side as it does the body's. A hanging part is a thick sheet: an outer and an inner
surface on the same grid of rings (rows) and columns, joined by rims along its edges
(:func:`vhgen.geom.primitives.solid_sheet`); hair, hats and carried things are made of the
posed solids of :mod:`vhgen.geom.primitives` too.

Skirts and coat hems are tubes around the legs: each ring is the convex hull of the body's
cross-section at its height (both legs and the gap between them, as cloth spans it), never
narrower than the ring above (cloth hangs from the widest part), plus ease and flare.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vhgen.body.chart import BodyChart
from vhgen.body.mesh import Rig


def hull_radius(points: np.ndarray, center: np.ndarray, angles: np.ndarray,
                support: int = 64) -> np.ndarray:
    """Distance (C,) from ``center`` (2,) to the convex hull of ``points`` (N, 2) along the
    directions (sin a, cos a) of ``angles`` (C,) radians, in the (x, z) plane (a = 0 is
    +z, the front; pi/2 is +x, the subject's left). The hull is taken as the polygon of
    its ``support`` supporting lines (at most 0.13% wider than the hull for 64); 0 where
    there are no points."""
    pts = np.asarray(points, np.float64) - center
    if len(pts) == 0:
        return np.zeros(len(angles))
    phi = np.arange(support) * (2 * np.pi / support)
    u = np.column_stack([np.sin(phi), np.cos(phi)])
    h = np.maximum((pts @ u.T).max(axis=0), 0.0)  # support function (S,)
    c = np.cos(np.asarray(angles)[:, None] - phi[None])  # (C, S)
    with np.errstate(divide="ignore"):
        r = np.where(c > 1e-6, h[None] / c, np.inf)
    return r.min(axis=1)


def hanging_tube(skin: np.ndarray, y_top: float, y_bottom: float, ease: float, flare: float,
                 cloth: float, columns: int = 28, ring_step: float = 0.05,
                 gap_angle: float = 0.0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The outer and inner grids (R, C, 3) of a tube hanging from ``y_top`` down to
    ``y_bottom`` around the ``skin`` points (N, 3) (the body parts it hangs around), each
    ring's half width (R,), and the grid (R, C, 3) of the points of the body's hull the
    cloth hangs over (what a hand presses it back to).

    Ring radius: the hull of the skin within half a ring step of its height, at least the
    ring above's, plus ``ease`` and ``flare`` per metre below ``y_top``; ``cloth`` thick.
    ``gap_angle`` > 0 leaves the front open over that angle (radians): an open coat; the
    columns then run from one edge of the opening round the back to the other.
    """
    rows = max(2, int(np.ceil((y_top - y_bottom) / ring_step)) + 1)
    ys = np.linspace(y_top, y_bottom, rows)
    if gap_angle > 0:
        angles = np.linspace(gap_angle / 2, 2 * np.pi - gap_angle / 2, columns)
    else:
        angles = np.arange(columns, dtype=np.float64) * (2 * np.pi / columns)
    band = max(ring_step, 0.02)
    radius = np.zeros((rows, columns))
    centers = np.zeros((rows, 2))
    for k, y in enumerate(ys):
        near = skin[np.abs(skin[:, 1] - y) < band][:, [0, 2]]
        if len(near) >= 3:
            centers[k] = [0.0, 0.5 * (near[:, 1].min() + near[:, 1].max())]
        elif k:
            centers[k] = centers[k - 1]
        radius[k] = hull_radius(near, centers[k], angles) if len(near) >= 3 else 0.0
    # a ring past the body's end (below the feet) keeps the ring above's shape
    for k in range(1, rows):
        radius[k] = np.maximum(radius[k], radius[k - 1])
    # the axis moves smoothly: cloth does not follow the body's every bump
    for _ in range(2):
        centers[1:-1] = 0.25 * centers[:-2] + 0.5 * centers[1:-1] + 0.25 * centers[2:]
    drop = (y_top - ys)[:, None]
    r_out = radius + ease + flare * drop
    r_in = np.maximum(r_out - cloth, 1e-3)
    sin, cos = np.sin(angles)[None], np.cos(angles)[None]

    def ring(r: np.ndarray) -> np.ndarray:
        return np.stack([centers[:, :1] + r * sin, np.broadcast_to(ys[:, None], r.shape),
                         centers[:, 1:] + r * cos], -1)

    half = np.abs(r_out * sin).max(axis=1)
    return ring(r_out), ring(r_in), half, ring(radius)


def curtain(skin: np.ndarray, guide: np.ndarray, head_half: np.ndarray, y_top: float,
            y_bottom: float, volume: float, columns: int = 20, row_step: float = 0.035
            ) -> tuple[np.ndarray, np.ndarray]:
    """Outer and inner grids (R, C, 3) of hair hanging down the back from ``y_top`` to
    ``y_bottom``: as wide at each height as the ``guide`` points (N, 3) there (MakeHuman's
    long-hair helper behind the head; below its end, as wide as its end) but no wider
    than ``head_half`` (2,) (the head's half width, and the height down to which it
    applies) beside the head, lying on the ``skin`` (N, 3) behind (the hair falls from the
    furthest-back point above it: never forward into the nape or the small of the back),
    ``volume`` thick, thinner at the top where it comes out of the hair on the scalp."""
    rows = max(2, int(np.ceil((y_top - y_bottom) / row_step)) + 1)
    ys = np.linspace(y_top, y_bottom, rows)
    half = np.zeros(rows)
    for k, y in enumerate(ys):
        g = guide[np.abs(guide[:, 1] - y) < max(row_step, 0.03)]
        half[k] = np.abs(g[:, 0]).max() if len(g) else (half[k - 1] if k else 0.08)
    half = np.where(ys > head_half[1], np.minimum(half, head_half[0]), half)
    half = np.maximum(half, 0.04)
    u = np.linspace(-1.0, 1.0, columns)
    x = half[:, None] * u[None]
    z = np.zeros((rows, columns))
    for k, y in enumerate(ys):
        near = skin[np.abs(skin[:, 1] - y) < max(row_step, 0.03)]
        dx = np.abs(near[:, 0][None] - x[k][:, None])  # (C, N)
        width = max(half[k] / columns * 2, 0.015)
        zz = np.where(dx < width, near[:, 2][None], np.inf).min(axis=1)
        if np.isinf(zz).all():
            z[k] = z[k - 1] if k else 0.0
        else:
            z[k] = np.where(np.isinf(zz), zz[np.isfinite(zz)].min(), zz)
    z = np.minimum.accumulate(z, axis=0)  # hangs from the furthest-back point above
    y = np.broadcast_to(ys[:, None], x.shape)
    inner = np.stack([x, y, z - 0.004], -1)
    # thickest in the middle, thinning to the sides and the ends; at the top it comes
    # out of the hair on the scalp
    top = np.clip((y_top - ys) / 0.06, 0.3, 1.0)[:, None]
    t = volume * (0.35 + 0.65 * np.sqrt(1 - u[None] ** 2)) * top
    outer = np.stack([x * (1 + 0.1 * t / max(volume, 1e-6)), y, z - 0.004 - t], -1)
    return outer, inner


@dataclass(frozen=True, eq=False)
class Fit:
    """What loose parts are fitted to, per avatar: the shaped rest ``skin`` (V, 3), its
    unit ``normals`` (V, 3), ``dense`` skinning weights (V, B) (the body's 4 influences
    spread over the bones), the ``rig`` and the topology's ``chart``."""

    skin: np.ndarray
    normals: np.ndarray
    dense: np.ndarray
    rig: Rig
    chart: BodyChart

    def region_skin(self, regions: tuple[int, ...]) -> np.ndarray:
        """Skin vertices (N, 3) of the given chart regions."""
        return self.skin[np.isin(self.chart.region, regions)]

    def bone(self, name: str) -> np.ndarray:
        """(B,) weights binding rigidly to one bone."""
        w = np.zeros(self.dense.shape[1])
        w[self.rig.index(name)] = 1.0
        return w

    def nearest_weights(self, points: np.ndarray, regions: tuple[int, ...], k: int = 1
                        ) -> np.ndarray:
        """Dense weights (N, B) of the skin under ``points`` (N, 3): the mean over the
        ``k`` nearest skin vertices of ``regions`` (k > 1 smooths them, for loose cloth)."""
        from scipy.spatial import cKDTree

        idx = np.flatnonzero(np.isin(self.chart.region, regions))
        _, near = cKDTree(self.skin[idx]).query(np.asarray(points, np.float64), k=k)
        near = idx[np.asarray(near).reshape(len(points), -1)]
        return self.dense[near].mean(axis=1)


@dataclass(frozen=True, eq=False)
class Part:
    """A loose part: a closed mesh (``vertices`` (n, 3) rest, ``faces`` (m, 3)), its dense
    skinning ``weights`` (n, B), the body ``regions`` whose nearest triangle labels each
    of its triangles, whether it is a ``carried`` thing (its own scene class), and for
    cloth a hand may press back towards the body, ``offsets`` (n, 3): each vertex minus
    the point of the body's hull it hangs over."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    regions: tuple[int, ...]
    carried: bool = False
    offsets: np.ndarray | None = None


def rigid_part(name: str, mesh: tuple[np.ndarray, np.ndarray], weights: np.ndarray,
               regions: tuple[int, ...], carried: bool = False) -> Part:
    """A part bound with the same (B,) weights at every vertex."""
    v, f = mesh
    return Part(name, v, f, np.tile(weights, (len(v), 1)), regions, carried)
