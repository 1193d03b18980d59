"""The sensor model as GL compute passes (``sensor.backend: gl``).

The same :class:`~vhgen.sensor.sensor_config.SensorConfig` and effect specs as the CPU
sensor (:class:`~vhgen.sensor.simulator.SensorModel`, the reference), run as compute
shaders (GL 4.3; ``shaders/sensor_*.comp``) over the frame's depth, ids and incidence in
shader storage buffers, so the effects run where the frame was rendered. Each effect is a
:class:`GLPass` registered for its spec class, as the CPU stages are; an effect with no
pass (or parameters its pass cannot run) is refused when the sensor is loaded
(:meth:`EffectSpec.gl_unsupported`), never in a frame.

What differs from the CPU path, by design: arithmetic is float32 (the CPU's float64), and
the random numbers come from a counter-based hash (PCG's output permutation of (frame key,
effect, pixel, draw)) instead of the frame's Generator, which gives only the two-word key.
So a frame is identical run to run and its statistics match the CPU sensor's (measured in
``tests/render/test_sensor_gl.py`` and docs/realism.md), but its pixels are not the CPU's.
"""

from __future__ import annotations

from typing import Any, ClassVar, Generic, TypeVar

import numpy as np

from vhgen.errors import RenderError
from vhgen.render.context import is_software_renderer
from vhgen.render.renderer import _park, _shader
from vhgen.sensor.effects import (
    AxialNoise,
    CorrelationWindow,
    DisparityQuantisation,
    Dropout,
    LateralNoise,
    LensDistortion,
    ProjectorShadow,
    RangeDropout,
    RangeGate,
    Registration,
    SpeckleFilter,
)
from vhgen.sensor.pattern import PATTERN_PAD, dot_pattern
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.simulator import SensorOutput
from vhgen.sensor.spec import EffectSpec
from vhgen.sensor.stages import undistort_map
from vhgen.sensor.state import HOLE_CAUSES

S = TypeVar("S", bound=EffectSpec)
_PASSES: dict[type[EffectSpec], type[GLPass[Any]]] = {}

GL_VERSION_NEEDED = 430  # compute shaders and shader storage buffers
_LOCAL = 8  # work group edge of the per-pixel programs (8 x 8)
_ROWS = 32  # rows a work group of the row scans with one invocation a row
GPU_ROW_THREADS = 128  # invocations a row of the row scans on a GPU (row_scan.glsl)
# names the shaders use for the hole causes, effects and steps (#defines)
_CONSTANTS: dict[str, object] = {c.upper(): i for i, c in enumerate(HOLE_CAUSES)}
_CONSTANTS.update({k: i + 1 for i, k in enumerate((
    "LATERAL", "LENS",
    "DOTS", "ARGS", "ACCEPT", "SCATTER", "SPLAT", "ROWS", "MERGE", "COUNT", "REMOVE"))})
_AXIAL_MODELS = {"disparity": 0, "khoshelham": 1, "nguyen": 2, "barron_malik": 3}
_CHANNELS = ("val", "flags", "ids", "inc")  # the state, bindings 0-3 (spares 4-7)


def gl_effects() -> frozenset[type[EffectSpec]]:
    """The effect spec classes that have a GL pass."""
    return frozenset(_PASSES)


class GLPass(Generic[S]):
    """Base of every GL pass: compiled once per :class:`GLSensorModel`, ``run`` per frame
    on the model's buffers. Subclasses register for their spec (``spec=``)."""

    SPEC: ClassVar[type[EffectSpec]]

    def __init_subclass__(cls, spec: type[EffectSpec] | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if spec is not None:
            if spec in _PASSES:
                raise TypeError(f"effect {spec.name!r} has two GL passes")
            cls.SPEC = spec
            _PASSES[spec] = cls

    def __init__(self, spec: S, model: GLSensorModel, index: int):
        self.spec = spec
        self.model = model
        self.index = index  # the effect's position: its random stream

    def run(self) -> None:
        """Queue (:meth:`GLSensorModel.pointwise`) or dispatch this effect's steps."""
        raise NotImplementedError


class GLSensorModel:
    """Runs a :class:`SensorConfig` with GL compute passes on a moderngl context (GL 4.3
    or newer); same interface as :class:`~vhgen.sensor.simulator.SensorModel`.

    Per-pixel steps (the domain changes, range gate and dropout, axial noise, dropout,
    quantisation, the registration border, exact shadows, and the frame's load and the
    output encoding) are queued with :meth:`pointwise` and run fused, one program per run
    of them, when a pass that reads other pixels (:meth:`dispatch`) or the end of the frame
    needs their result: openni_525 runs its 11 per-pixel steps as 5 programs.

    ctx : a current moderngl context (see :mod:`vhgen.render.context`).
    row_threads : invocations a row in the row scans (shadows, registration, the speckle
        filter's runs; ``row_scan.glsl``): None picks 1 on a software renderer (llvmpipe,
        where work-group barriers cost more than walking a row) and
        :data:`GPU_ROW_THREADS` on a GPU. The output is the same either way.
    Raises :class:`RenderError` (one line naming ``sensor.backend: cpu``) when the context
    has no compute shaders, or when an effect has no GL pass.
    """

    def __init__(self, ctx, cfg: SensorConfig, row_threads: int | None = None):
        if ctx.version_code < GL_VERSION_NEEDED:
            raise RenderError(f"the GL sensor needs OpenGL 4.3 compute shaders; this context "
                              f"is {ctx.version_code // 100}.{ctx.version_code % 100 // 10} "
                              f"({ctx.info.get('GL_RENDERER', '?')}): use sensor.backend: cpu")
        self.ctx = ctx
        self.cfg = cfg
        if row_threads is None:
            soft = is_software_renderer(ctx.info.get("GL_RENDERER", ""))
            row_threads = 1 if soft else GPU_ROW_THREADS
        if row_threads not in (1, 2, 4, 8, 16, 32, 64, 128, 256):
            raise ValueError(f"row_threads {row_threads}: a power of two up to 256")
        self.row_threads = row_threads
        self.row_group = _ROWS if row_threads == 1 else 1  # rows a work group
        intr = cfg.intrinsics
        self.width, self.height = intr.width, intr.height
        self.fb = intr.fx * cfg.baseline_m
        self.intr = (intr.fx, intr.fy, intr.cx, intr.cy)
        n = self.width * self.height
        self._programs: dict[tuple[str, tuple[tuple[str, object], ...]], Any] = {}
        self.buffers: dict[str, Any] = {}
        self.spare: dict[str, Any] = {}
        for ch in _CHANNELS:
            self.buffers[ch] = ctx.buffer(reserve=4 * n)
            self.spare[ch] = ctx.buffer(reserve=4 * n)
        self.aux = [ctx.buffer(reserve=4 * n) for _ in range(4)]
        # zeros copied on the GPU where a pass needs a cleared buffer: moderngl's
        # Buffer.clear maps the buffer, which waits for every queued use of it (the
        # frames in flight), so the CPU and the GPU would take turns again
        self.zeros = ctx.buffer(bytes(4 * n))
        self.counts = ctx.buffer(reserve=4 * 8)
        self.out = ctx.buffer(reserve=4 * n)
        size = (self.width, self.height)
        self.textures = {k: ctx.texture(size, 1, dtype="f4")
                         for k in ("depth", "ids", "inc", "proj")}
        self.source: Any = None  # lens distortion's source pixels
        self.pattern: Any = None
        self.pattern_width = 0
        self.domain = "z"
        self.stream = 0  # the running effect's position: its random stream
        self._key = (0, 0)
        # queued per-pixel steps: (function, 4 floats, 4 ints, stream), and whether the
        # queue starts with the frame's load
        self._queue: list[tuple[str, tuple[float, ...], tuple[int, ...], int]] = []
        self._load: dict[str, object] | None = None
        self.passes: list[GLPass[Any]] = []
        for i, e in enumerate(cfg.effects):
            cls = _PASSES.get(type(e))
            gap = e.gl_unsupported()
            if cls is None or gap is not None:
                self.release()
                raise RenderError(f"effect {e.name} has no GL pass"
                                  + (f" ({gap[0]}: {gap[1]})" if gap and gap[0] else "")
                                  + ": use sensor.backend: cpu")
            self.passes.append(cls(e, self, i))
        self._check("compiling the sensor passes")

    # --- plumbing ------------------------------------------------------------------------
    def program(self, name: str, **defines: object):
        """The compute program of shader file ``name`` with ``defines`` (cached)."""
        k = (name, tuple(sorted(defines.items())))
        prog = self._programs.get(k)
        if prog is None:
            prog = self.ctx.compute_shader(_shader(name, {
                **_CONSTANTS, "ROW_THREADS": self.row_threads, "ROW_GROUP": self.row_group,
                "ROW_LOCAL": self.row_threads * self.row_group,
                **defines}))
            self._set(prog, size=(self.width, self.height), fb=self.fb, intr=self.intr,
                      key=self._key)
            self._programs[k] = prog
        return prog

    @staticmethod
    def _set(prog, **uniforms: object) -> None:
        """Set the uniforms the program uses (the compiler drops the ones it does not)."""
        for name, v in uniforms.items():
            if name in prog:
                prog[name].value = v

    def _bind_state(self) -> None:
        for i, ch in enumerate(_CHANNELS):
            self.buffers[ch].bind_to_storage_buffer(i)
            self.spare[ch].bind_to_storage_buffer(4 + i)

    def pointwise(self, function: str, a: tuple[float, ...] = (),
                  n: tuple[int, ...] = ()) -> None:
        """Queue the per-pixel step ``function`` of ``sensor_pointwise.glsl`` with up to 4
        numbers ``a`` and 4 integers ``n`` (run by the next :meth:`flush`)."""
        self._queue.append((function, tuple(map(float, a)), tuple(map(int, n)), self.stream))

    def flush(self, finish: bool = False) -> None:
        """Run the queued per-pixel steps as one program (with the output encoding after
        them when ``finish``)."""
        if not self._queue and self._load is None and not finish:
            return
        q = self._queue
        steps = " ".join(f"{f}(v, f, c, q, p, prm[{i}], iprm[{i}], {s}u);"
                         for i, (f, _, _, s) in enumerate(q))
        prog = self.program("sensor_chain.comp", STEPS=steps, NSTEPS=max(len(q), 1),
                            LOAD=int(self._load is not None), FINISH=int(finish),
                            FINISH_DISPARITY="true" if self.domain == "d" else "false")
        if q:
            prm = np.zeros((len(q), 4), np.float32)
            iprm = np.zeros((len(q), 4), np.int32)
            for i, (_, a, n, _) in enumerate(q):
                prm[i, :len(a)] = a
                iprm[i, :len(n)] = n
            # the compiler trims an array to the entries the steps read
            for name, arr in (("prm", prm), ("iprm", iprm)):
                if name in prog:
                    prog[name].write(arr[:prog[name].array_length].tobytes())
        self._set(prog, **(self._load or {}))
        if finish:
            self._set(prog, d_off=self.cfg.encoding.d_off)
            self.out.bind_to_storage_buffer(12)
        self._queue = []
        self._load = None
        self._bind_state()
        prog.run(-(-self.width // _LOCAL), -(-self.height // _LOCAL), 1)
        self.ctx.memory_barrier()

    def dispatch(self, prog, rows: bool = False, local: int = _LOCAL,
                 **uniforms: object) -> None:
        """Run ``prog`` over the image (one invocation per pixel, or a row scan with
        ``rows``: row_scan.glsl; ``local``: the program's work group edge) on the current
        state (bindings 0-3) and spares (4-7), after the queued per-pixel steps."""
        self.flush()
        self._set(prog, **uniforms)
        self._bind_state()
        if rows:
            prog.run(-(-self.height // self.row_group), 1, 1)  # row_scan.glsl
        else:
            prog.run(-(-self.width // local), -(-self.height // local), 1)
        self.ctx.memory_barrier()

    def dispatch_list(self, prog, args, offset: int, **uniforms: object) -> None:
        """Run ``prog`` with the work groups the GPU wrote to ``args`` at byte ``offset``
        (indirect dispatch over a list the GPU built)."""
        self.flush()
        self._set(prog, **uniforms)
        self._bind_state()
        prog.run_indirect(args, offset)
        self.ctx.memory_barrier()

    def swap(self, *channels: str) -> None:
        """The spares of ``channels`` (written by the last pass) become the state."""
        for ch in channels:
            self.buffers[ch], self.spare[ch] = self.spare[ch], self.buffers[ch]

    def to_depth(self) -> None:
        if self.domain == "d":
            self.pointwise("pw_invert")
            self.domain = "z"

    def to_disparity(self) -> None:
        if self.domain == "z":
            self.pointwise("pw_invert")
            self.domain = "d"

    def _check(self, what: str) -> None:
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RenderError(f"OpenGL error {what}: {err}")

    # --- a frame -------------------------------------------------------------------------
    def simulate(self, depth: np.ndarray, rng: np.random.Generator | None, *,
                 labels: np.ndarray | None = None, incidence: np.ndarray | None = None,
                 projector_depth: np.ndarray | None = None) -> SensorOutput:
        """The effects on a rendered frame, as
        :meth:`vhgen.sensor.simulator.SensorModel.simulate` (same inputs and outputs;
        ``disparity`` float32 values as float64). ``rng``: the frame's generator, from
        which two uint32 words are drawn as the frame's key when an effect is random."""
        cfg = self.cfg
        h, w = self.height, self.width
        z = np.asarray(depth)
        if z.shape != (h, w):
            raise ValueError(f"depth {z.shape} does not match the sensor {h}x{w}")
        if "incidence" in cfg.needs and incidence is None:
            raise ValueError(f"sensor {cfg.name} needs the incidence (|cos| of the angle "
                             "between surface normal and viewing ray)")
        if "projector_depth" in cfg.needs and projector_depth is None:
            raise ValueError(f"sensor {cfg.name} needs a projector-view depth image")
        if cfg.random and rng is None:
            raise ValueError(f"sensor {cfg.name} draws noise: pass the frame's Generator")
        key = self._frame_key(rng)
        tex = self.textures
        tex["depth"].write(np.ascontiguousarray(z, dtype="f4").tobytes())
        if labels is not None:
            tex["ids"].write(np.ascontiguousarray(labels, dtype="f4").tobytes())
        if incidence is not None:
            tex["inc"].write(np.ascontiguousarray(incidence, dtype="f4").tobytes())
        if projector_depth is not None and "projector_depth" in cfg.needs:
            tex["proj"].write(np.ascontiguousarray(projector_depth, dtype="f4").tobytes())
        for unit, name in enumerate(("depth", "ids", "inc", "proj")):
            tex[name].use(unit)
        self._run(key, {"depth_tex": 0, "ids_tex": 1, "inc_tex": 2, "proj_tex": 3,
                        "want_ids": labels is not None,
                        "inc_component": 0 if incidence is not None else -1,
                        **_glass_bits(())})
        return self._read(labels.dtype if labels is not None else None)

    def simulate_target(self, renderer, rng: np.random.Generator | None, *,
                        labels_dtype=np.uint32) -> SensorOutput:
        """The effects on the frame that ``renderer`` (a
        :class:`~vhgen.render.renderer.DepthLabelRenderer` on this context) last drew,
        read where it lies: its depth [+ incidence] and ids textures, with no upload. Same
        output as :meth:`simulate` on that view's arrays (``labels`` packed ids of
        ``labels_dtype``). The caller makes sure the target still holds the camera view
        (:attr:`vhgen.render.scene_renderer.SceneViews.in_target`); a sensor that needs a
        projector view takes :meth:`simulate`."""
        self._run_target(renderer, rng, ())
        return self._read(np.dtype(labels_dtype))

    @property
    def output_words(self) -> int:
        """The 32-bit words a frame's outputs take in a buffer (:meth:`queue_target`)."""
        return 4 * self.width * self.height

    def queue_target(self, renderer, rng: np.random.Generator | None, buffer, offset: int,
                     glass: tuple[int, ...] = ()) -> None:
        """:meth:`simulate_target` without waiting for it: the passes are queued and their
        outputs copied, by the GL when it gets there, into the GL ``buffer`` at byte
        ``offset`` (:attr:`output_words` words: the encoded depth and raw value, the
        flags, the disparity, the packed ids; :func:`sensor_output` or
        :func:`vhgen.render.frame_words.decode` read them). ``glass``: the scene classes
        that return nothing (window glass), taken out of the frame before the effects, as
        :meth:`vhgen.render.scene_renderer.SceneRenderer.render` takes them out of the
        read-back."""
        self._run_target(renderer, rng, glass)
        n4 = 4 * self.width * self.height
        for i, src in enumerate((self.out, self.buffers["flags"], self.spare["val"],
                                 self.buffers["ids"])):
            self.ctx.copy_buffer(buffer, src, n4, write_offset=offset + i * n4)

    def _run_target(self, renderer, rng: np.random.Generator | None,
                    glass: tuple[int, ...]) -> None:
        cfg = self.cfg
        if renderer.ctx is not self.ctx:
            raise RenderError("simulate_target: the renderer draws on another context")
        if (renderer.intr.width, renderer.intr.height) != (self.width, self.height):
            raise ValueError("simulate_target: the renderer's image is not the sensor's")
        if "incidence" in cfg.needs and not renderer.want_incidence:
            raise ValueError(f"sensor {cfg.name} needs the incidence: make the renderer "
                             "with incidence=True")
        if "projector_depth" in cfg.needs:
            raise ValueError(f"sensor {cfg.name} needs a projector view: use simulate()")
        if cfg.random and rng is None:
            raise ValueError(f"sensor {cfg.name} draws noise: pass the frame's Generator")
        renderer.color.use(0)
        renderer.ids_tex.use(1)
        self._run(self._frame_key(rng),
                  {"depth_tex": 0, "ids_tex": 1, "inc_tex": 0, "want_ids": True,
                   "inc_component": 1 if renderer.want_incidence else -1,
                   **_glass_bits(glass)})

    def _frame_key(self, rng: np.random.Generator | None) -> tuple[int, int]:
        """Two words of the frame's generator (0, 0 for a sensor that draws nothing)."""
        if not self.cfg.random:
            return 0, 0
        assert rng is not None
        k = rng.integers(0, 2**32, size=2, dtype=np.uint32)
        return int(k[0]), int(k[1])

    def _run(self, key: tuple[int, int], load: dict[str, object]) -> None:
        """Every pass on the frame whose textures are bound; ``load``: the load step's
        uniforms (texture units, ids and incidence present)."""
        if key != self._key:
            self._key = key
            for prog in self._programs.values():
                self._set(prog, key=key)
        self._load = load
        self.domain = "z"
        for p in self.passes:
            self.stream = p.index
            p.run()
        self.flush(finish=True)
        self._check("in the sensor passes")

    def _read(self, labels_dtype) -> SensorOutput:
        h, w = self.height, self.width
        out = np.frombuffer(self.out.read(), np.uint32).reshape(h, w)
        flags = np.frombuffer(self.buffers["flags"].read(), np.uint32).reshape(h, w)
        disp = np.frombuffer(self.spare["val"].read(), np.float32).reshape(h, w)
        ids = None
        if labels_dtype is not None:
            ids = np.frombuffer(self.buffers["ids"].read(), np.uint32).reshape(h, w)
        return sensor_output(out, flags, disp, ids, labels_dtype, self.cfg.encoding.raw11)

    def release(self) -> None:
        """Release the programs, buffers and textures."""
        _park(self.ctx)
        objs = [*self._programs.values(), *self.buffers.values(), *self.spare.values(),
                *self.aux, self.zeros, self.counts, self.out, *self.textures.values()]
        objs += [b for b in (self.pattern, self.source) if b is not None]
        for o in objs:
            o.release()
        self._programs = {}


def sensor_output(out: np.ndarray, flags: np.ndarray, disp: np.ndarray,
                  ids: np.ndarray | None, labels_dtype, raw11: bool) -> SensorOutput:
    """The :class:`SensorOutput` of the passes' output arrays (H, W) each: ``out`` uint32
    (millimetres in the low half, the raw value in the high half), ``flags`` uint32 (bit
    0 valid, bit c + 1 hole cause c), ``disp`` float32, ``ids`` uint32 packed ids (or
    None) returned as ``labels_dtype``; ``raw11``: whether the encoding keeps the raw
    value. (:func:`vhgen.render.frame_words.decode` makes what a frame keeps of them in
    one pass.)"""
    depth_mm = (out & 0xFFFF).astype(np.uint16)
    valid = depth_mm > 0
    raw = (out >> 16).astype(np.uint16) if raw11 else None
    lab = None
    if ids is not None and labels_dtype is not None:
        lab = ids.astype(labels_dtype)
    present = int(np.bitwise_or.reduce(flags, axis=None))  # one pass for every cause
    masks = {cause: (flags & np.uint32(2 << i)) != 0 for i, cause in enumerate(HOLE_CAUSES)
             if cause == "no_hit" or present & (2 << i)}
    holes = {c: int(np.count_nonzero(m)) for c, m in masks.items()}
    return SensorOutput(depth_mm, valid, lab, raw, disp.astype(np.float64), holes, masks)


def _glass_bits(classes: tuple[int, ...]) -> dict[str, tuple[int, int, int, int]]:
    """The load step's ``glass_a`` / ``glass_b`` uniforms: scene classes 0-255 as bits."""
    words = [0] * 8
    for c in classes:
        if not 0 <= int(c) < 256:
            raise ValueError(f"scene class {c} is not 0-255")
        words[int(c) >> 5] |= 1 << (int(c) & 31)
    return {"glass_a": tuple(words[:4]), "glass_b": tuple(words[4:])}  # type: ignore[dict-item]


# --- the passes, one per effect (specs in vhgen.sensor.effects) -------------------------

class RangeGatePass(GLPass[RangeGate], spec=RangeGate):
    def run(self) -> None:
        m = self.model
        m.to_depth()
        m.pointwise("pw_range_gate", (self.spec.z_min_m, self.spec.z_max_m))


class RangeDropoutPass(GLPass[RangeDropout], spec=RangeDropout):
    def run(self) -> None:
        p, m = self.spec, self.model
        m.to_depth()
        m.pointwise("pw_range_dropout", (p.z_start_m, p.z_end_m, p.power), (p.blob_px,))


class AxialNoisePass(GLPass[AxialNoise], spec=AxialNoise):
    def run(self) -> None:
        p, m = self.spec, self.model
        if p.model == "disparity":
            m.to_disparity()
        else:
            m.to_depth()
        m.pointwise("pw_axial_noise", (p.sigma_px, float(p.angle_term)),
                    (_AXIAL_MODELS[p.model],))


class DropoutPass(GLPass[Dropout], spec=Dropout):
    def run(self) -> None:
        p, m = self.spec, self.model
        m.to_depth()
        # albedo < 0.01 + 0.16 r  <=>  r > (albedo - 0.01) / 0.16; -1: no range rule
        r_max = (p.albedo - 0.01) / 0.16 if p.range_rule else -1.0
        if p.range_rule and r_max < 0:
            r_max = 0.0  # every range is too far: the CPU's r > r_max for r >= 0
        m.pointwise("pw_dropout", (float(np.cos(np.deg2rad(p.max_angle_deg))), r_max))


class QuantisationPass(GLPass[DisparityQuantisation], spec=DisparityQuantisation):
    def run(self) -> None:
        self.model.to_disparity()
        self.model.pointwise("pw_quantise", (self.spec.step_px,))


class ProjectorShadowPass(GLPass[ProjectorShadow], spec=ProjectorShadow):
    def __init__(self, spec: ProjectorShadow, model: GLSensorModel, index: int):
        super().__init__(spec, model, index)
        self.scan = model.program("sensor_scan.comp")

    def run(self) -> None:
        m = self.model
        if self.spec.method == "screen_space":
            m.to_disparity()
            m.dispatch(self.scan, rows=True, scale=1.0, right=m.cfg.baseline_m > 0,
                       cause=HOLE_CAUSES.index("shadow"))
        else:  # the projector's view was uploaded with the frame
            m.to_depth()
            m.pointwise("pw_exact_shadow", (self.spec.tolerance,))


class RegistrationPass(GLPass[Registration], spec=Registration):
    def __init__(self, spec: Registration, model: GLSensorModel, index: int):
        super().__init__(spec, model, index)
        self.scan = model.program("sensor_scan.comp")

    def run(self) -> None:
        p, m = self.spec, self.model
        if p.ir_offset_m != 0.0:
            m.to_disparity()
            m.dispatch(self.scan, rows=True, scale=abs(p.ir_offset_m) / m.cfg.baseline_m,
                       right=p.ir_offset_m > 0, cause=HOLE_CAUSES.index("registration"))
        if p.left_px or p.right_px or p.top_px or p.bottom_px:
            m.pointwise("pw_band", (), (p.left_px, p.right_px, p.top_px, p.bottom_px))


class LensDistortionPass(GLPass[LensDistortion], spec=LensDistortion):
    def __init__(self, spec: LensDistortion, model: GLSensorModel, index: int):
        super().__init__(spec, model, index)
        intr = model.cfg.intrinsics
        vs, us, inside = undistort_map(spec, intr)
        src = np.where(inside, vs * intr.width + us, 0xFFFFFFFF).astype(np.uint32)
        model.source = model.ctx.buffer(src.tobytes())
        self.prog = model.program("sensor_move.comp", EFFECT="LENS")

    def run(self) -> None:
        m = self.model
        m.source.bind_to_storage_buffer(8)  # (a gather: in either domain)
        m.dispatch(self.prog)
        m.swap(*_CHANNELS)


class LateralNoisePass(GLPass[LateralNoise], spec=LateralNoise):
    def __init__(self, spec: LateralNoise, model: GLSensorModel, index: int):
        super().__init__(spec, model, index)
        self.prog = model.program("sensor_move.comp", EFFECT="LATERAL")

    def run(self) -> None:
        # a gather copies values: it needs no domain (the CPU stage works in depth)
        m = self.model
        m.dispatch(self.prog, sigma_px=self.spec.sigma_px, nguyen=self.spec.model == "nguyen",
                   stream=self.index)
        m.swap(*_CHANNELS)


class CorrelationWindowPass(GLPass[CorrelationWindow], spec=CorrelationWindow):
    def __init__(self, spec: CorrelationWindow, model: GLSensorModel, index: int):
        super().__init__(spec, model, index)
        if spec.splat_radius_px ** 2 > 254.0:
            raise RenderError("correlation_window: splat radius above sqrt(254) px (15.9)")
        cfg = model.cfg
        if model.pattern is None:
            pat = dot_pattern(cfg.pattern_seed, cfg.intrinsics.height, cfg.intrinsics.width,
                              cfg.dot_density)
            model.pattern = model.ctx.buffer(np.ascontiguousarray(pat, np.uint32).tobytes())
            model.pattern_width = pat.shape[1]
        if model.width * model.height > 1 << 24:
            raise RenderError("the GL correlation window takes images of up to 2^24 pixels "
                              "(its splat keys hold a pixel index in 24 bits): use "
                              "sensor.backend: cpu")
        # window and footprint are compile-time constants: the loops unroll
        consts = {"HALF": spec.window // 2, "SPLAT_R": max(int(spec.splat_radius_px), 0),
                  "SPLAT_R2": f"{spec.splat_radius_px ** 2!r}"}
        self.progs = {s: model.program("sensor_window.comp", STEP=s, **consts)
                      for s in ("DOTS", "ARGS", "ACCEPT", "SCATTER", "SPLAT")}

    def run(self) -> None:
        p, m = self.spec, self.model
        m.to_disparity()
        for i, b in enumerate(m.aux[:2]):
            b.bind_to_storage_buffer(8 + i)
        m.pattern.bind_to_storage_buffer(10)
        m.aux[2].bind_to_storage_buffer(11)
        m.aux[3].bind_to_storage_buffer(12)
        m.counts.bind_to_storage_buffer(13)
        m.counts.write(np.zeros(8, np.uint32).tobytes())
        pr = self.progs
        m.dispatch(pr["DOTS"], pattern_width=m.pattern_width, pad=PATTERN_PAD)
        self._args(0)
        m.dispatch_list(pr["ACCEPT"], m.counts, 0, frac=p.frac, inlier_px=p.inlier_px)
        self._args(1)
        m.dispatch_list(pr["SCATTER"], m.counts, 12)
        m.dispatch(pr["SPLAT"])
        m.swap("val", "ids", "inc")

    def _args(self, which: int) -> None:
        """The work groups of list ``which`` (0 candidates, 1 accepted dots)."""
        prog = self.progs["ARGS"]
        prog["which"].value = which
        prog.run(1, 1, 1)
        self.model.ctx.memory_barrier()


class SpeckleFilterPass(GLPass[SpeckleFilter], spec=SpeckleFilter):
    def __init__(self, spec: SpeckleFilter, model: GLSensorModel, index: int):
        super().__init__(spec, model, index)
        self.progs = {s: model.program("sensor_speckle.comp", STEP=s)
                      for s in ("ROWS", "MERGE", "COUNT", "REMOVE")}

    def run(self) -> None:
        m = self.model
        m.aux[0].bind_to_storage_buffer(8)
        m.aux[1].bind_to_storage_buffer(9)
        m.ctx.copy_buffer(m.aux[1], m.zeros)  # cleared on the GPU, no wait (see zeros)
        m.dispatch(self.progs["ROWS"], rows=True)
        for step in ("MERGE", "COUNT"):
            m.dispatch(self.progs[step])
        m.dispatch(self.progs["REMOVE"], max_area=self.spec.max_area_px)
