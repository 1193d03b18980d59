"""Shotton's depth-comparison feature, evaluated exactly as PCL's people detector does.

    f(I, x) = d(x + u / d(x)) - d(x + v / d(x))

* depth ``d`` in millimetres (uint16); ``u = (du1, dv1)``, ``v = (du2, dv2)`` are integer
  offsets in pixel-metres (int16, PCL's ``AttribLocation``). The probe position is
  ``x + u * scale`` with ``scale = 1000 / d(x)`` (PCL ``trees::focal = 1000``), i.e. ``u``
  pixels at 1 m, ``u / 2`` pixels at 2 m.
* Background and no-measurement pixels read as ``BACKGROUND_MM = 65535``: PCL's
  ``prepareForeGroundDepth`` (gpu/people/src/cuda/utils.cu) writes
  ``numeric_limits<unsigned short>::max()`` there and ``runThroughTree`` / the CUDA pass
  label such pixels "no label"/Background (29). :func:`prepare_depth` does the same to our
  0 = no measurement.
* A probe outside the image reads the nearest border pixel: PCL's ``Tex2Dfetcher``
  (gpu/people/src/trees.cpp) truncates the float position to int and clamps to
  ``[0, W-1] x [0, H-1]``; the CUDA kernel (multi_tree.cu) fetches with
  ``cudaAddressModeClamp``. Truncation and floor agree after clamping.
* Precision: ``float64`` follows the CPU ``runThroughTree`` (``double scale``, the
  position cast to ``float`` before truncation); ``float32`` follows the CUDA kernel
  (``float scale = f / depth``, float arithmetic). Both return the same integer feature
  except where a probe lands within float rounding of a pixel edge.
* The split test is ``f > thresh`` -> right child (PCL ``nid*2+2``), else left.
"""

from __future__ import annotations

import numba
import numpy as np

BACKGROUND_MM = 65535
FOCAL_SCALE = 1000.0  # PCL trees::focal: offsets are pixel-metres, depth millimetres


def prepare_depth(depth: np.ndarray) -> np.ndarray:
    """Depth as the feature reads it: 0 (no measurement) -> :data:`BACKGROUND_MM`.

    depth : (..., H, W) uint16 millimetres. Returns a new C-contiguous uint16 array.
    """
    d = np.array(depth, dtype=np.uint16, order="C", copy=True)
    d[d == 0] = BACKGROUND_MM
    return d


@numba.njit(inline="always")
def _probe64(img, x, y, du, dv, scale):
    h, w = img.shape
    # PCL trees.cpp: (float)(x + du*scale) in double, then static_cast<int>, then clamp
    u = int(np.float32(x + du * scale))
    v = int(np.float32(y + dv * scale))
    u = min(max(u, 0), w - 1)
    v = min(max(v, 0), h - 1)
    return np.int32(img[v, u])


@numba.njit(inline="always")
def _probe32(img, x, y, du, dv, scale32):
    h, w = img.shape
    # PCL multi_tree.cu: float arithmetic, tex2D point sampling = floor, clamp address mode
    u = int(np.floor(np.float32(x) + np.float32(du) * scale32))
    v = int(np.floor(np.float32(y) + np.float32(dv) * scale32))
    u = min(max(u, 0), w - 1)
    v = min(max(v, 0), h - 1)
    return np.int32(img[v, u])


@numba.njit(inline="always")
def feature_at(img, x, y, du1, dv1, du2, dv2):
    """One feature value (float64 path). img: (H, W) uint16 prepared depth."""
    d0 = img[y, x]
    scale = FOCAL_SCALE / np.float64(d0)
    return (_probe64(img, x, y, du1, dv1, scale)
            - _probe64(img, x, y, du2, dv2, scale))


@numba.njit(cache=True)
def _features_kernel(depths, img, xs, ys, offsets, use32, out):
    n = img.shape[0]
    k = offsets.shape[0]
    for i in range(n):
        im = depths[img[i]]
        x = xs[i]
        y = ys[i]
        d0 = im[y, x]
        scale = FOCAL_SCALE / np.float64(d0)
        scale32 = np.float32(FOCAL_SCALE) / np.float32(d0)
        for j in range(k):
            du1 = offsets[j, 0]
            dv1 = offsets[j, 1]
            du2 = offsets[j, 2]
            dv2 = offsets[j, 3]
            if use32:
                out[i, j] = (_probe32(im, x, y, du1, dv1, scale32)
                             - _probe32(im, x, y, du2, dv2, scale32))
            else:
                out[i, j] = (_probe64(im, x, y, du1, dv1, scale)
                             - _probe64(im, x, y, du2, dv2, scale))


def evaluate_features(depths: np.ndarray, img: np.ndarray, xs: np.ndarray, ys: np.ndarray,
                      offsets: np.ndarray, precision: str = "float64") -> np.ndarray:
    """Feature values of K offset pairs at N pixels.

    depths : (M, H, W) uint16 prepared depth (:func:`prepare_depth`), millimetres.
    img, xs, ys : (N,) image index, column, row of each pixel (its depth must be valid,
        i.e. not 0 and not BACKGROUND_MM: the scale 1000/d(x) is undefined there).
    offsets : (K, 4) int (du1, dv1, du2, dv2) pixel-metres.
    precision : "float64" (PCL CPU path, used everywhere in vhgen) or "float32" (CUDA path).
    Returns (N, K) int32 millimetre differences.
    """
    if precision not in ("float64", "float32"):
        raise ValueError(f"precision must be float64 or float32, not {precision!r}")
    out = np.empty((len(img), len(offsets)), dtype=np.int32)
    _features_kernel(np.ascontiguousarray(depths, dtype=np.uint16),
                     np.asarray(img, dtype=np.int64), np.asarray(xs, dtype=np.int64),
                     np.asarray(ys, dtype=np.int64),
                     np.asarray(offsets, dtype=np.int64).reshape(-1, 4),
                     precision == "float32", out)
    return out


def draw_offsets(rng: np.random.Generator, n: int, max_offset: int,
                 unary_fraction: float = 0.5) -> np.ndarray:
    """Candidate offset pairs (n, 4) int16, uniform integers in [-max_offset, max_offset].

    In a ``unary_fraction`` of them the second probe is the pixel itself (v = 0): the
    depth of a probe relative to the pixel is the most common useful test in Shotton's
    examples, and random pairs almost never produce it.
    """
    off = rng.integers(-max_offset, max_offset + 1, size=(n, 4), dtype=np.int64)
    unary = rng.random(n) < unary_fraction
    off[unary, 2:] = 0
    return off.astype(np.int16)
