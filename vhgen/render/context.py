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
from typing import Any

from vhgen.errors import RenderError

log = logging.getLogger(__name__)

BACKENDS = ("egl", "osmesa")

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
    """Create a headless moderngl context (GL 3.3 core or newer).

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
            ctx = moderngl.create_context(standalone=True, backend="egl",
                                          device_index=device_index)
        else:
            ctx = moderngl.create_context(standalone=True, context=OSMesaContext())
    except RenderError:
        raise
    except Exception as e:  # glcontext raises bare Exception/ValueError with its own text
        hint = ("install libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri" if backend == "egl"
                else "install libosmesa6")
        raise RenderError(f"cannot create a {backend} OpenGL context: {e} ({hint})") from None
    renderer = ctx.info.get("GL_RENDERER", "?")
    log.info("GL context: backend=%s renderer=%s version=%s", backend, renderer,
             ctx.info.get("GL_VERSION", "?"))
    if require_renderer and require_renderer.lower() not in renderer.lower():
        ctx.release()
        raise RenderError(f"GL_RENDERER is {renderer!r}, which lacks the required "
                          f"{require_renderer!r} (fallback to software rendering?)")
    return ctx
