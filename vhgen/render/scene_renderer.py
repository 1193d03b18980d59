"""The render step: every requested view of a whole frame description in one pass each.

People and static geometry are drawn into the same depth-tested target, so occlusion
between them is exact; the projector view (same scene, from +baseline along the
camera's x axis) is drawn only when a sensor effect needs it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from vhgen.body.avatar import Body
from vhgen.body.contact import body_contacts
from vhgen.camera import world_to_projector
from vhgen.errors import RenderError
from vhgen.render.renderer import DepthLabelRenderer, Draw, GpuMesh, View
from vhgen.scene.description import FrameDescription
from vhgen.scene.geometry import PERSON, StaticMesh, pack_ids
from vhgen.sensor.composite import real_depth_m

MAX_RESIDENT_AVATARS = 16  # ~1.1 MB of GPU buffers each


@dataclass(frozen=True, eq=False)
class SceneViews:
    """camera: the camera view; projector_depth (H, W) float32 metres or None;
    in_target: the renderer's target still holds exactly ``camera`` (no projector view
    drawn after it, no glass removed from the read-back, no real background composited),
    so a GL sensor may read the frame there (:meth:`GLSensorModel.simulate_target`)."""

    camera: View
    projector_depth: np.ndarray | None
    in_target: bool = False


def merge_static(meshes: tuple[StaticMesh, ...] | list[StaticMesh]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Static meshes concatenated in order: vertices (V, 3) float64, faces (T, 3) int64
    (re-indexed), face classes (T,) uint8."""
    starts = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return (np.concatenate([m.vertices for m in meshes]),
            np.concatenate([np.asarray(m.faces, np.int64) + k
                            for m, k in zip(meshes, starts, strict=True)]),
            np.concatenate([np.asarray(m.face_classes, np.uint8) for m in meshes]))


def upload_body(renderer: DepthLabelRenderer, body: Body) -> GpuMesh:
    """Put a body on the GPU; a dressed one (:mod:`vhgen.body.outfit`) with its garment
    offsets, its hands and its triangles' own scene classes (anything with a body's
    arrays will do: the dressed ones are optional)."""
    offsets = getattr(body, "offsets", None)
    classes = getattr(body, "face_classes", None)
    shared = len(body.faces) - getattr(body, "appended_faces", 0)
    if offsets is None or not offsets.any():  # nothing to press: the plain program
        return renderer.upload(body.vertices, body.faces, body.joints, body.weights,
                               body.face_labels, body.num_bones, face_classes=classes,
                               shared=shared)
    return renderer.upload(body.vertices, body.faces, body.joints, body.weights,
                           body.face_labels, body.num_bones, face_classes=classes,
                           offsets=offsets, press=body.press, shared=shared,
                           contacts=body_contacts(body.rig, body.vertices - offsets,
                                                  body.joints))


def composite(view: View, real_depth: np.ndarray, real_ids: int) -> View:
    """The people's ``view`` (drawn against the real depth, see
    :meth:`DepthLabelRenderer.set_background`) over the real frame: where a person was
    kept its depth, ids and incidence, elsewhere the real depth (float32 m, 0 = none) with
    the packed ids ``real_ids`` (holes too: a hole keeps the class of the surface behind
    it) and incidence 1."""
    hit = view.ids != 0  # a person's ids are never 0 (its class is person)
    incidence = None
    if view.incidence is not None:
        incidence = np.where(hit, view.incidence, np.float32(1.0))
    return View(np.where(hit, view.depth, real_depth), np.where(hit, view.ids,
                                                                 np.uint32(real_ids)),
                incidence)


class SceneRenderer:
    """Draws :class:`FrameDescription` s with one :class:`DepthLabelRenderer`; keeps the
    last few avatars' meshes on the GPU (``body_of`` builds a body on the CPU) and the
    last real background (``class_id`` gives the scene class id of its pixels)."""

    def __init__(self, renderer: DepthLabelRenderer, body_of: Callable[[int], Body],
                 class_id: Callable[[str], int] | None = None):
        self.renderer = renderer
        self.body_of = body_of
        self.class_id = class_id
        self._meshes: dict[int, GpuMesh] = {}
        self._background: tuple[int, np.ndarray] | None = None  # (index, float32 depth)

    def _resident(self, avatar_ids: list[int]) -> list[GpuMesh]:
        """The GPU meshes of ``avatar_ids`` (uploaded if needed), least recently used ones
        released beyond :data:`MAX_RESIDENT_AVATARS`, never one this frame draws."""
        need = list(dict.fromkeys(avatar_ids))
        for a in need:  # most recently used at the end
            mesh = self._meshes.pop(a, None)
            if mesh is None:
                mesh = upload_body(self.renderer, self.body_of(a))
            self._meshes[a] = mesh
        # the last len(need) entries are this frame's: only older ones go
        while len(self._meshes) > max(MAX_RESIDENT_AVATARS, len(need)):
            self._meshes.pop(next(iter(self._meshes))).release()
        return [self._meshes[a] for a in avatar_ids]

    def render(self, desc: FrameDescription, projector_baseline_m: float | None = None
               ) -> SceneViews:
        """The camera view and, when ``projector_baseline_m`` is given, the projector's
        depth of the same scene."""
        draws = self._draws(desc)
        w2c = desc.camera.world_to_camera
        if desc.background is not None:
            return SceneViews(self._over_background(desc, draws(w2c),
                                                    projector_baseline_m), None)
        cam = self.renderer.draw(draws(w2c))
        in_target = True
        if desc.no_return:  # window glass: the pixel gets no measurement (nor what is behind)
            glass = np.isin(cam.classes, desc.no_return)
            if glass.any():
                cam = replace(cam, depth=np.where(glass, np.float32(0), cam.depth))
                in_target = False
        proj = None
        if projector_baseline_m is not None:
            proj = self.renderer.draw(draws(world_to_projector(w2c, projector_baseline_m))).depth
            in_target = False
        return SceneViews(cam, proj, in_target)

    def submit(self, desc: FrameDescription) -> None:
        """Draw the camera view of ``desc`` (no real background) without reading it back:
        it stays in the renderer's target, window glass and all, for a GL sensor that
        reads it there (``GLSensorModel.queue_target(..., glass=desc.no_return)``) and a
        read-back queued after it (:meth:`DepthLabelRenderer.read_view_into`)."""
        if desc.background is not None:
            raise RenderError("submit: a frame over a real background is composited on the "
                              "CPU; use render()")
        self.renderer.submit(self._draws(desc)(desc.camera.world_to_camera))

    def _draws(self, desc: FrameDescription) -> Callable[[np.ndarray], list[Draw]]:
        """The draws of ``desc`` seen from a world-to-view transform (its people's meshes
        made resident, its static geometry written)."""
        meshes = self._resident([p.avatar_id for p in desc.people])
        people = list(zip(meshes, desc.people, strict=True))
        # all static geometry as one mesh, one draw: the same triangles in the same order
        # (so the same depth-test outcome) for a fraction of the GL objects and calls, in
        # buffers the renderer reuses from frame to frame
        static = []
        if desc.static:
            # the tuple itself is the key: frames sharing a layout (scene.layout_frames)
            # share it, and then the buffers already hold it
            held = self.renderer.static_for(desc.static)
            if held is None:
                held = self.renderer.write_static(*merge_static(desc.static), key=desc.static)
            static.append(held)

        def draws(w2v: np.ndarray) -> list[Draw]:
            return ([Draw(mesh, w2v @ p.bones, p.instance, PERSON) for mesh, p in people]
                    + [Draw(m, w2v) for m in static])

        return draws

    def _over_background(self, desc: FrameDescription, draws: list[Draw],
                         projector_baseline_m: float | None) -> View:
        """The people drawn against the frame's real background, composited over it."""
        bg = desc.background
        assert bg is not None
        if projector_baseline_m is not None:
            raise RenderError("a real background has no projector view (the sensor's "
                              "projector_shadow must be screen_space)")
        if self._background is None or self._background[0] != bg.index:
            self._background = (bg.index, real_depth_m(bg.depth_mm))
            self.renderer.set_background(self._background[1])
        if self.class_id is None:
            raise RenderError("a real background needs the scene's class ids (class_id)")
        cls = self.class_id(bg.class_name)
        real_ids = int(pack_ids(np.zeros(1, np.uint8), np.zeros(1, np.uint8),
                                np.full(1, cls, np.uint8))[0])  # label 0, instance 0
        return composite(self.renderer.draw(draws), self._background[1], real_ids)

    def release(self) -> None:
        for m in self._meshes.values():
            m.release()
        self._meshes = {}
