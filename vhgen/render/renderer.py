"""Skinned depth + label rendering with moderngl.

The renderer receives a context (see :mod:`vhgen.render.context`); it never creates one.
One draw call per pose fills one RG32F target (planar depth, part label).
"""

from __future__ import annotations

from importlib import resources

import numpy as np

from vhgen.camera import Intrinsics
from vhgen.errors import RenderError

LABEL_TEX_WIDTH = 4096


def _shader(name: str) -> str:
    return resources.files("vhgen.render").joinpath("shaders", name).read_text()


class DepthLabelRenderer:
    """Renders a skinned mesh into planar depth (float32 m) and labels (uint8).

    One renderer per context: it owns the render target; :meth:`set_mesh` uploads a body
    (again for each avatar), :meth:`render` draws one pose.

    ctx : a moderngl context (current); intr : intrinsics (image size and projection);
    near, far : clip planes in metres, geometry outside is not drawn.
    """

    def __init__(self, ctx, intr: Intrinsics, near: float = 0.1, far: float = 20.0):
        self.ctx = ctx
        self.intr = intr
        self.projection = intr.gl_projection(near, far)
        self.color = ctx.texture((intr.width, intr.height), 2, dtype="f4")
        self.depth = ctx.depth_renderbuffer((intr.width, intr.height))
        self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)
        self._out = np.empty((intr.height, intr.width, 2), dtype=np.float32)
        self.program = None
        self.num_bones = 0
        self._mesh: list = []
        self.vao = None

    def _compile(self, num_bones: int) -> None:
        if self.program is not None and num_bones == self.num_bones:
            return
        if self.program is not None:
            self.program.release()
        defs = (f"#define MAX_BONES {num_bones}\n"
                f"#define LABEL_TEX_WIDTH {LABEL_TEX_WIDTH}\n")
        vs = _shader("skin.vert").replace("#version 330 core\n", "#version 330 core\n" + defs)
        fs = _shader("skin.frag").replace("#version 330 core\n", "#version 330 core\n" + defs)
        self.program = self.ctx.program(vertex_shader=vs, fragment_shader=fs)
        self.program["face_labels"].value = 0
        self.program["projection"].write(self.projection.T.astype("f4").tobytes())
        self.num_bones = num_bones

    def set_mesh(self, vertices, faces, joints, weights, face_labels, num_bones: int) -> None:
        """Upload a mesh: vertices (V,3), faces (T,3), joints (V,4) int, weights (V,4),
        face_labels (T,) uint8, for a rig of ``num_bones`` bones."""
        import moderngl

        joints = np.asarray(joints)
        if joints.ndim != 2 or joints.shape[1] != 4:
            raise RenderError(f"the vertex shader takes exactly 4 influences, got "
                              f"{joints.shape}")
        if joints.max() >= num_bones or joints.min() < 0:
            raise RenderError("joint index out of range of the bone array")
        self._release_mesh()
        self._compile(int(num_bones))
        ctx = self.ctx
        vbo_pos = ctx.buffer(np.ascontiguousarray(vertices, dtype="f4").tobytes())
        vbo_joints = ctx.buffer(np.ascontiguousarray(joints, dtype="i4").tobytes())
        vbo_weights = ctx.buffer(np.ascontiguousarray(weights, dtype="f4").tobytes())
        ibo = ctx.buffer(np.ascontiguousarray(faces, dtype="u4").tobytes())
        self.vao = ctx.vertex_array(self.program, [
            (vbo_pos, "3f", "in_position"),
            (vbo_joints, "4i", "in_joints"),
            (vbo_weights, "4f", "in_weights"),
        ], index_buffer=ibo, index_element_size=4)
        labels = np.asarray(face_labels, dtype=np.uint8)
        rows = -(-len(labels) // LABEL_TEX_WIDTH)
        padded = np.zeros(rows * LABEL_TEX_WIDTH, dtype=np.uint8)
        padded[:len(labels)] = labels
        label_tex = ctx.texture((LABEL_TEX_WIDTH, rows), 1, padded.tobytes(), dtype="u1")
        label_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._mesh = [self.vao, ibo, vbo_pos, vbo_joints, vbo_weights, label_tex]
        self.label_tex = label_tex
        self._check("uploading the mesh")

    def _check(self, what: str) -> None:
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RenderError(f"OpenGL error {what}: {err}")

    def render(self, camera_bones: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Draw one pose.

        camera_bones : (B, 4, 4) float64 world_to_camera @ M_b.
        Returns depth (H, W) float32 metres (0 = no hit) and labels (H, W) uint8.
        """
        import moderngl

        if self.vao is None:
            raise RenderError("render() before set_mesh()")
        m = np.asarray(camera_bones, dtype=np.float64)
        if m.shape != (self.num_bones, 4, 4):
            raise RenderError(f"expected ({self.num_bones}, 4, 4) bone matrices, got {m.shape}")
        # column-major for GL: transpose each matrix
        self.program["bones"].write(np.ascontiguousarray(
            np.swapaxes(m, -1, -2), dtype="f4").tobytes())
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        self.label_tex.use(0)
        self.vao.render(moderngl.TRIANGLES)
        self.fbo.read_into(self._out, components=2, dtype="f4")
        self._check("after draw")
        return self._out[..., 0].copy(), self._out[..., 1].astype(np.uint8)

    def _release_mesh(self) -> None:
        for obj in self._mesh:
            obj.release()
        self._mesh = []
        self.vao = None

    def release(self) -> None:
        self._release_mesh()
        for obj in (self.program, self.fbo, self.color, self.depth):
            if obj is not None:
                obj.release()
        self.program = None
