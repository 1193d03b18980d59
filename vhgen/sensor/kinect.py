"""Kinect v1 / PrimeSense depth sensor effects, NumPy, float64 where it matters.

Rectified geometry: IR camera at the origin, projector at +baseline along x. Disparity
``d = f * b / z`` in pixels. The raw value the device reports is ``k_d = d_off - 8 d``
(1/8 px units); we quantise ``d`` to 1/8 px with *round half up*
(``floor(8 d + 0.5) / 8``) and convert back with the same f*b, so quantisation is the
only change to a noiseless depth.

Effects implemented here (ordered as the pipeline applies them):

* axial disparity noise, N(0, sigma_d) px, before quantisation (Khoshelham-Elberink
  report sigma_d ~ 0.062 px; Nguyen et al. 0.07-0.08 px at 1-4 m);
* range gating: valid iff ``z_min <= z <= z_max`` and the pixel hit something;
* 1/8 px disparity quantisation;
* output encoding to uint16 millimetres, 0 = no measurement.

Invalid pixels are tracked with a boolean mask and never inverted, so no inf/NaN travels.
"""

from __future__ import annotations

import numpy as np


def disparity_from_depth(z: np.ndarray, focal_px: float, baseline_m: float,
                         valid: np.ndarray) -> np.ndarray:
    """d = f b / z (float64 px) where ``valid``; 0 elsewhere."""
    z = np.asarray(z, np.float64)
    out = np.zeros(z.shape, dtype=np.float64)
    np.divide(focal_px * baseline_m, z, out=out, where=valid)
    return out


def quantise_disparity(d: np.ndarray, step: float = 0.125) -> np.ndarray:
    """Round disparity to multiples of ``step`` px, half up: floor(d/step + 0.5) * step."""
    return np.floor(np.asarray(d, np.float64) / step + 0.5) * step


def depth_to_mm(z: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Planar depth in metres -> uint16 millimetres (rounded half up), 0 where invalid.

    Depths that would overflow uint16 (> 65.535 m) are invalid.
    """
    mm = np.floor(np.asarray(z, np.float64) * 1000.0 + 0.5)
    ok = valid & (mm >= 1) & (mm <= 65535)
    return np.where(ok, mm, 0).astype(np.uint16)


def simulate(depth: np.ndarray, *, focal_px: float, baseline_m: float, z_min: float,
             z_max: float, disparity_noise_px: float, subpixel: float,
             rng: np.random.Generator | None) -> tuple[np.ndarray, np.ndarray]:
    """Apply the configured effects to a rendered planar depth image.

    depth : (H, W) float32/64 metres, 0 or non-finite = no hit.
    disparity_noise_px : sigma of Gaussian disparity noise (0 disables it, and then no
        random numbers are drawn).
    subpixel : quantisation step in px (1/8 for Kinect v1; 0 disables quantisation).
    rng : per-frame generator; required when noise is on.
    Returns (depth_m float64, valid bool).
    """
    z = np.asarray(depth, np.float64)
    valid = np.isfinite(z) & (z > 0)
    valid &= (z >= z_min) & (z <= z_max)
    if disparity_noise_px <= 0 and subpixel <= 0:
        return np.where(valid, z, 0.0), valid
    fb = focal_px * baseline_m
    d = disparity_from_depth(z, focal_px, baseline_m, valid)
    if disparity_noise_px > 0:
        if rng is None:
            raise ValueError("disparity noise needs a per-frame np.random.Generator")
        d = d + rng.normal(0.0, disparity_noise_px, size=d.shape) * valid
    if subpixel > 0:
        d = quantise_disparity(d, subpixel)
    # noise or rounding can push a far pixel to d <= 0: invalid, never inverted
    valid &= d > 0
    zq = np.zeros_like(d)
    np.divide(fb, d, out=zq, where=valid)
    # re-gate: a noisy pixel may leave the range
    valid &= (zq >= z_min) & (zq <= z_max)
    return np.where(valid, zq, 0.0), valid
