"""Which triangles lie on closed surfaces (and may be back-face culled)."""

from __future__ import annotations

import numpy as np
import trimesh

from vhgen.scene.topology import INWARD, OPEN, OUTWARD, closed_sides, components


def _sphere():
    s = trimesh.creation.icosphere(subdivisions=2)
    return np.asarray(s.vertices), np.asarray(s.faces)


def test_closed_sphere_faces_out_or_in():
    v, f = _sphere()
    assert (closed_sides(v, f) == OUTWARD).all()
    assert (closed_sides(v, f[:, ::-1]) == INWARD).all()
    # translation and scale do not change the verdict (signed volume, relative flatness)
    assert (closed_sides(v * 1e-3 + 50.0, f) == OUTWARD).all()


def test_open_or_broken_surfaces_are_never_culled():
    v, f = _sphere()
    assert (closed_sides(v, f[1:]) == OPEN).all()  # a hole
    g = f.copy()
    g[0] = g[0, ::-1]  # one triangle wound the wrong way
    assert (closed_sides(v, g) == OPEN).all()
    assert (closed_sides(v, np.vstack([f, f[:1]])) == OPEN).all()  # a duplicated face
    flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    # both sides of a single triangle: closed by the edge test, but of zero volume
    assert (closed_sides(flat, np.array([[0, 1, 2], [0, 2, 1]])) == OPEN).all()
    tube = trimesh.creation.cylinder(radius=0.2, height=1.0, sections=16)
    side = np.abs(tube.face_normals[:, 2]) < 0.5  # the wall without its caps
    assert (closed_sides(tube.vertices, tube.faces[side]) == OPEN).all()
    assert (closed_sides(tube.vertices, tube.faces) == OUTWARD).all()
    assert closed_sides(v, np.zeros((0, 3), int)).shape == (0,)


def test_components_are_judged_separately():
    v, f = _sphere()
    n = len(v)
    verts = np.vstack([v, v + 3.0, v - 3.0])
    faces = np.vstack([f, f[:, ::-1] + n, f[1:] + 2 * n])
    side = closed_sides(verts, faces)
    k = len(f)
    assert (side[:k] == OUTWARD).all() and (side[k:2 * k] == INWARD).all()
    assert (side[2 * k:] == OPEN).all()
    labels = components(faces, len(verts))
    assert len(np.unique(labels)) == 3 and labels[0] == 0 and labels[n] == n


def test_makehuman_body_is_closed_and_its_tights_are_not(asset_dir, shotton):
    from vhgen.body.avatar import build_body

    body = build_body(asset_dir, shotton)
    assert (closed_sides(body.vertices, body.faces) == OUTWARD).all()
    dressed = build_body(asset_dir, shotton, clothing=("tights",))
    side = closed_sides(dressed.vertices, dressed.faces)
    n = len(body.faces)
    # the body's triangles come first and stay closed; the garment is open
    assert (side[:n] == OUTWARD).all() and (side[n:] == OPEN).all() and len(side) > n


def test_vertex_cache_order_is_a_permutation_that_reuses_vertices():
    from vhgen.scene.topology import vertex_cache_order

    v, f = _sphere()
    rng = np.random.default_rng(0)
    shuffled = f[rng.permutation(len(f))]
    order = vertex_cache_order(shuffled, len(v))
    assert np.array_equal(np.sort(order), np.arange(len(f)))

    def misses(faces, size=24):  # a FIFO post-transform cache, as the order assumes
        cache, n = [], 0
        for x in faces.reshape(-1):
            if x not in cache:
                n += 1
                cache = (cache + [x])[-size:]
        return n

    assert misses(shuffled[order]) < 0.5 * misses(shuffled)
    assert len(vertex_cache_order(np.zeros((0, 3), int), 0)) == 0
