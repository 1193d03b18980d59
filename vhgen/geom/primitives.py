"""Mesh primitives (pure NumPy; trimesh only for :func:`centred_cylinder`, once): the one
kit that props, clutter (:mod:`vhgen.scene.meshkit`) and the loose parts of outfits
(:mod:`vhgen.body.drape`) are built from.

Unit primitives (:func:`cube`, :func:`cylinder`, :func:`sphere`, :func:`leaf`,
:func:`centred_cylinder`) are built once per process and kept read-only, to be scaled,
moved or instanced by the caller. Posed solids (:func:`box`, :func:`lathe`,
:func:`ellipsoid`, :func:`solid_sheet`) are closed, outward-wound meshes placed by a
(4, 4) rigid transform (:func:`frame`). Vertices (V, 3) float64 metres, faces (T, 3)
int64.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True, eq=False)
class Primitive:
    """A unit mesh: vertices (V, 3) float64, faces (T, 3) int64 (read-only)."""

    vertices: np.ndarray
    faces: np.ndarray


def as_primitive(v: ArrayLike, f: ArrayLike) -> Primitive:
    """A read-only :class:`Primitive` of vertices (V, 3) and faces (T, 3) (copied only
    where not already contiguous float64 / int64)."""
    vertices = np.ascontiguousarray(v, np.float64)
    faces = np.ascontiguousarray(f, np.int64)
    vertices.setflags(write=False)
    faces.setflags(write=False)
    return Primitive(vertices, faces)


# -- unit primitives --------------------------------------------------------------------
@cache
def cube() -> Primitive:
    """The unit cube [-0.5, 0.5]^3, 12 outward-wound triangles."""
    v = [[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    f = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return as_primitive(v, f)


@cache
def cylinder(sections: int = 12, top_ratio: float = 1.0, caps: bool = True) -> Primitive:
    """A cylinder (or frustum: top radius ``top_ratio``) of radius 1 from y = 0 to y = 1,
    ``sections`` sides, with caps unless ``caps`` is false (an open tube)."""
    a = np.linspace(0.0, 2 * np.pi, sections, endpoint=False)
    ring = np.column_stack([np.cos(a), np.zeros(sections), np.sin(a)])
    top = ring * np.array([top_ratio, 1.0, top_ratio]) + np.array([0.0, 1.0, 0.0])
    v = [ring, top]
    k = np.arange(sections)
    n = (k + 1) % sections
    f = [np.column_stack([k, sections + n, n]), np.column_stack([k, sections + k, sections + n])]
    if caps:
        v.append(np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
        c0, c1 = 2 * sections, 2 * sections + 1
        f += [np.column_stack([np.full(sections, c0), k, n]),
              np.column_stack([np.full(sections, c1), sections + n, sections + k])]
    return as_primitive(np.concatenate(v), np.concatenate(f))


@cache
def centred_cylinder() -> Primitive:
    """Radius 1, height 1, along y, centred on the origin, 24 sides as trimesh builds it
    (the cylinder prop's mesh; built once: building one per prop cost 0.5 ms a frame)."""
    import trimesh

    cyl = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=24)
    # trimesh's cylinder runs along z: stand it up along y
    cyl.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    return as_primitive(np.asarray(cyl.vertices, np.float64), np.asarray(cyl.faces, np.int64))


@cache
def sphere() -> Primitive:
    """A unit sphere, 8 x 6 latitude-longitude (80 triangles): bags, balls, fruit."""
    lat = np.linspace(0, np.pi, 7)[1:-1]
    lon = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = np.array([[np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)]
                     for t in lat for p in lon])
    v = np.concatenate([[[0.0, 1.0, 0.0]], ring, [[0.0, -1.0, 0.0]]])
    m, rows = 8, len(lat)
    f = []
    for j in range(m):
        f.append([0, 1 + (j + 1) % m, 1 + j])
        f.append([len(v) - 1, 1 + (rows - 1) * m + j, 1 + (rows - 1) * m + (j + 1) % m])
    for r in range(rows - 1):
        for j in range(m):
            a, b = 1 + r * m + j, 1 + r * m + (j + 1) % m
            f += [[a, b, b + m], [a, b + m, a + m]]
    return as_primitive(v, f)


@cache
def leaf() -> Primitive:
    """A leaf: length 1 along +x from its stalk at the origin, width 0.4 in z, the midrib
    raised 0.04 in y (4 triangles; open: both sides are seen)."""
    v = [[0.0, 0.0, 0.0], [0.35, 0.0, 0.2], [1.0, 0.0, 0.0], [0.35, 0.0, -0.2],
         [0.4, 0.04, 0.0]]
    f = [[0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]]
    return as_primitive(v, f)


# -- posed closed solids ----------------------------------------------------------------
def frame(origin: np.ndarray, y_axis: ArrayLike, z_hint: ArrayLike) -> np.ndarray:
    """(4, 4) rigid transform with its origin at ``origin``, local y along ``y_axis`` and
    local z as near ``z_hint`` as is orthogonal to it."""
    y = np.asarray(y_axis, np.float64)
    y = y / np.linalg.norm(y)
    hint = np.asarray(z_hint, np.float64)
    z = hint - y * float(np.dot(hint, y))
    nz = np.linalg.norm(z)
    z = z / nz if nz > 1e-9 else np.cross(y, [1.0, 0.0, 0.0]) / max(
        np.linalg.norm(np.cross(y, [1.0, 0.0, 0.0])), 1e-9)
    x = np.cross(y, z)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    return m


def _moved(v: np.ndarray, transform: np.ndarray) -> np.ndarray:
    m = np.asarray(transform, np.float64)
    return v @ m[:3, :3].T + m[:3, 3]


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed mesh (positive when wound outward)."""
    v = vertices[faces]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def box(size: np.ndarray, transform: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A closed box of ``size`` (3,) centred at the origin, moved by ``transform`` (4, 4):
    :func:`cube` scaled (12 outward triangles; the faces are the cube's, read-only)."""
    unit = cube()
    return _moved(unit.vertices * np.asarray(size, np.float64), transform), unit.faces


def lathe(profile: np.ndarray, transform: np.ndarray, segments: int = 16
          ) -> tuple[np.ndarray, np.ndarray]:
    """A closed solid of revolution about the local y axis: ``profile`` (P, 2) of (radius,
    y) from the bottom pole (radius 0) to the top pole (radius 0), moved by ``transform``."""
    p = np.asarray(profile, np.float64)
    a = np.arange(segments) * (2 * np.pi / segments)
    ring = p[1:-1]
    v = [[0.0, p[0, 1], 0.0], [0.0, p[-1, 1], 0.0]]
    for r, y in ring:
        v += [[r * np.sin(t), y, r * np.cos(t)] for t in a]
    verts = np.array(v)
    faces = []
    n = segments
    k = np.arange(n)
    first, last = 2, 2 + (len(ring) - 1) * n
    faces.append(np.stack([np.zeros(n, int), first + (k + 1) % n, first + k], -1))
    for j in range(len(ring) - 1):
        a0, a1 = 2 + j * n, 2 + (j + 1) * n
        faces.append(np.stack([a0 + k, a0 + (k + 1) % n, a1 + (k + 1) % n], -1))
        faces.append(np.stack([a0 + k, a1 + (k + 1) % n, a1 + k], -1))
    faces.append(np.stack([np.ones(n, int), last + k, last + (k + 1) % n], -1))
    f = np.concatenate(faces).astype(np.int64)
    if signed_volume(verts, f) < 0:
        f = f[:, ::-1].copy()
    return _moved(verts, transform), f


def ellipsoid(radii: np.ndarray, transform: np.ndarray, segments: int = 14,
              rings: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """A closed ellipsoid with semi-axes ``radii`` (3,), moved by ``transform``."""
    t = np.linspace(-np.pi / 2, np.pi / 2, rings + 2)
    v, f = lathe(np.column_stack([np.cos(t), np.sin(t)]), np.eye(4), segments)
    v = v * np.asarray(radii, np.float64)
    return _moved(v, transform), f


def solid_sheet(outer: np.ndarray, inner: np.ndarray, wrap: bool) -> tuple[np.ndarray,
                                                                           np.ndarray]:
    """A closed solid between two grids of points (R, C, 3) (R >= 2 rows, C >= 2 columns;
    ``wrap``: column C-1 joins column 0, a tube). Returns vertices (2RC, 3) float64 and
    faces (F, 3) int64, wound counter-clockwise seen from outside (positive volume)."""
    r, c = outer.shape[:2]
    verts = np.concatenate([outer.reshape(-1, 3), inner.reshape(-1, 3)]).astype(np.float64)
    o = np.arange(r * c).reshape(r, c)
    i = o + r * c
    cols = c if wrap else c - 1

    def grid(g: np.ndarray, flip: bool) -> list[np.ndarray]:
        a, b = g[:-1, :cols], g[:-1, (np.arange(cols) + 1) % c]
        d, e = g[1:, :cols], g[1:, (np.arange(cols) + 1) % c]
        t1 = np.stack([a, d, e], -1).reshape(-1, 3)
        t2 = np.stack([a, e, b], -1).reshape(-1, 3)
        return [t1[:, ::-1], t2[:, ::-1]] if flip else [t1, t2]

    def strip(p: np.ndarray, q: np.ndarray, closed: bool) -> list[np.ndarray]:
        """Quads between two polylines p, q (n,) of vertex ids (p[k], p[k+1], q[k+1], q[k])."""
        n = len(p) if closed else len(p) - 1
        k, k1 = np.arange(n), (np.arange(n) + 1) % len(p)
        return [np.stack([p[k], p[k1], q[k1]], -1), np.stack([p[k], q[k1], q[k]], -1)]

    faces = grid(o, False) + grid(i, True)
    faces += strip(o[0], i[0], wrap) + strip(i[-1], o[-1], wrap)
    if not wrap:
        faces += strip(i[:, 0], o[:, 0], False) + strip(o[:, -1], i[:, -1], False)
    f = np.concatenate(faces).astype(np.int64)
    if signed_volume(verts, f) < 0:
        f = f[:, ::-1].copy()
    return verts, f
