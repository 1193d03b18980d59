"""Building clutter meshes from instanced unit primitives (pure NumPy).

A clutter item is hundreds of repeated simple solids: books, shelf boards, leaves,
balusters, radiator fins. Each primitive (a unit cube, a unit cylinder, a leaf, a thin
tube, a low-poly sphere: :mod:`vhgen.geom.primitives`) is built once per process and
kept; an item is a list of *instance batches* (one primitive, an (N, 3, 4) affine
transform per instance), turned into vertices with one ``einsum`` per batch. Nothing is
rebuilt with trimesh per frame.

Every face carries a *role*, mapped to a scene class when the item is placed:
:data:`BODY` (the kind's own class), :data:`OBJECT` (things standing on the item: books,
cups, boxes), :data:`WALL` and :data:`FLOOR` (a door's corridor, a window's frame and
sill, which belong to the building). Every face also carries a *group*: the item's
footprint is one solid per group (see :class:`vhgen.scene.solids.Solid`), so a door's
leaf, open at an angle, or a chair pulled out from a desk, gets a footprint of its own.
"""

from __future__ import annotations

import numpy as np

from vhgen.geom.primitives import Primitive, as_primitive, cube, cylinder, leaf, sphere

BODY, OBJECT, WALL, FLOOR = range(4)
ROLES = ("body", "object", "wall", "floor")


def yaw_matrix(yaw: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations about +y by ``yaw`` radians (the convention of
    :func:`vhgen.scene.placement.yaw_transform`)."""
    c, s = np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def frame_from_axis(axis: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations taking +y onto each unit ``axis`` (N, 3) (the shortest turn;
    an axis along -y turns about x)."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    y = np.array([0.0, 1.0, 0.0])
    v = np.cross(np.broadcast_to(y, a.shape), a)
    c = a[:, 1]
    k = np.zeros((len(a), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 0] = -v[:, 2], v[:, 1], v[:, 2]
    k[:, 1, 2], k[:, 2, 0], k[:, 2, 1] = -v[:, 0], -v[:, 1], v[:, 0]
    opposite = c < -1 + 1e-9
    scale = np.where(opposite, 0.0, 1.0 / np.maximum(1.0 + c, 1e-12))
    r = np.eye(3) + k + (k @ k) * scale[:, None, None]
    r[opposite] = np.diag([1.0, -1.0, -1.0])
    return r


class Kit:
    """Collects instances of unit primitives and builds one mesh (vertices, faces, roles,
    groups): one ``einsum`` per primitive, however many calls added instances of it.

    Transforms are affine (3, 4): ``[A | t]`` maps a unit-primitive point p to A p + t.
    ``group`` tags what the next calls add (see the module docstring)."""

    def __init__(self) -> None:
        # primitive -> lists of (N, 3, 4) transforms, (N,) roles, (N,) groups
        self._batches: dict[int, tuple[Primitive, list, list, list]] = {}
        self.group = 0

    def add(self, prim: Primitive, transforms: np.ndarray, role) -> None:
        """``prim`` once per (N, 3, 4) affine transform, faces of ``role`` (one or (N,))."""
        t = np.asarray(transforms, np.float64).reshape(-1, 3, 4)
        if not len(t):
            return
        entry = self._batches.setdefault(id(prim), (prim, [], [], []))
        entry[1].append(t)
        entry[2].append(np.broadcast_to(np.asarray(role, np.uint8), (len(t),)))
        entry[3].append(np.full(len(t), self.group, np.uint8))

    def boxes(self, sizes, centres, role, yaw=None) -> None:
        """Boxes of extents (N, 3) about centres (N, 3), turned by ``yaw`` (N,) radians
        about their vertical axis (default unturned); ``role`` one or (N,)."""
        s = np.asarray(sizes, np.float64).reshape(-1, 3)
        c = np.asarray(centres, np.float64).reshape(-1, 3)
        n = len(s)
        t = np.zeros((n, 3, 4))
        if yaw is None:
            t[:, 0, 0], t[:, 1, 1], t[:, 2, 2] = s[:, 0], s[:, 1], s[:, 2]
        else:
            t[:, :, :3] = yaw_matrix(np.broadcast_to(np.asarray(yaw, np.float64), (n,))) \
                * s[:, None, :]
        t[:, :, 3] = c
        self.add(cube(), t, role)

    def box(self, size, centre, role: int, yaw: float | None = None) -> None:
        """One box (see :meth:`boxes`)."""
        self.boxes([size], [centre], role, None if yaw is None else [yaw])

    def cylinders(self, radius, height, base, role, sections: int = 12,
                  top_ratio: float = 1.0) -> None:
        """Upright cylinders of radius (N,) and height (N,) standing on points (N, 3)."""
        r = np.atleast_1d(np.asarray(radius, np.float64))
        h = np.broadcast_to(np.asarray(height, np.float64), r.shape)
        b = np.asarray(base, np.float64).reshape(-1, 3)
        t = np.zeros((len(r), 3, 4))
        t[:, 0, 0], t[:, 1, 1], t[:, 2, 2] = r, h, r
        t[:, :, 3] = b
        self.add(cylinder(sections, top_ratio), t, role)

    def tubes(self, p0, p1, radius, role: int, sections: int = 6) -> None:
        """Thin open tubes from points (N, 3) to points (N, 3) of radius (N,) (branches,
        poles, balusters, chair legs)."""
        a = np.asarray(p0, np.float64).reshape(-1, 3)
        b = np.asarray(p1, np.float64).reshape(-1, 3)
        d = b - a
        length = np.linalg.norm(d, axis=1)
        keep = length > 1e-9
        a, d, length = a[keep], d[keep], length[keep]
        r = np.broadcast_to(np.asarray(radius, np.float64), keep.shape)[keep]
        rot = frame_from_axis(d)
        t = np.concatenate([rot * np.stack([r, length, r], 1)[:, None, :], a[:, :, None]], 2)
        self.add(cylinder(sections, 1.0, False), t, role)

    def spheres(self, radii, centres, role) -> None:
        """Ellipsoids of semi-axes (N, 3) about centres (N, 3)."""
        s = np.asarray(radii, np.float64).reshape(-1, 3)
        c = np.asarray(centres, np.float64).reshape(-1, 3)
        t = np.zeros((len(s), 3, 4))
        t[:, 0, 0], t[:, 1, 1], t[:, 2, 2] = s[:, 0], s[:, 1], s[:, 2]
        t[:, :, 3] = c
        self.add(sphere(), t, role)

    def leaves(self, base, direction, length, roll, role: int) -> None:
        """Leaves with stalks at (N, 3), pointing along unit directions (N, 3), of length
        (N,), turned about their own axis by ``roll`` (N,) radians."""
        d = np.asarray(direction, np.float64).reshape(-1, 3)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        ln = np.asarray(length, np.float64)
        # a frame whose x axis is the leaf direction: from +y onto d, then x and y swapped
        r = frame_from_axis(d)
        x_axis, y_axis, z_axis = r[:, :, 1], -r[:, :, 0], r[:, :, 2]
        c, s = np.cos(roll), np.sin(roll)
        y2 = c[:, None] * y_axis + s[:, None] * z_axis
        z2 = -s[:, None] * y_axis + c[:, None] * z_axis
        a = np.stack([x_axis, y2, z2], axis=2) * ln[:, None, None]
        self.add(leaf(), np.concatenate([a, np.asarray(base, np.float64)[:, :, None]], 2),
                 role)

    def mesh(self, vertices, faces, role: int) -> None:
        """An explicit mesh (V, 3), (T, 3), once (curtains, a door's corridor)."""
        self.add(as_primitive(vertices, faces), np.eye(3, 4)[None], role)

    def build(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """vertices (V, 3) float64, faces (T, 3) int64, roles (T,) uint8, groups (T,)
        uint8: per primitive (in order of first use) all its instances."""
        verts, faces, roles, groups = [], [], [], []
        start = 0
        for prim, ts, rs, gs in self._batches.values():
            t = np.concatenate(ts) if len(ts) > 1 else ts[0]
            n, nv, nf = len(t), len(prim.vertices), len(prim.faces)
            v = np.einsum("nij,vj->nvi", t[:, :, :3], prim.vertices) + t[:, None, :, 3]
            verts.append(v.reshape(-1, 3))
            offs = start + nv * np.arange(n)
            faces.append((prim.faces[None] + offs[:, None, None]).reshape(-1, 3))
            roles.append(np.repeat(np.concatenate(rs), nf))
            groups.append(np.repeat(np.concatenate(gs), nf))
            start += n * nv
        if not verts:
            return (np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.uint8),
                    np.zeros(0, np.uint8))
        return (np.concatenate(verts), np.concatenate(faces), np.concatenate(roles),
                np.concatenate(groups))
