"""The reference path: a structured-light simulation the cheaper effects are measured against.

After Landau, Choo & Beling (2016), in the rectified rig (camera at the origin, projector
at +b along x, same intrinsics):

1. the projector's binary dot pattern (:func:`vhgen.sensor.pattern.dot_pattern`) lights
   each surface point; a pixel u of depth z sees the pattern at projector column u - d,
   d = f b / z, as the pixel-area average of the binary dots (linear interpolation);
   points the projector cannot see (projector-view depth) stay dark;
2. IR intensity in 10-bit units: I = P * rho * 5.90e8 * cos(theta) / r_mm^2, with
   multiplicative Gamma(4.54, 0.196) and additive N(-0.126, 10.4^2) noise, clipped to
   [0, 1023];
3. integer disparity by zero-mean normalised cross-correlation (ZNCC) of 9x9 windows
   against the pattern over ``search_px`` candidates (box filters, one pass per candidate);
   a pixel is invalid when its window is flat (no dots, or unlit) or the best ZNCC is
   below ``min_zncc``, or the best candidate lies on the search boundary;
4. refinement to 1/8 px: ZNCC against the pattern shifted by k/8 px, k = -4..3, around
   the integer best (ZNCC rather than SAD, so the unknown IR gain cancels);
5. d -> z = f b / d downstream, like the device.

Cost is O(P * candidates) box filters: seconds per 640x480 frame in NumPy.
"""

from __future__ import annotations

import numpy as np

from vhgen.sensor.effects import StructuredLight
from vhgen.sensor.pattern import PATTERN_PAD
from vhgen.sensor.stage import Stage
from vhgen.sensor.stages import exact_shadow
from vhgen.sensor.state import SensorState


def _shifted(pattern: np.ndarray, shift: float, width: int, pad: int) -> np.ndarray:
    """The pattern as seen by camera columns 0..width-1 for disparity ``shift`` px:
    P(u - shift), linearly interpolated (pixel-area average of binary dots)."""
    x = np.arange(width, dtype=np.float64) - shift + pad
    i0 = np.floor(x).astype(np.int64)
    f = x - i0
    i0 = np.clip(i0, 0, pattern.shape[1] - 2)
    return (1.0 - f) * pattern[:, i0] + f * pattern[:, i0 + 1]


def _box(a: np.ndarray, n: int) -> np.ndarray:
    # imported here: only the reference effect needs scipy.ndimage (0.15 s to import),
    # and every frame worker imports this module
    from scipy.ndimage import uniform_filter

    return uniform_filter(a, size=n, mode="constant")


def ir_image(z: np.ndarray, valid: np.ndarray, lit: np.ndarray, pattern: np.ndarray,
             pad: int, fb: float, ranges_mm: np.ndarray, cos: np.ndarray, albedo: float,
             rng: np.random.Generator | None) -> np.ndarray:
    """Simulated 10-bit IR image (float64)."""
    h, w = z.shape
    d = np.zeros_like(z)
    np.divide(fb, z, out=d, where=valid)
    x = np.arange(w)[None, :] - d + pad
    i0 = np.clip(np.floor(x).astype(np.int64), 0, pattern.shape[1] - 2)
    f = x - np.floor(x)
    rows = np.arange(h)[:, None]
    p = (1.0 - f) * pattern[rows, i0] + f * pattern[rows, i0 + 1]
    r2 = np.where(valid, ranges_mm, 1.0) ** 2
    inten = np.where(valid & lit, p * albedo * 5.90e8 * cos / r2, 0.0)
    if rng is not None:
        inten = inten * rng.gamma(4.54, 0.196, size=inten.shape) + \
            rng.normal(-0.126, 10.4, size=inten.shape)
    return np.clip(inten, 0.0, 1023.0)


def match(ir: np.ndarray, pattern: np.ndarray, pad: int, d_lo: int, search_px: int,
          window: int, min_zncc: float) -> tuple[np.ndarray, np.ndarray]:
    """Block matching of the IR image against the pattern. Returns (d px, valid)."""
    h, w = ir.shape
    n = window
    m_i = _box(ir, n)
    v_i = _box(ir * ir, n) - m_i * m_i
    flat_i = v_i < 1e-3
    best = np.full((h, w), -np.inf)
    best_d = np.zeros((h, w), dtype=np.int64)
    pat = pattern.astype(np.float64)
    m_p_full = _box(pat, n)
    v_p_full = _box(pat * pat, n) - m_p_full * m_p_full
    cols = np.arange(w)
    for dd in range(d_lo, d_lo + search_px):
        idx = np.clip(cols - dd + pad, 0, pat.shape[1] - 1)
        ref = pat[:, idx]
        m_p = m_p_full[:, idx]
        v_p = v_p_full[:, idx]
        cov = _box(ir * ref, n) - m_i * m_p
        den = np.sqrt(np.maximum(v_i * v_p, 1e-12))
        z = np.where(v_p > 1e-6, cov / den, -1.0)
        better = z > best
        best = np.where(better, z, best)
        best_d = np.where(better, dd, best_d)
    ok = ~flat_i & (best >= min_zncc) & (best_d > d_lo) & (best_d < d_lo + search_px - 1)
    # 1/8 px refinement around each integer best, per distinct integer disparity
    frac = np.zeros((h, w))
    for dd in np.unique(best_d[ok]):
        sel = ok & (best_d == dd)
        top = np.full((h, w), -np.inf)
        for k in range(-4, 4):
            ref = _shifted(pat, dd + k / 8.0, w, pad)
            m_p = _box(ref, n)
            v_p = _box(ref * ref, n) - m_p * m_p
            cov = _box(ir * ref, n) - m_i * m_p
            zz = cov / np.sqrt(np.maximum(v_i * v_p, 1e-12))
            better = sel & (zz > top)
            top = np.where(better, zz, top)
            frac = np.where(better, k / 8.0, frac)
    return np.where(ok, best_d + frac, 0.0), ok


class StructuredLightStage(Stage[StructuredLight], spec=StructuredLight):
    """The structured-light reference path (see the module docstring)."""

    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        if s.pattern is None or s.ray_norm is None:
            raise ValueError("structured_light needs the dot pattern and the viewing rays")
        z = s.to_depth()
        lit = ~exact_shadow(s, 0.01)
        ranges = z * s.ray_norm * 1000.0
        cos = s.incidence_cos() if s.incidence is not None else np.ones_like(z)
        if p.ir_noise and rng is None:
            raise ValueError("structured_light with ir_noise draws noise: pass a Generator")
        ir = ir_image(z, s.valid, lit, s.pattern.astype(np.float64), PATTERN_PAD, s.fb,
                      ranges, cos, p.albedo, rng if p.ir_noise else None)
        d, ok = match(ir, s.pattern, PATTERN_PAD, p.d_min_px, p.search_px, p.window,
                      p.min_zncc)
        lost = s.valid & ~ok
        s.holes["matching"] = s.hole("matching") | lost
        s.d = d
        s.z = None
        s.valid = ok
        s.domain = "d"
