"""Skinned depth + label rendering with moderngl.

The renderer receives a context (see :mod:`vhgen.render.context`); it never creates one.
One draw fills two targets: planar depth (with the incidence cosine when asked for),
and the ids (part label, person instance, scene class) packed in one channel; a scene is
several draws into the same targets, depth-tested against each other.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np

from vhgen.body.contact import CLOTH_MARGIN_M, Contacts
from vhgen.body.skinning import dual_quaternions
from vhgen.camera import Intrinsics
from vhgen.errors import RenderError
from vhgen.scene.geometry import id_bytes
from vhgen.scene.topology import (
    INWARD,
    OUTWARD,
    closed_components,
    closed_sides,
    vertex_cache_order,
)

LABEL_TEX_WIDTH = 4096


SKINNING_MODES = ("lbs", "dqs")
_PARKING: dict[int, Any] = {}


def _park(ctx) -> None:
    """Bind a tiny framebuffer that is never released, so our framebuffers are never bound
    when released: moderngl rebinds the current framebuffer when it creates the next one,
    and a deleted one there is GL_INVALID_OPERATION."""
    fbo = _PARKING.get(id(ctx))
    if fbo is None:
        fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((1, 1))])
        _PARKING[id(ctx)] = fbo
    fbo.use()


def _shader(name: str, defines: dict[str, object]) -> str:
    """Shader source with ``#include "x.glsl"`` expanded and #defines after #version."""
    folder = resources.files("vhgen.render").joinpath("shaders")
    src = folder.joinpath(name).read_text()
    while '#include "' in src:
        start = src.index('#include "')
        end = src.index('"', start + 10)
        src = src[:start] + folder.joinpath(src[start + 10:end]).read_text() + src[end + 1:]
    head, rest = src.split("\n", 1)
    defs = "".join(f"#define {k} {v}\n" for k, v in defines.items())
    return f"{head}\n{defs}{rest}"


def write_bones(program, matrices: np.ndarray, mode: str) -> None:
    """Upload (B, 4, 4) rigid float64 bone transforms as LBS matrices or dual quaternions."""
    m = np.asarray(matrices, dtype=np.float64)
    if mode == "lbs":
        program["bones"].write(np.ascontiguousarray(np.swapaxes(m, -1, -2), dtype="f4").tobytes())
    else:
        real, dual = dual_quaternions(m)
        program["dq_real"].write(np.ascontiguousarray(real, dtype="f4").tobytes())
        program["dq_dual"].write(np.ascontiguousarray(dual, dtype="f4").tobytes())


def _defines(num_bones: int, mode: str) -> dict[str, object]:
    if mode not in SKINNING_MODES:
        raise RenderError(f"unknown skinning {mode!r}; choose one of {', '.join(SKINNING_MODES)}")
    d: dict[str, object] = {"MAX_BONES": num_bones, "LABEL_TEX_WIDTH": LABEL_TEX_WIDTH}
    if mode == "dqs":
        d["SKINNING_DQS"] = 1
    return d


@dataclass(eq=False)
class GpuMesh:
    """A mesh resident on the GPU: its vertex array, buffers and per-triangle label texture.

    ``static`` meshes carry scene classes in the texture and are drawn with one rigid
    transform; skinned meshes carry body-part labels (and a scene class per triangle
    where it is not the draw's). ``ranges`` are the runs of triangles drawn with one
    culling state: (first triangle, count, face culled or None). A dressed body
    (``contacts`` set) is drawn by the garment program (:mod:`vhgen.body.contact`).
    """

    vao: Any
    objects: list
    label_tex: Any
    static: bool
    ranges: tuple[tuple[int, int, str | None], ...] = ()
    contacts: Contacts | None = None

    def release(self) -> None:
        for obj in self.objects:
            obj.release()
        self.objects = []


def contact_uniforms(contacts: Contacts, bones: np.ndarray) -> dict[str, bytes]:
    """The garment program's contact uniforms for one draw's (B, 4, 4) bone matrices
    (camera frame): the hands (``press_*``) and the legs (``push_*``)."""
    p = contacts.posed(bones)
    # a sphere holding each flattened capsule: centre, half its length + its half width
    centre = 0.5 * (p["hand_a"] + p["hand_b"])
    reach = (0.5 * np.linalg.norm(p["hand_b"] - p["hand_a"], axis=1)
             + contacts.hand_radius * np.maximum(contacts.hand_width, 1.0))
    return {
        "press_reach": np.column_stack([centre, reach]).astype("f4").tobytes(),
        "press_a": np.column_stack([p["hand_a"], contacts.hand_radius]).astype("f4").tobytes(),
        "press_b": np.column_stack([p["hand_b"], contacts.hand_width]).astype("f4").tobytes(),
        "press_lateral": np.ascontiguousarray(p["hand_lateral"], dtype="f4").tobytes(),
        "push_a": np.column_stack([p["leg_a"], contacts.leg_ra]).astype("f4").tobytes(),
        "push_b": np.column_stack([p["leg_b"], contacts.leg_rb]).astype("f4").tobytes(),
    }


@dataclass(frozen=True, eq=False)
class Draw:
    """One mesh in a view: ``bones`` (B, 4, 4) float64 world_to_view @ M_b (a static mesh
    takes one (4, 4) world_to_view), ``instance`` 0..255 and ``draw_class`` (the scene
    class of a skinned mesh's pixels; static meshes carry theirs per triangle)."""

    mesh: GpuMesh
    bones: np.ndarray
    instance: int = 0
    draw_class: int = 0


@dataclass(frozen=True, eq=False)
class View:
    """What one draw of a whole scene leaves in the targets, (H, W) each: planar depth
    float32 metres (0 = no hit), ``ids`` uint32 (see :func:`pack_ids`; 0 = no hit), and
    the incidence (H, W) float32 when the renderer was made with ``incidence=True``: |cos|
    of the angle between the (flat) face normal and the pixel's viewing ray, in [0, 1].
    ``labels``, ``instances`` and ``classes`` are (H, W) uint8 views into ``ids`` (no
    copy; not contiguous)."""

    depth: np.ndarray
    ids: np.ndarray
    incidence: np.ndarray | None

    @property
    def labels(self) -> np.ndarray:
        """(H, W) uint8 body-part labels (0 = not a person)."""
        return id_bytes(self.ids)[..., 0]

    @property
    def instances(self) -> np.ndarray:
        """(H, W) uint8 person instance (0 = no person)."""
        return id_bytes(self.ids)[..., 1]

    @property
    def classes(self) -> np.ndarray:
        """(H, W) uint8 scene class."""
        return id_bytes(self.ids)[..., 2]


class DepthLabelRenderer:
    """Renders skinned and static meshes into planar depth (float32 m) and labels (uint8).

    One renderer per context: it owns the render target. :meth:`upload` puts a mesh on the
    GPU (any number may be resident), :meth:`draw` renders a list of them in one target,
    depth-tested against each other, so occlusion between people and geometry is exact.
    :meth:`set_mesh` / :meth:`render` are the one-mesh shorthand.

    ctx : a moderngl context (current); intr : intrinsics (image size and projection);
    near, far : clip planes in metres, geometry outside is not drawn.
    """

    def __init__(self, ctx, intr: Intrinsics, near: float = 0.1, far: float = 20.0,
                 skinning: str = "lbs", incidence: bool = False, background: bool = False):
        _defines(1, skinning)
        self.skinning = skinning
        self.want_incidence = bool(incidence)
        # a real depth frame as the depth test's far limit (see set_background); compiled
        # in only when asked for, so other jobs run the very same shader as before
        self.want_background = bool(background)
        self.background_tex: Any = None
        self.incidence: np.ndarray | None = None  # (H, W) float32 after render()
        self.ctx = ctx
        self.intr = intr
        self.projection = intr.gl_projection(near, far)
        size = (intr.width, intr.height)
        # depth alone, or depth and the incidence in one texel (only when a sensor effect
        # needs it: every effect that looks at surface orientation uses only the angle to
        # the viewing ray, so 1 float, not a 3-float normal); the packed ids in a second
        # target
        self._depth_components = 2 if self.want_incidence else 1
        self.color = ctx.texture(size, self._depth_components, dtype="f4")
        self.ids_tex = ctx.texture(size, 1, dtype="f4")
        self.depth = ctx.depth_renderbuffer(size)
        self.fbo = ctx.framebuffer(color_attachments=[self.color, self.ids_tex],
                                   depth_attachment=self.depth)
        self.program: Any = None
        self.garment_program: Any = None  # compiled when the first dressed body arrives
        self.num_bones = 0
        self._single: GpuMesh | None = None
        self._static: tuple[GpuMesh, int, int] | None = None  # (mesh, vertices, triangles)
        # what the static buffers hold: (key of write_static, the mesh it returned)
        self._static_key: tuple[object, GpuMesh] | None = None
        self._topologies: dict[tuple, tuple[tuple[np.ndarray, np.ndarray], np.ndarray]] = {}

    def _program(self, num_bones: int, garments: bool):
        defs = _defines(num_bones, self.skinning)
        if self.want_incidence:
            defs["WANT_INCIDENCE"] = 1
        if garments:
            defs["GARMENTS"] = 1
            defs["CLOTH_MARGIN"] = f"{CLOTH_MARGIN_M!r}"
        if self.want_background:
            defs["BACKGROUND_DEPTH"] = 1
        program = self.ctx.program(vertex_shader=_shader("skin.vert", defs),
                                   fragment_shader=_shader("skin.frag", defs))
        program["face_labels"].value = 0
        if self.want_background:
            program["background_depth"].value = 1
        program["projection"].write(self.projection.T.astype("f4").tobytes())
        return program

    def _compile(self, num_bones: int, garments: bool = False) -> None:
        if self.program is None or num_bones != self.num_bones:
            for p in (self.program, self.garment_program):
                if p is not None:
                    p.release()
            self.garment_program = None
            self.program = self._program(num_bones, False)
            self.num_bones = num_bones
        if garments and self.garment_program is None:
            self.garment_program = self._program(num_bones, True)

    def _topology(self, faces: np.ndarray, num_vertices: int
                  ) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
        """The closed components and the vertex-cache position of each triangle of a
        topology, cached (avatars share their topology: found once, ~60 ms)."""
        key = (faces.shape, hashlib.sha1(np.ascontiguousarray(faces).tobytes()).digest())
        cached = self._topologies.get(key)
        if cached is None:
            position = np.empty(len(faces), np.int64)
            position[vertex_cache_order(faces, num_vertices)] = np.arange(len(faces))
            cached = (closed_components(faces, num_vertices), position)
            if len(self._topologies) >= 8:
                self._topologies.pop(next(iter(self._topologies)))
            self._topologies[key] = cached
        return cached

    def _cull_ranges(self, vertices, faces, labels, cull: bool, shared: int = 0
                     ) -> tuple[np.ndarray, np.ndarray, tuple[tuple[int, int, str | None], ...]]:
        """Faces and labels reordered so that triangles of closed surfaces come first, each
        run in vertex-cache order (:func:`~vhgen.scene.topology.vertex_cache_order`: the
        same triangles, ~5% less of a frame's draw on llvmpipe), and the runs to draw: the
        closed ones with the side facing away from the camera culled (see
        :mod:`vhgen.scene.topology`), open ones with nothing culled.
        Culling halves the triangles a body sends to rasterisation and leaves what is seen
        unchanged: a closed surface's far side is always behind its near side (measured:
        ids identical; 0-3 silhouette pixels a frame where a far-side triangle used to tie
        the depth test now show the near side, < 0.4 mm apart). The projection does not
        flip y, so a triangle wound counter-clockwise seen from outside appears clockwise
        on screen when it faces the camera: GL's "back"; the far side is GL's "front".
        ``shared``: the first triangles are a topology other meshes share (a body under
        the appended parts of its outfit, which use vertices of their own)."""
        faces = np.asarray(faces)
        if not cull or len(faces) == 0:
            return faces, labels, ((0, len(faces), None),)
        p = self.projection
        far_side_of_outward = "front" if p[0, 0] * p[1, 1] > 0 else "back"
        near_side = {"front": "back", "back": "front"}[far_side_of_outward]
        if 0 < shared < len(faces):
            # a dressed body: the body's topology (shared by every avatar, cached) and its
            # own small parts (their vertices are their own: separate components)
            (head_comp, head_closed), head_pos = self._topology(faces[:shared], len(vertices))
            tail = faces[shared:]
            tail_comp, tail_closed = closed_components(tail, len(vertices))
            tail_pos = np.empty(len(tail), np.int64)
            tail_pos[vertex_cache_order(tail, len(vertices))] = np.arange(len(tail))
            topology = (np.concatenate([head_comp, tail_comp + len(head_closed)]),
                        np.concatenate([head_closed, tail_closed]))
            position = np.concatenate([head_pos, tail_pos + shared])
        else:
            topology, position = self._topology(faces, len(vertices))
        side = closed_sides(vertices, faces, topology)
        rank = np.where(side == OUTWARD, 0, np.where(side == INWARD, 1, 2))
        order = np.lexsort((position, rank))
        counts = np.bincount(rank, minlength=3)
        modes = (far_side_of_outward, near_side, None)
        ranges, start = [], 0
        for k in range(3):
            if counts[k]:
                ranges.append((start, int(counts[k]), modes[k]))
                start += int(counts[k])
        return faces[order], labels[order], tuple(ranges)

    def upload(self, vertices, faces, joints, weights, face_labels, num_bones: int,
               static: bool = False, cull: bool = True, face_classes=None, offsets=None,
               press=None, contacts: Contacts | None = None, shared: int = 0) -> GpuMesh:
        """Put a mesh on the GPU: vertices (V,3), faces (T,3), joints (V,4) int, weights
        (V,4), face_labels (T,) uint8 (body parts, or scene classes when ``static``), for a
        rig of ``num_bones`` bones. All meshes of one renderer share the rig size.
        ``cull``: the far side of closed surfaces is culled (open ones never are; skinning
        is rigid per bone, so a closed surface stays closed and keeps its facing).

        A dressed body (:class:`vhgen.body.avatar.Body`) also gives ``face_classes`` (T,)
        uint8 (a triangle's own scene class, 0 = the draw's), ``offsets`` (V, 3) (the
        garment's thickness over the skin at each vertex), ``press`` (V,) uint8 (its
        contact bits) and its ``contacts``: it is drawn by the garment program, where a
        hand resting on a garment presses it in and legs push skirts out
        (:mod:`vhgen.body.contact`, ``skin.vert``); ``shared``: its first triangles are
        the body's topology, the rest its outfit's own parts (found once per topology)."""

        joints = np.asarray(joints)
        if joints.ndim != 2 or joints.shape[1] != 4:
            raise RenderError(f"the vertex shader takes exactly 4 influences, got "
                              f"{joints.shape}")
        if joints.max() >= num_bones or joints.min() < 0:
            raise RenderError("joint index out of range of the bone array")
        dressed = offsets is not None
        if dressed and contacts is None:
            raise RenderError("a mesh with garment offsets needs its contacts")
        self._compile(int(num_bones), dressed)
        program = self.garment_program if dressed else self.program
        labels = np.asarray(face_labels, dtype=np.uint8)
        if face_classes is not None:
            # two bytes per triangle: part label, own scene class (0 = the draw's)
            labels = np.column_stack([labels, np.asarray(face_classes, dtype=np.uint8)])
        faces, labels, ranges = self._cull_ranges(vertices, faces, labels, cull, shared)
        ctx = self.ctx
        position = np.asarray(vertices, np.float64)
        buffers = []
        if dressed:
            extra = np.column_stack([np.asarray(offsets, np.float64),
                                     np.asarray(press, np.float64)])
            buffers.append((ctx.buffer(np.ascontiguousarray(extra, dtype="f4").tobytes()),
                            "4f", "in_offset"))
        vbo_pos = ctx.buffer(np.ascontiguousarray(position, dtype="f4").tobytes())
        vbo_joints = ctx.buffer(np.ascontiguousarray(joints, dtype="i4").tobytes())
        vbo_weights = ctx.buffer(np.ascontiguousarray(weights, dtype="f4").tobytes())
        ibo = ctx.buffer(np.ascontiguousarray(faces, dtype="u4").tobytes())
        vao = ctx.vertex_array(program, [
            (vbo_pos, "3f", "in_position"),
            (vbo_joints, "4i", "in_joints"),
            (vbo_weights, "4f", "in_weights"),
        ] + buffers, index_buffer=ibo, index_element_size=4)
        label_tex = self._label_texture(labels)
        mesh = GpuMesh(vao, [vao, ibo, vbo_pos, vbo_joints, vbo_weights, label_tex]
                       + [b[0] for b in buffers], label_tex, static, ranges,
                       contacts if dressed else None)
        self._check("uploading the mesh")
        return mesh

    def _label_texture(self, labels: np.ndarray):
        """The per-triangle texture (RG8UI, LABEL_TEX_WIDTH texels a row): r = label (or
        a static mesh's class), g = the triangle's own scene class (0 = the draw's)."""
        import moderngl

        rows = max(1, -(-len(labels) // LABEL_TEX_WIDTH))
        padded = np.zeros((rows * LABEL_TEX_WIDTH, 2), dtype=np.uint8)
        cols = labels.reshape(len(labels), -1)
        padded[:len(labels), :cols.shape[1]] = cols
        tex = self.ctx.texture((LABEL_TEX_WIDTH, rows), 2, padded.tobytes(), dtype="u1")
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return tex

    def upload_static(self, vertices, faces, face_classes) -> GpuMesh:
        """A rigid mesh in world coordinates, (V,3) float, (T,3) int, (T,) uint8 classes."""
        if self.program is None:
            raise RenderError("upload a skinned mesh first (it fixes the rig size)")
        n = len(vertices)
        # not culled: a few hundred triangles, rebuilt every frame, mostly open (walls)
        return self.upload(vertices, faces, np.zeros((n, 4), np.int32),
                           np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (n, 1)),
                           face_classes, self.num_bones, static=True, cull=False)

    def write_static(self, vertices, faces, face_classes, key: object = None) -> GpuMesh:
        """Like :meth:`upload_static`, into buffers this renderer keeps and reuses (grown
        when a frame needs more): for the per-frame static geometry, whose GL objects cost
        more to create and release every frame than to overwrite. The mesh stays owned by
        the renderer and is valid until the next call (never release it).

        key : an object that stands for this geometry (frames sharing a layout pass the
            same one and keep it alive), for :meth:`static_for`."""
        self._static_key = None
        if self.program is None:
            raise RenderError("upload a skinned mesh first (it fixes the rig size)")
        v = np.ascontiguousarray(vertices, dtype="f4")
        f = np.ascontiguousarray(faces, dtype="u4")
        labels = np.asarray(face_classes, dtype=np.uint8)
        if len(f) and int(f.max()) >= len(v):
            raise RenderError("static face index out of range of the vertices")
        slot = self._static
        if slot is None or len(v) > slot[1] or len(f) > slot[2]:
            if slot is not None:
                slot[0].release()
            cap_v = max(256, 1 << (max(len(v), 1) - 1).bit_length())
            cap_t = max(256, 1 << (max(len(f), 1) - 1).bit_length())
            mesh = self.upload_static(np.zeros((cap_v, 3)), np.zeros((cap_t, 3), np.int64),
                                      np.zeros(cap_t, np.uint8))
            slot = self._static = (mesh, cap_v, cap_t)
        mesh = slot[0]
        vbo_pos, ibo = mesh.objects[2], mesh.objects[1]
        vbo_pos.write(v.tobytes())
        ibo.write(f.tobytes())
        padded = np.zeros((mesh.label_tex.width * mesh.label_tex.height, 2), np.uint8)
        padded[:len(labels), 0] = labels
        mesh.label_tex.write(padded.tobytes())
        self._check("writing the static geometry")
        out = GpuMesh(mesh.vao, [], mesh.label_tex, True, ((0, len(f), None),))
        if key is not None:
            self._static_key = (key, out)
        return out

    def static_for(self, key: object) -> GpuMesh | None:
        """The mesh of the last :meth:`write_static` if it was written with ``key`` (the
        same object), else None: the buffers still hold that geometry."""
        if self._static_key is not None and self._static_key[0] is key:
            return self._static_key[1]
        return None

    def set_mesh(self, vertices, faces, joints, weights, face_labels, num_bones: int) -> None:
        """Upload the one mesh :meth:`render` draws (replacing the previous one)."""
        if self._single is not None:
            self._single.release()
            self._single = None
        self._single = self.upload(vertices, faces, joints, weights, face_labels, num_bones)

    def set_background(self, depth_m: np.ndarray) -> None:
        """The real depth (H, W) float32 planar metres (0 = no measurement) the following
        draws are tested against: a fragment at or behind it is discarded (see
        ``skin.frag``). Needs a renderer made with ``background=True``."""
        import moderngl

        if not self.want_background:
            raise RenderError("set_background() on a renderer made without background=True")
        z = np.ascontiguousarray(depth_m, dtype="f4")
        if z.shape != (self.intr.height, self.intr.width):
            raise RenderError(f"background depth {z.shape} is not the image "
                              f"{self.intr.height}x{self.intr.width}")
        if self.background_tex is None:
            self.background_tex = self.ctx.texture((self.intr.width, self.intr.height), 1,
                                                   dtype="f4")
            self.background_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.background_tex.write(z.tobytes())
        self._check("uploading the background depth")

    def _check(self, what: str) -> None:
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RenderError(f"OpenGL error {what}: {err}")

    def draw(self, draws: list[Draw]) -> View:
        """Draw ``draws`` into one cleared target and read it back (see :class:`View`)."""
        self.submit(draws)
        h, w = self.intr.height, self.intr.width
        k = self._depth_components
        out = np.empty((h, w, k) if k > 1 else (h, w), dtype=np.float32)
        self.fbo.read_into(out, components=k, dtype="f4")
        ids = np.empty((h, w), dtype=np.float32)
        self.fbo.read_into(ids, components=1, attachment=1, dtype="f4")
        self._check("after draw")
        incidence = None
        if self.want_incidence:
            incidence = np.ascontiguousarray(out[..., 1])
            self.incidence = incidence
            depth = np.ascontiguousarray(out[..., 0])
        else:
            depth = out
        return View(depth, ids.astype(np.uint32), incidence)

    @property
    def view_floats(self) -> int:
        """The float32 values a read-back of the targets holds (:meth:`read_view_into`)."""
        return 2 * self.intr.width * self.intr.height

    def read_view_into(self, buffer, offset: int) -> None:
        """Queue the read-back of the targets into the GL ``buffer`` at byte ``offset``
        (a pixel pack buffer: the GL copies when it gets there, nothing waits):
        :attr:`view_floats` float32, the depth texels (without the incidence), then the
        packed ids."""
        n = self.intr.width * self.intr.height
        self.fbo.read_into(buffer, components=1, dtype="f4", write_offset=offset)
        self.fbo.read_into(buffer, components=1, attachment=1, dtype="f4",
                           write_offset=offset + 4 * n)

    def submit(self, draws: list[Draw]) -> None:
        """Draw ``draws`` into one cleared target, without reading it back (the GL runs
        it when it gets there; :meth:`draw` reads it, or a GL sensor reads it in place)."""
        import moderngl

        if self.program is None:
            raise RenderError("draw() before any mesh was uploaded")
        if self.want_background:
            if self.background_tex is None:
                raise RenderError("draw() before set_background()")
            self.background_tex.use(1)
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx = self.ctx
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        culling = False
        for d in draws:
            m = np.asarray(d.bones, dtype=np.float64)
            if d.mesh.static:
                if m.shape != (4, 4):
                    raise RenderError(f"a static mesh takes one 4x4 transform, got {m.shape}")
                m = np.broadcast_to(m, (self.num_bones, 4, 4))
            elif m.shape != (self.num_bones, 4, 4):
                raise RenderError(f"expected ({self.num_bones}, 4, 4) bone matrices, "
                                  f"got {m.shape}")
            program = self.program if d.mesh.contacts is None else self.garment_program
            write_bones(program, m, self.skinning)
            if d.mesh.contacts is not None:
                for name, data in contact_uniforms(d.mesh.contacts, m).items():
                    program[name].write(data)
            program["labels_are_classes"].value = int(d.mesh.static)
            program["instance_id"].value = int(d.instance)
            program["draw_class"].value = int(d.draw_class)
            d.mesh.label_tex.use(0)
            for first, count, culled in d.mesh.ranges:
                if culled is not None:
                    ctx.cull_face = culled
                if (culled is not None) != culling:
                    culling = culled is not None
                    (ctx.enable if culling else ctx.disable)(moderngl.CULL_FACE)
                # gl_PrimitiveID restarts at 0 in every draw call
                program["prim_offset"].value = first
                d.mesh.vao.render(moderngl.TRIANGLES, vertices=3 * count, first=3 * first)
        if culling:
            ctx.disable(moderngl.CULL_FACE)

    def render(self, camera_bones: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Draw the :meth:`set_mesh` mesh in one pose.

        camera_bones : (B, 4, 4) float64 world_to_camera @ M_b.
        Returns depth (H, W) float32 metres (0 = no hit) and labels (H, W) uint8; with
        ``incidence=True`` the incidence of the same draw is in :attr:`incidence`.
        """
        if self._single is None:
            raise RenderError("render() before set_mesh()")
        view = self.draw([Draw(self._single, camera_bones)])
        return view.depth, view.labels

    def release(self) -> None:
        """Release the target, the program and the :meth:`set_mesh` mesh (meshes from
        :meth:`upload` belong to the caller, who releases them before this)."""
        _park(self.ctx)
        if self._single is not None:
            self._single.release()
            self._single = None
        if self._static is not None:
            self._static[0].release()
            self._static = None
        self._static_key = None
        for obj in (self.program, self.garment_program, self.fbo, self.color, self.ids_tex,
                    self.depth, self.background_tex):
            if obj is not None:
                obj.release()
        self.program = None
        self.garment_program = None


class GPUSkinner:
    """Reads back GPU-skinned vertex positions (transform feedback) with the same GLSL
    skinning code the renderer draws with, to measure it against the float64 reference."""

    def __init__(self, ctx, vertices, joints, weights, num_bones: int, skinning: str = "lbs"):
        self.ctx = ctx
        self.skinning = skinning
        self.num_bones = int(num_bones)
        self.n = len(vertices)
        defs = _defines(self.num_bones, skinning)
        self.program = ctx.program(vertex_shader=_shader("skin_feedback.vert", defs),
                                   varyings=["out_position"])
        self._bufs = [ctx.buffer(np.ascontiguousarray(vertices, dtype="f4").tobytes()),
                      ctx.buffer(np.ascontiguousarray(joints, dtype="i4").tobytes()),
                      ctx.buffer(np.ascontiguousarray(weights, dtype="f4").tobytes())]
        self.vao = ctx.vertex_array(self.program, [(self._bufs[0], "3f", "in_position"),
                                                   (self._bufs[1], "4i", "in_joints"),
                                                   (self._bufs[2], "4f", "in_weights")])
        self.out = ctx.buffer(reserve=self.n * 12)
        # a standalone context has no default framebuffer; draws need one bound
        self._rb = ctx.renderbuffer((1, 1))
        self._fbo = ctx.framebuffer(color_attachments=[self._rb])

    def positions(self, matrices: np.ndarray) -> np.ndarray:
        """(V, 3) float32 skinned positions for rigid (B, 4, 4) bone transforms."""
        import moderngl

        write_bones(self.program, matrices, self.skinning)
        self._fbo.use()
        self.vao.transform(self.out, mode=moderngl.POINTS, vertices=self.n)
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RenderError(f"OpenGL error in transform feedback: {err}")
        return np.frombuffer(self.out.read(), dtype=np.float32).reshape(self.n, 3).copy()

    def release(self) -> None:
        _park(self.ctx)
        for obj in (self.vao, self.out, *self._bufs, self.program, self._fbo, self._rb):
            obj.release()
