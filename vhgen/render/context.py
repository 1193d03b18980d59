"""The one place that creates OpenGL contexts.

Backends, chosen by argument (never by an environment variable read here):

* ``egl``: headless EGL through glcontext (Mesa llvmpipe on CPUs, the NVIDIA driver on
  GPUs). Needs Debian's ``libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri``.
* ``osmesa``: Mesa's off-screen renderer through a small ctypes context object, because
  glcontext 3.x has no OSMesa backend. Needs ``libosmesa6``. Recent upstream Mesa
  releases dropped OSMesa, so EGL stays the primary path.

Every context's ``GL_RENDERER`` is logged and returned, so a GPU job that silently fell
back to llvmpipe is visible (and can be refused with ``require_renderer``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from vhgen.errors import RenderError

log = logging.getLogger(__name__)

BACKENDS = ("egl", "osmesa")
# a frame worker's process exits with this code when its GL context fails mid-shard
GL_LOST_EXIT = 70


def gl_failures() -> tuple[type[BaseException], ...]:
    """The exceptions of a failing GL context (moderngl's: a lost context or device, out
    of GPU memory, a framebuffer that cannot be read): a worker that meets one mid-shard
    cannot trust its context any more (see :func:`vhgen.pipeline.worker.FrameWorker.run`)."""
    import moderngl

    return (moderngl.Error,)

_OSMESA_RGBA = 0x1908  # GL_RGBA
_OSMESA_FORMAT = 0x22
_OSMESA_DEPTH_BITS = 0x30
_OSMESA_STENCIL_BITS = 0x31
_OSMESA_ACCUM_BITS = 0x32
_OSMESA_PROFILE = 0x33
_OSMESA_CORE_PROFILE = 0x34
_OSMESA_CONTEXT_MAJOR_VERSION = 0x36
_OSMESA_CONTEXT_MINOR_VERSION = 0x37
_GL_UNSIGNED_BYTE = 0x1401


class OSMesaContext:
    """The loader/context protocol moderngl's ``create_context(context=...)`` expects.

    Owns an OSMesa core-profile context made current on a private 1x1 buffer; vhgen
    renders into its own framebuffer objects, never into that buffer.
    """

    def __init__(self, major: int = 3, minor: int = 3):
        name = ctypes.util.find_library("OSMesa") or "libOSMesa.so.8"
        try:
            self._lib = ctypes.CDLL(name)
        except OSError as e:
            raise RenderError(f"OSMesa backend: cannot load {name} ({e}); on Debian install "
                              "'libosmesa6'") from None
        lib = self._lib
        lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
        lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
        lib.OSMesaMakeCurrent.restype = ctypes.c_int
        lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int,
                                          ctypes.c_int, ctypes.c_int]
        lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
        lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
        lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
        attrs = [_OSMESA_FORMAT, _OSMESA_RGBA, _OSMESA_DEPTH_BITS, 24, _OSMESA_STENCIL_BITS, 8,
                 _OSMESA_ACCUM_BITS, 0, _OSMESA_PROFILE, _OSMESA_CORE_PROFILE,
                 _OSMESA_CONTEXT_MAJOR_VERSION, major, _OSMESA_CONTEXT_MINOR_VERSION, minor, 0]
        arr = (ctypes.c_int * len(attrs))(*attrs)
        self._ctx = lib.OSMesaCreateContextAttribs(arr, None)
        if not self._ctx:
            raise RenderError(f"OSMesaCreateContextAttribs failed for a GL {major}.{minor} "
                              "core context")
        self._buf = (ctypes.c_ubyte * 4)()
        self.__enter__()

    def load(self, name: str) -> int:
        return self._lib.OSMesaGetProcAddress(name.encode()) or 0

    def __enter__(self) -> OSMesaContext:
        if not self._lib.OSMesaMakeCurrent(self._ctx, self._buf, _GL_UNSIGNED_BYTE, 1, 1):
            raise RenderError("OSMesaMakeCurrent failed")
        return self

    def __exit__(self, *exc: Any) -> None:
        pass  # one context per process (per actor): stay current

    def release(self) -> None:
        if self._ctx:
            self._lib.OSMesaDestroyContext(self._ctx)
            self._ctx = None


def create_context(backend: str = "egl", *, device_index: int = 0,
                   require_renderer: str | None = None):
    """Create a headless moderngl context (GL 3.3 core or newer; 4.3 where the driver has it).

    backend : ``"egl"`` or ``"osmesa"``.
    device_index : EGL device to use (counts EGL devices, not CUDA devices).
    require_renderer : if given, a substring that ``GL_RENDERER`` must contain (e.g.
        ``"NVIDIA"``), so a GPU job refuses to fall back to software rendering.
    Returns the moderngl.Context; its ``info["GL_RENDERER"]`` is logged.
    """
    import moderngl

    if backend not in BACKENDS:
        raise RenderError(f"unknown GL backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    try:
        if backend == "egl":
            ctx = _egl_context(moderngl, device_index)
        else:
            ctx = moderngl.create_context(standalone=True, context=OSMesaContext())
    except RenderError:
        raise
    except Exception as e:  # glcontext raises bare Exception/ValueError with its own text
        hint = ("install libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri" if backend == "egl"
                else "install libosmesa6")
        raise RenderError(f"cannot create a {backend} OpenGL context: {e} ({hint})") from None
    ctx.extra = {"flush": _gl_function(backend, "glFlush")}
    renderer = ctx.info.get("GL_RENDERER", "?")
    log.info("GL context: backend=%s renderer=%s version=%s", backend, renderer,
             ctx.info.get("GL_VERSION", "?"))
    if require_renderer and require_renderer.lower() not in renderer.lower():
        ctx.release()
        raise RenderError(f"GL_RENDERER is {renderer!r}, which lacks the required "
                          f"{require_renderer!r} (fallback to software rendering?)")
    return ctx


def gl_flush(ctx) -> None:
    """``glFlush`` on ``ctx`` (which moderngl does not offer): the commands queued so far
    go to the GPU now, so it works on them while this thread does something else, instead
    of when the next read-back asks for their results. Nothing on a context that
    :func:`create_context` did not make."""
    flush = (ctx.extra or {}).get("flush") if isinstance(ctx.extra, dict) else None
    if flush is not None:
        flush()


def _gl_function(backend: str, name: str):
    """A GL function without arguments or result, by the backend's own loader (None where
    it has no such function)."""
    if backend == "osmesa":
        lib = ctypes.CDLL(ctypes.util.find_library("OSMesa") or "libOSMesa.so.8")
        loader = lib.OSMesaGetProcAddress
    else:
        try:
            lib = ctypes.CDLL(ctypes.util.find_library("EGL") or "libEGL.so.1")
        except OSError:
            return None
        loader = lib.eglGetProcAddress
    loader.restype = ctypes.c_void_p
    loader.argtypes = [ctypes.c_char_p]
    addr = loader(name.encode())
    return ctypes.CFUNCTYPE(None)(addr) if addr else None


def _egl_context(moderngl, device_index: int):
    """An EGL context of GL 4.3 (compute shaders: the GL sensor) where the driver has it,
    else whatever it gives (3.3 core at least). NVIDIA's EGL makes exactly the version
    asked for (3.3 when none is), Mesa's the newest it has either way."""
    try:
        return moderngl.create_context(standalone=True, backend="egl",
                                       device_index=device_index, require=430)
    except Exception:  # noqa: BLE001  # no 4.3 here: the renderer alone needs 3.3
        return moderngl.create_context(standalone=True, backend="egl",
                                       device_index=device_index)


# --- choosing the EGL device of a GPU worker -------------------------------------------
# EGL numbers its devices in its own order (what glcontext's device_index counts), which
# need not match CUDA's. NVIDIA's EGL_NV_device_cuda tells each device's CUDA ordinal; the
# driver reports ordinals as CUDA sees them in this process, i.e. relative to
# CUDA_VISIBLE_DEVICES (Ray sets it to the GPU it assigned to the actor), so the actor's
# GPU is the device with CUDA ordinal 0. Software devices (Mesa llvmpipe/softpipe) carry
# EGL_MESA_device_software and no CUDA ordinal.

_EGL_EXTENSIONS = 0x3055
_EGL_CUDA_DEVICE_NV = 0x323A
_EGL_DRM_DEVICE_FILE_EXT = 0x3233
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "software rasterizer")


@dataclass(frozen=True)
class EGLDevice:
    """One EGL device as enumerated by ``eglQueryDevicesEXT``.

    index : position in EGL's enumeration (glcontext's ``device_index``).
    extensions : the device's extension strings.
    cuda_id : ``EGL_CUDA_DEVICE_NV`` (CUDA ordinal, relative to CUDA_VISIBLE_DEVICES), or
        None where the device has no CUDA ordinal (Mesa, or a GPU hidden from CUDA).
    drm_path : ``EGL_DRM_DEVICE_FILE_EXT`` (e.g. ``/dev/dri/card1``) if known.
    """

    index: int
    extensions: tuple[str, ...] = ()
    cuda_id: int | None = None
    drm_path: str | None = None

    @property
    def software(self) -> bool:
        return "EGL_MESA_device_software" in self.extensions

    def describe(self) -> str:
        kind = "software" if self.software else (
            f"CUDA {self.cuda_id}" if self.cuda_id is not None else "no CUDA ordinal")
        drm = f", {self.drm_path}" if self.drm_path else ""
        return f"EGL device {self.index} ({kind}{drm})"


def choose_egl_device(devices: Sequence[EGLDevice], cuda_visible_devices: str | None) -> EGLDevice:
    """The EGL device of a worker that was given a GPU (pure; no EGL calls).

    devices : the enumeration (:func:`query_egl_devices`).
    cuda_visible_devices : the worker's ``CUDA_VISIBLE_DEVICES`` as Ray set it (e.g. ``"3"``
        or ``"GPU-8f2e..."``), or None if unset.
    Returns the device whose CUDA ordinal is 0 (the first GPU visible to this process).
    Raises :class:`RenderError` (naming every device) when no GPU is visible, when only
    software devices exist, or when no device, or more than one, has CUDA ordinal 0.
    """
    listing = "; ".join(d.describe() for d in devices) or "none"
    if cuda_visible_devices is not None and cuda_visible_devices.strip() in ("", "-1",
                                                                            "NoDevFiles"):
        raise RenderError(f"a GPU was requested but CUDA_VISIBLE_DEVICES="
                          f"{cuda_visible_devices!r} hides every GPU (EGL devices: {listing})")
    gpus = [d for d in devices if d.cuda_id is not None and not d.software]
    if not gpus:
        raise RenderError("a GPU was requested but no EGL device has a CUDA ordinal "
                          f"(EGL_NV_device_cuda), so only software rendering is available "
                          f"(EGL devices: {listing}); is the NVIDIA driver's EGL installed "
                          "and the container started with graphics capability?")
    match = [d for d in gpus if d.cuda_id == 0]
    visible = cuda_visible_devices if cuda_visible_devices is not None else "unset"
    if len(match) != 1:
        why = "none has" if not match else f"{len(match)} have"
        raise RenderError(f"a GPU was requested (CUDA_VISIBLE_DEVICES={visible}) but {why} "
                          f"CUDA ordinal 0 among the EGL devices: {listing}")
    return match[0]


def is_software_renderer(renderer: str) -> bool:
    """True for Mesa's CPU rasterisers (``GL_RENDERER`` such as ``llvmpipe (LLVM 15...)``)."""
    r = renderer.lower()
    return any(s in r for s in SOFTWARE_RENDERERS)


def query_egl_devices() -> list[EGLDevice]:
    """Enumerate EGL devices through libEGL (EGL_EXT_device_enumeration / _query).

    Returns one :class:`EGLDevice` per device, in EGL's order. Raises :class:`RenderError`
    if libEGL or the device extensions are missing.
    """
    name = ctypes.util.find_library("EGL") or "libEGL.so.1"
    try:
        lib = ctypes.CDLL(name)
    except OSError as e:
        raise RenderError(f"cannot load {name} ({e}); on Debian install libegl1") from None
    lib.eglGetProcAddress.restype = ctypes.c_void_p
    lib.eglGetProcAddress.argtypes = [ctypes.c_char_p]

    def proc(fname: str, restype: Any, *argtypes: Any) -> Any:
        addr = lib.eglGetProcAddress(fname.encode())
        if not addr:
            raise RenderError(f"libEGL lacks {fname} (EGL_EXT_device_enumeration/query)")
        return ctypes.CFUNCTYPE(restype, *argtypes)(addr)

    query_devices = proc("eglQueryDevicesEXT", ctypes.c_uint, ctypes.c_int,
                         ctypes.POINTER(ctypes.c_void_p), ctypes.POINTER(ctypes.c_int))
    query_string = proc("eglQueryDeviceStringEXT", ctypes.c_char_p, ctypes.c_void_p,
                        ctypes.c_int)
    query_attrib = proc("eglQueryDeviceAttribEXT", ctypes.c_uint, ctypes.c_void_p, ctypes.c_int,
                        ctypes.POINTER(ctypes.c_ssize_t))
    n = ctypes.c_int(0)
    if not query_devices(0, None, ctypes.byref(n)):
        raise RenderError("eglQueryDevicesEXT failed")
    handles = (ctypes.c_void_p * max(n.value, 1))()
    if not query_devices(n.value, handles, ctypes.byref(n)):
        raise RenderError("eglQueryDevicesEXT failed")
    out = []
    for i in range(n.value):
        ext_raw = query_string(handles[i], _EGL_EXTENSIONS)
        exts = tuple(ext_raw.decode(errors="replace").split()) if ext_raw else ()
        cuda_id = None
        if "EGL_NV_device_cuda" in exts:
            v = ctypes.c_ssize_t(-1)
            if query_attrib(handles[i], _EGL_CUDA_DEVICE_NV, ctypes.byref(v)) and v.value >= 0:
                cuda_id = int(v.value)
        drm = None
        if "EGL_EXT_device_drm" in exts:
            raw = query_string(handles[i], _EGL_DRM_DEVICE_FILE_EXT)
            drm = raw.decode(errors="replace") if raw else None
        out.append(EGLDevice(i, exts, cuda_id, drm))
    return out


def create_gpu_context(cuda_visible_devices: str | None):
    """A moderngl context on this worker's GPU: EGL device chosen by
    :func:`choose_egl_device`, logged, and refused if it renders in software."""
    devices = query_egl_devices()
    dev = choose_egl_device(devices, cuda_visible_devices)
    ctx = create_context("egl", device_index=dev.index)
    renderer = ctx.info.get("GL_RENDERER", "?")
    log.info("GPU worker: CUDA_VISIBLE_DEVICES=%s -> %s, GL_RENDERER=%s", cuda_visible_devices,
             dev.describe(), renderer)
    if is_software_renderer(renderer):
        ctx.release()
        raise RenderError(f"a GPU was requested but {dev.describe()} renders with "
                          f"{renderer!r} (software); refusing to run on the CPU")
    return ctx
