"""Which triangles of a mesh are faces of a closed surface, and which way they face.

A triangle of a closed, consistently wound surface that faces away from the camera is
never the nearest surface along its pixel's ray: the ray must cross a camera-facing
triangle of the same surface first. Such triangles can be dropped before rasterisation
(back-face culling) without changing what is seen, but only on closed surfaces: an open
one (a garment, a wall, a quad) shows its inside. Pure numpy; the renderer uses it when a
mesh is uploaded.
"""

from __future__ import annotations

import numpy as np

OPEN, OUTWARD, INWARD = 0, 1, -1


def components(faces: np.ndarray, num_vertices: int) -> np.ndarray:
    """(V,) int64 label of each vertex's connected component (the smallest vertex index
    in it); vertices joined by a triangle edge share a label. Union by minimum label with
    pointer jumping: a few vectorised rounds, no recursion, no scipy import."""
    f = np.asarray(faces, np.int64)
    a = f.reshape(-1)
    b = np.roll(f, -1, axis=1).reshape(-1)
    parent = np.arange(num_vertices, dtype=np.int64)
    while True:
        pa, pb = parent[a], parent[b]
        low = np.minimum(pa, pb)
        before = parent.copy()
        np.minimum.at(parent, pa, low)  # hook each root under the smaller root
        np.minimum.at(parent, pb, low)
        while True:  # pointer jumping until every vertex points at a root
            nxt = parent[parent]
            if np.array_equal(nxt, parent):
                break
            parent = nxt
        if np.array_equal(parent, before):
            return parent


def closed_components(faces: np.ndarray, num_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """The topology half of :func:`closed_sides` (it depends on the faces only, so a
    renderer can reuse it for every avatar of one mesh topology): the component of each
    triangle (T,) int64 in 0..C-1, and whether each component is closed (C,) bool.

    A connected component is closed when every directed edge (a, b) of its triangles
    occurs once and its reverse (b, a) once: watertight, manifold, consistently wound.
    """
    f = np.asarray(faces, np.int64)
    t = len(f)
    if t == 0:
        return np.zeros(0, np.int64), np.zeros(0, bool)
    n = np.int64(num_vertices)
    a = f.reshape(-1)
    b = np.roll(f, -1, axis=1).reshape(-1)
    code = a * n + b
    order = np.argsort(code, kind="stable")
    sorted_code = code[order]
    once = np.ones(len(code), bool)  # the directed edge occurs exactly once
    dup = sorted_code[1:] == sorted_code[:-1]
    once[order[1:][dup]] = False
    once[order[:-1][dup]] = False
    rev = b * n + a
    pos = np.clip(np.searchsorted(sorted_code, rev), 0, len(code) - 1)
    paired = once & (sorted_code[pos] == rev)
    face_ok = paired.reshape(t, 3).all(axis=1)
    _, comp = np.unique(components(f, num_vertices)[f[:, 0]], return_inverse=True)
    comp = comp.reshape(-1).astype(np.int64)
    ncomp = int(comp.max()) + 1
    closed = np.bincount(comp, weights=~face_ok, minlength=ncomp) == 0
    return comp, closed


def closed_sides(vertices: np.ndarray, faces: np.ndarray,
                 topology: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(T,) int8 per triangle: OUTWARD (1) when it belongs to a closed surface wound
    counter-clockwise seen from outside (positive signed volume), INWARD (-1) for a closed
    surface wound the other way, OPEN (0) otherwise (see :func:`closed_components`; pass
    its result as ``topology`` to skip recomputing it). A closed component of (near) zero
    volume is OPEN: its facing is undefined. vertices (V, 3) float, faces (T, 3) int.
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    if len(f) == 0:
        return np.zeros(0, np.int8)
    comp, closed = topology if topology is not None else closed_components(f, len(v))
    ncomp = len(closed)
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    vol6 = np.einsum("ij,ij->i", p0, np.cross(p1, p2))
    volume = np.bincount(comp, weights=vol6, minlength=ncomp) / 6.0
    # "near zero": relative to the component's extent cubed, so units do not matter
    vcomp = np.full(len(v), -1, np.int64)  # a vertex lies in exactly one component
    vcomp[f.reshape(-1)] = np.repeat(comp, 3)
    used = np.flatnonzero(vcomp >= 0)
    order = used[np.argsort(vcomp[used], kind="stable")]
    starts = np.flatnonzero(np.r_[True, np.diff(vcomp[order]) != 0])
    extent = (np.maximum.reduceat(v[order], starts, axis=0)
              - np.minimum.reduceat(v[order], starts, axis=0)).max(axis=1)
    flat = np.abs(volume) <= 1e-9 * extent ** 3
    side = np.where(~closed | flat, OPEN, np.where(volume > 0, OUTWARD, INWARD))
    return side[comp].astype(np.int8)


def vertex_cache_order(faces: np.ndarray, num_vertices: int, cache_size: int = 24
                       ) -> np.ndarray:
    """A permutation of the triangles (T,) int64 that reuses recently used vertices:
    Tipsify (Sander, Nehab and Barczak, "Fast triangle reordering for vertex locality and
    reduced overdraw", SIGGRAPH 2007). Fans around one vertex at a time, then moves to a
    vertex of the last fans that is still in a simulated FIFO cache of ``cache_size``.
    A GL implementation shades a vertex again when it has left its post-transform cache;
    llvmpipe also bins the triangles of a run together. The same triangles are drawn, in
    another order. Linear time; ~35 ms for a 32k-triangle body."""
    f = np.asarray(faces, np.int64)
    t = len(f)
    if t == 0:
        return np.zeros(0, np.int64)
    flat = f.reshape(-1)
    by_vertex = (np.argsort(flat, kind="stable") // 3).tolist()  # triangles of each vertex
    counts = np.bincount(flat, minlength=num_vertices)
    starts = np.concatenate([[0], np.cumsum(counts)]).tolist()
    live = counts.tolist()  # triangles of the vertex not emitted yet
    stamp = [-(cache_size + 1)] * num_vertices  # when the vertex last entered the cache
    emitted = [False] * t
    tri = f.tolist()
    out: list[int] = []
    dead_end: list[int] = []
    clock = cache_size + 1
    cursor = 0
    fan = int(flat[0])
    while fan >= 0:
        candidates = []
        for k in by_vertex[starts[fan]:starts[fan + 1]]:
            if emitted[k]:
                continue
            emitted[k] = True
            out.append(k)
            for v in tri[k]:
                dead_end.append(v)
                candidates.append(v)
                live[v] -= 1
                if clock - stamp[v] > cache_size:  # a miss: the vertex enters the cache
                    stamp[v] = clock
                    clock += 1
        # next fan: the candidate still in the cache longest, if its fan fits in it
        fan, best = -1, -1
        for v in candidates:
            if live[v] > 0:
                age = clock - stamp[v]
                priority = age if age + 2 * live[v] <= cache_size else 0
                if priority > best:
                    best, fan = priority, v
        while fan < 0 and dead_end:  # back along the recent vertices
            v = dead_end.pop()
            if live[v] > 0:
                fan = v
        while fan < 0 and cursor < num_vertices:  # or the next vertex with triangles left
            if live[cursor] > 0:
                fan = cursor
            cursor += 1
    return np.asarray(out, np.int64)
