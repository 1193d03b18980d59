"""GL tests, run on both backends (EGL and OSMesa) through the gl_ctx fixture."""

import numpy as np
import pytest

from vhgen.body.skinning import bone_matrices, skin_vertices
from vhgen.camera import Intrinsics, backproject, pixel_rays
from vhgen.errors import RenderError
from vhgen.render.renderer import DepthLabelRenderer, Draw, GpuMesh
from vhgen.rotations import axis_rotation, rigid

INTR = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)


def _quad(x0, x1, y0, y1, z):
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def test_tilted_plane_depth_and_labels_exact(gl_ctx):
    """A plane n.X = c: every covered pixel's planar depth is c / (n . ray)."""
    n = np.array([0.3, -0.2, 1.0])
    c = 2.0
    xs, ys = np.meshgrid([-1.2, 1.2], [-0.9, 0.9])
    pts = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(4)])
    pts[:, 2] = (c - pts[:, 0] * n[0] - pts[:, 1] * n[1]) / n[2]  # z on the plane
    faces = np.array([[0, 1, 3], [0, 3, 2]])
    ren = DepthLabelRenderer(gl_ctx, INTR)
    ren.set_mesh(pts, faces, np.zeros((4, 4), int), np.tile([1.0, 0, 0, 0], (4, 1)),
                 np.array([7, 9], np.uint8), 1)
    depth, labels = ren.render(np.eye(4)[None])
    rays = pixel_rays(INTR)
    expected = c / (rays @ n)
    hit = depth > 0
    assert hit.sum() > 0.6 * depth.size
    np.testing.assert_allclose(depth[hit], expected[hit], rtol=2e-6)
    assert set(np.unique(labels[hit])) == {7, 9} and (labels[~hit] == 0).all()
    # back-projected hits lie on the plane
    p = backproject(INTR, np.where(hit, depth, 0.0))[hit]
    assert np.abs(p @ n - c).max() < 2e-5
    ren.release()


def test_occlusion_nearest_wins(gl_ctx):
    v1, f1 = _quad(-1, 1, -1, 1, 3.0)
    v2, f2 = _quad(-0.2, 0.2, -0.2, 0.2, 1.5)
    v = np.vstack([v1, v2])
    f = np.vstack([f1, f2 + 4])
    ren = DepthLabelRenderer(gl_ctx, INTR)
    ren.set_mesh(v, f, np.zeros((8, 4), int), np.tile([1.0, 0, 0, 0], (8, 1)),
                 np.array([1, 1, 2, 2], np.uint8), 1)
    depth, labels = ren.render(np.eye(4)[None])
    assert depth[59, 79] == pytest.approx(1.5, rel=1e-6) and labels[59, 79] == 2
    assert depth[59, 40] == pytest.approx(3.0, rel=1e-6) and labels[59, 40] == 1
    ren.release()


def test_gpu_skinning_matches_numpy_reference(gl_ctx):
    """Two bones with 50/50 weights: the rendered depth equals the depth of the mesh
    skinned in float64 by NumPy (a flat quad stays flat under a blended rigid motion)."""
    v, f = _quad(-0.5, 0.5, -0.4, 0.4, 0.0)
    joints = np.tile([0, 1, 0, 0], (4, 1))
    weights = np.tile([0.5, 0.5, 0.0, 0.0], (4, 1))
    m0 = rigid(axis_rotation("Y", 0.3), [0.1, 0.0, 2.0])
    m1 = rigid(axis_rotation("Y", 0.3), [0.3, 0.1, 2.2])
    mats = np.stack([m0, m1])
    ren = DepthLabelRenderer(gl_ctx, INTR)
    ren.set_mesh(v, f, joints, weights, np.array([3, 4], np.uint8), 2)
    depth, _ = ren.render(mats)
    sv = skin_vertices(v, joints, weights, mats)
    n = np.cross(sv[1] - sv[0], sv[3] - sv[0])
    expected = (n @ sv[0]) / (pixel_rays(INTR) @ n)
    hit = depth > 0
    assert hit.sum() > 500
    np.testing.assert_allclose(depth[hit], expected[hit], rtol=2e-6)
    ren.release()


def test_body_renders_with_all_visible_labels(gl_ctx, body):
    from vhgen.camera import look_at

    intr = Intrinsics(320, 240, 285.63, 285.63, 159.5, 119.5)
    ren = DepthLabelRenderer(gl_ctx, intr)
    ren.set_mesh(body.vertices, body.faces, body.joints, body.weights, body.face_labels,
                 body.num_bones)
    b = body.num_bones
    mats = bone_matrices(body.rig, np.broadcast_to(np.eye(3), (b, 3, 3)), body.rig.heads[0])
    w2c = look_at([0, 0.9, 2.6], [0, 0.85, 0])
    depth, labels = ren.render(w2c @ mats)
    hit = depth > 0
    assert np.array_equal(hit, labels > 0)
    assert 2.2 < depth[hit].min() and depth[hit].max() < 3.0
    seen = set(np.unique(labels[hit]).tolist())
    assert len(seen) >= 28  # frontal view of the rest pose shows nearly every part
    # subject faces the camera: their left leg (label 22, LU_leg) is on the image right
    cols = np.nonzero(labels == 22)[1]
    assert cols.mean() > intr.cx
    ren.release()


def test_bad_inputs_raise_render_errors(gl_ctx):
    ren = DepthLabelRenderer(gl_ctx, INTR)
    with pytest.raises(RenderError, match="before set_mesh"):
        ren.render(np.eye(4)[None])
    v, f = _quad(-1, 1, -1, 1, 2)
    with pytest.raises(RenderError, match="out of range"):
        ren.set_mesh(v, f, np.full((4, 4), 3), np.ones((4, 4)) / 4, np.ones(2, np.uint8), 2)
    ren.set_mesh(v, f, np.zeros((4, 4), int), np.ones((4, 4)) / 4, np.ones(2, np.uint8), 1)
    with pytest.raises(RenderError, match="bone matrices"):
        ren.render(np.eye(4)[None].repeat(3, 0))
    ren.release()


def test_unknown_backend():
    from vhgen.render.context import create_context

    with pytest.raises(RenderError, match="unknown GL backend"):
        create_context("vulkan")


def test_renderers_can_be_released_and_recreated(gl_ctx):
    """A released renderer's framebuffer must not break the next one on the same context."""
    v, f = _quad(-1, 1, -1, 1, 2)
    for _ in range(3):
        ren = DepthLabelRenderer(gl_ctx, INTR, incidence=True)
        ren.set_mesh(v, f, np.zeros((4, 4), int), np.tile([1.0, 0, 0, 0], (4, 1)),
                     np.ones(2, np.uint8), 1)
        depth, _ = ren.render(np.eye(4)[None])
        assert depth[59, 79] == pytest.approx(2.0)
        # the plane faces the optical axis: the incidence is the ray's cosine to it
        rays = pixel_rays(INTR)
        np.testing.assert_allclose(ren.incidence, np.where(
            depth > 0, 1 / np.linalg.norm(rays, axis=-1), 0), atol=2e-6)
        ren.release()


@pytest.mark.parametrize("wound", ["outward", "inward"])
def test_back_face_culling_changes_no_pixel(gl_ctx, wound):
    """A closed sphere (either winding) and an open shell in front of it, every triangle
    its own label: culled and unculled renders are identical (so the culled side is the far
    one and the labels of every run of triangles are looked up at the right offset);
    culling the near side instead would change them (culling really happens)."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    f = np.asarray(s.faces)
    f = f if wound == "outward" else f[:, ::-1]
    shell = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    keep = shell.vertices[shell.faces].mean(axis=1)[:, 2] < -0.1  # an open cap
    v = np.vstack([s.vertices + [0.1, 0.0, 3.0], shell.vertices + [-0.1, 0.0, 2.3]])
    faces = np.vstack([f, shell.faces[keep] + len(s.vertices)])
    labels = (np.arange(len(faces)) % 250 + 1).astype(np.uint8)
    n = len(v)
    args = (np.zeros((n, 4), int), np.tile([1.0, 0, 0, 0], (n, 1)), labels, 1)
    ren = DepthLabelRenderer(gl_ctx, INTR, incidence=True)
    views = []
    for cull in (True, False):
        mesh = ren.upload(v, faces, *args, cull=cull)
        views.append(ren.draw([Draw(mesh, np.eye(4)[None])]))
        if cull:
            assert [r[2] is not None for r in mesh.ranges] == [True, False]
            wrong = GpuMesh(mesh.vao, [], mesh.label_tex, False,
                            tuple((a, b, {"front": "back", "back": "front"}.get(c))
                                  for a, b, c in mesh.ranges))
            bad = ren.draw([Draw(wrong, np.eye(4)[None])])
        mesh.release()
    ren.release()
    culled, full = views
    assert (full.depth > 0).sum() > 2000
    np.testing.assert_array_equal(culled.ids, full.ids)
    np.testing.assert_array_equal(culled.depth, full.depth)
    np.testing.assert_array_equal(culled.incidence, full.incidence)
    sphere = (full.labels > 0) & (culled.depth > 2.8)
    assert (bad.depth[sphere] > full.depth[sphere] + 1e-3).mean() > 0.95
