"""The render step on tiny synthetic scenes: people and static geometry in one target."""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.camera import CameraPose, Intrinsics, pixel_rays
from vhgen.errors import RenderError
from vhgen.render.renderer import DepthLabelRenderer, Draw
from vhgen.render.scene_renderer import SceneRenderer
from vhgen.scene.description import FrameDescription, Person
from vhgen.scene.geometry import FLOOR, PERSON, PROP, WALL, StaticMesh, quad

INTR = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)


class _Quad:
    """A one-bone "body": a quad of part label 5 (stands in for a person)."""

    def __init__(self, x0, x1, y0, y1, z, label=5):
        self.vertices = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
        self.faces = np.array([[0, 1, 2], [0, 2, 3]])
        self.joints = np.zeros((4, 4), int)
        self.weights = np.tile([1.0, 0, 0, 0], (4, 1))
        self.face_labels = np.full(2, label, np.uint8)
        self.num_bones = 1


def _desc(people, static):
    return FrameDescription(0, 0, CameraPose(np.eye(4), 0.0, 0.0, 0.0), tuple(people),
                            tuple(static), None, np.random.PCG64(0).state)


def _person(instance, avatar):
    return Person(instance, avatar, 0, np.eye(4)[None], np.zeros((1, 3)), np.zeros(3))


def test_person_behind_box_gets_no_labels_where_box_is_nearer(gl_ctx):
    """Exact: a person plane at 3 m, half covered by a prop at 2 m, a wall at 4 m."""
    bodies = {0: _Quad(-1.0, 1.0, -0.6, 0.6, 3.0)}
    box = quad(np.array([[0.0, -2, 2.0], [2, -2, 2.0], [2, 2, 2.0], [0.0, 2, 2.0]]), PROP,
               "box")
    wall = quad(np.array([[-9, -9, 4.0], [9, -9, 4.0], [9, 9, 4.0], [-9, 9, 4.0]]), WALL,
                "wall")
    ren = DepthLabelRenderer(gl_ctx, INTR)
    scene = SceneRenderer(ren, bodies.__getitem__)
    view = scene.render(_desc([_person(1, 0)], [box, wall])).camera
    scene.release()
    ren.release()
    rays = pixel_rays(INTR)
    x3, y3 = rays[..., 0] * 3.0, rays[..., 1] * 3.0
    x2 = rays[..., 0] * 2.0
    inner = 0.02  # keep off the rasterised edges (one pixel is 0.02 m at 3 m)
    box_px = x2 > inner
    person_px = (np.abs(x3) < 1 - inner) & (np.abs(y3) < 0.6 - inner) & (x2 < -inner)
    assert view.labels[box_px].max() == 0 and view.instances[box_px].max() == 0
    assert (view.classes[box_px] == PROP).all()
    np.testing.assert_allclose(view.depth[box_px], 2.0, rtol=1e-6)
    assert (view.labels[person_px] == 5).all() and (view.instances[person_px] == 1).all()
    assert (view.classes[person_px] == PERSON).all()
    np.testing.assert_allclose(view.depth[person_px], 3.0, rtol=1e-6)
    # everywhere: a label exactly where the person is the nearest surface
    assert ((view.labels > 0) == (view.classes == PERSON)).all()
    wall_px = (view.classes == WALL)
    np.testing.assert_allclose(view.depth[wall_px], 4.0, rtol=1e-6)
    assert wall_px.sum() > 0.3 * wall_px.size


def test_two_people_occlude_each_other_exactly(gl_ctx):
    bodies = {0: _Quad(-1.0, 0.3, -1, 1, 2.5, label=3), 1: _Quad(-0.3, 1.0, -1, 1, 3.0,
                                                                 label=7)}
    ren = DepthLabelRenderer(gl_ctx, INTR, incidence=True)
    scene = SceneRenderer(ren, bodies.__getitem__)
    views = scene.render(_desc([_person(1, 0), _person(2, 1)], []), projector_baseline_m=0.075)
    cam = views.camera
    x = pixel_rays(INTR)[..., 0]
    front = np.abs(x * 2.5 - (-0.35)) < 0.6  # well inside person 1's quad
    back_only = (x * 3.0 > 0.35) & (x * 3.0 < 0.95) & (np.abs(pixel_rays(INTR)[..., 1] * 3) < .9)
    assert (cam.instances[front & (np.abs(pixel_rays(INTR)[..., 1] * 2.5) < .9)] == 1).all()
    assert (cam.instances[back_only] == 2).all() and (cam.labels[back_only] == 7).all()
    assert set(np.unique(cam.classes)) == {0, PERSON}
    assert cam.incidence is not None and views.projector_depth is not None
    # the projector sees the same scene shifted: its depth differs from the camera's
    assert not np.array_equal(views.projector_depth, cam.depth)
    # avatars stay resident: rendering again uploads nothing new
    meshes = dict(scene._meshes)
    scene.render(_desc([_person(1, 0), _person(2, 1)], []))
    assert scene._meshes == meshes
    scene.release()
    ren.release()


def test_static_draw_errors(gl_ctx):
    ren = DepthLabelRenderer(gl_ctx, INTR)
    floor = StaticMesh("floor", np.zeros((3, 3)), np.array([[0, 1, 2]]), np.array([FLOOR],
                                                                                 np.uint8))
    with pytest.raises(RenderError, match="skinned mesh first"):
        ren.upload_static(floor.vertices, floor.faces, floor.face_classes)
    b = _Quad(-1, 1, -1, 1, 2)
    m = ren.upload(b.vertices, b.faces, b.joints, b.weights, b.face_labels, 1)
    s = ren.upload_static(floor.vertices, floor.faces, floor.face_classes)
    with pytest.raises(RenderError, match="one 4x4"):
        ren.draw([Draw(s, np.eye(4)[None].repeat(2, 0))])
    with pytest.raises(RenderError, match="bone matrices"):
        ren.draw([Draw(m, np.eye(4)[None].repeat(2, 0))])
    m.release()
    s.release()
    ren.release()


@pytest.mark.parametrize("incidence", [False, True])
def test_packed_ids_are_exact_up_to_255(gl_ctx, incidence):
    """Part label, instance and class travel packed in one float channel: every value
    0..255 of each comes back exactly, with and without the incidence channel, and a static
    mesh's triangles keep their own (user) classes in one merged draw."""
    bodies = {0: _Quad(-2.0, 0.0, -2, 2, 2.0, label=255)}
    left = quad(np.array([[0.0, -2, 3.0], [9, -2, 3.0], [9, 0, 3.0], [0.0, 0, 3.0]]), 254,
                "left")
    right = quad(np.array([[0.0, 0, 3.0], [9, 0, 3.0], [9, 2, 3.0], [0.0, 2, 3.0]]), 7,
                 "right")
    ren = DepthLabelRenderer(gl_ctx, INTR, incidence=incidence)
    scene = SceneRenderer(ren, bodies.__getitem__)
    view = scene.render(_desc([_person(255, 0)], [left, right])).camera
    scene.release()
    ren.release()
    assert view.ids.dtype == np.uint32 and view.ids.shape == (INTR.height, INTR.width)
    assert view.labels.dtype == view.instances.dtype == view.classes.dtype == np.uint8
    rays = pixel_rays(INTR)
    person = rays[..., 0] * 2.0 < -0.05
    up, down = (rays[..., 0] * 3.0 > 0.05) & (rays[..., 1] * 3 < -0.05), \
        (rays[..., 0] * 3.0 > 0.05) & (rays[..., 1] * 3 > 0.05)
    assert (view.labels[person] == 255).all() and (view.instances[person] == 255).all()
    assert (view.classes[person] == PERSON).all()
    assert (view.classes[up] == 254).all() and (view.classes[down] == 7).all()
    assert (view.labels[up | down] == 0).all() and (view.instances[up | down] == 0).all()
    assert (view.ids[person] == 255 | 255 << 8 | PERSON << 16).all()
    assert (view.incidence is not None) == incidence
    if incidence:
        assert view.incidence is not None and view.incidence.shape == (INTR.height, INTR.width)
        rays = pixel_rays(INTR)
        np.testing.assert_allclose(view.incidence[up],
                                   1 / np.linalg.norm(rays, axis=-1)[up], atol=1e-5)


def test_static_geometry_written_into_reused_buffers_draws_as_uploaded(gl_ctx):
    """Frames with more, fewer, then more static triangles (the reused buffers grow):
    each draws exactly as a freshly uploaded mesh of the same geometry."""
    ren = DepthLabelRenderer(gl_ctx, INTR, incidence=True)
    b = _Quad(-1, 1, -1, 1, 9)
    person = ren.upload(b.vertices, b.faces, b.joints, b.weights, b.face_labels, 1)
    rng = np.random.default_rng(3)
    for n in (3, 1, 300, 40):
        quads = [quad(np.array([[x, -1.0, z], [x + 0.3, -1.0, z], [x + 0.3, 1.0, z + 0.2],
                                [x, 1.0, z + 0.2]]), int(c), "q")
                 for x, z, c in zip(rng.uniform(-1.5, 1.2, n), rng.uniform(2, 6, n),
                                    rng.integers(1, 4, n), strict=True)]
        v = np.concatenate([q.vertices for q in quads])
        f = np.concatenate([q.faces + 4 * k for k, q in enumerate(quads)])
        c = np.concatenate([q.face_classes for q in quads])
        reused = ren.draw([Draw(person, np.eye(4)[None]), Draw(ren.write_static(v, f, c),
                                                                np.eye(4))])
        fresh_mesh = ren.upload_static(v, f, c)
        fresh = ren.draw([Draw(person, np.eye(4)[None]), Draw(fresh_mesh, np.eye(4))])
        fresh_mesh.release()
        np.testing.assert_array_equal(reused.ids, fresh.ids)
        np.testing.assert_array_equal(reused.depth, fresh.depth)
        assert (reused.classes > 0).sum() > 100
    with pytest.raises(RenderError, match="out of range"):
        ren.write_static(np.zeros((3, 3)), np.array([[0, 1, 3]]), np.zeros(1, np.uint8))
    person.release()
    ren.release()


def test_many_avatars_never_release_a_mesh_the_frame_draws(gl_ctx, monkeypatch):
    """Frames of 3 (then 6) people drawn from 9 avatars, 4 resident: the resident meshes
    stay bounded (least recently used go) and never include a released one the frame still
    draws."""
    import vhgen.render.scene_renderer as scene_mod

    monkeypatch.setattr(scene_mod, "MAX_RESIDENT_AVATARS", 4)
    MAX_RESIDENT_AVATARS = 4

    bodies = {a: _Quad(-1.2 + 0.4 * k, -0.9 + 0.4 * k, -0.3, 0.3, 3.0 + 0.1 * a, label=a + 1)
              for a in range(9) for k in [a % 6]}
    built = []

    def body_of(a):
        built.append(a)
        return bodies[a]

    ren = DepthLabelRenderer(gl_ctx, INTR)
    scene = SceneRenderer(ren, body_of)
    rng = np.random.default_rng(5)
    for f in range(30):
        n = 3 if f < 20 else 6
        avatars = rng.choice(9, size=n, replace=False)
        people = [Person(k + 1, int(a), 0, np.eye(4)[None], np.zeros((1, 3)), np.zeros(3))
                  for k, a in enumerate(avatars)]
        view = scene.render(_desc(people, [])).camera
        assert len(scene._meshes) <= max(MAX_RESIDENT_AVATARS, n)
        # every person drawn, with their own avatar's labels (placed apart in x by avatar)
        seen = set(np.unique(view.labels[view.labels > 0]).tolist())
        assert {int(a) + 1 for a in avatars if a % 6 not in {b % 6 for b in avatars
                                                              if b != a}} <= seen
    assert len(built) > 9  # evicted avatars were uploaded again
    scene.release()
    ren.release()
