"""Runtime stages of the shipped effects (specs in :mod:`vhgen.sensor.effects`).

Each stage acts on a :class:`vhgen.sensor.state.SensorState` through the numba kernels;
caches that depend only on the sensor (undistortion maps) are built in ``__init__``.
"""

from __future__ import annotations

import numpy as np

from vhgen.camera import Intrinsics
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
from vhgen.sensor.pattern import PATTERN_PAD
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.sensor_kernels import (
    add_noise_drop_inplace,
    add_noise_sigma_inplace,
    correlation_window,
    dots_from_pattern,
    dropout_inplace,
    gate_inplace,
    gather_if_present,
    gather_state,
    lateral_indices,
    quantise_inplace,
    screen_space_shadow,
)
from vhgen.sensor.stage import Stage
from vhgen.sensor.state import NORMAL_TABLE, SensorState


def _need_rng(rng: np.random.Generator | None) -> np.random.Generator:
    if rng is None:
        raise ValueError("this effect draws noise: pass the frame's Generator")
    return rng


def _grazing_angle(s: SensorState) -> np.ndarray:
    """Incidence angle (rad), clamped at 85 deg so grazing pixels never divide by zero."""
    return np.minimum(np.arccos(np.clip(s.incidence_cos(), 0, 1)), np.deg2rad(85))


class RangeGateStage(Stage[RangeGate], spec=RangeGate):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        z = s.to_depth()
        s.record(lambda hole: gate_inplace(z, s.valid, p.z_min_m, p.z_max_m, hole), "range")


def undistort_map(p: LensDistortion,
                  intr: Intrinsics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each distorted pixel, the nearest ideal pixel (rows, cols; int64) and whether
    its undistorted ray stays inside the image (bool), all (H, W)."""
    v, u = np.mgrid[0:intr.height, 0:intr.width].astype(np.float64)
    xd, yd = (u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy
    x, y = xd.copy(), yd.copy()
    for _ in range(20):  # fixed-point inversion of the forward model
        r2 = x * x + y * y
        radial = 1 + p.k1 * r2 + p.k2 * r2 * r2 + p.k3 * r2 ** 3
        dx = 2 * p.p1 * x * y + p.p2 * (r2 + 2 * x * x)
        dy = p.p1 * (r2 + 2 * y * y) + 2 * p.p2 * x * y
        x, y = (xd - dx) / radial, (yd - dy) / radial
    # a wild model can diverge: such rays leave the image like any other
    with np.errstate(invalid="ignore", over="ignore"):
        fin = np.isfinite(x) & np.isfinite(y)
        uf = np.where(fin, np.clip(x * intr.fx + intr.cx, -1, intr.width), -1)
        vf = np.where(fin, np.clip(y * intr.fy + intr.cy, -1, intr.height), -1)
    us = np.rint(uf).astype(np.int64)
    vs = np.rint(vf).astype(np.int64)
    inside = (us >= 0) & (us < intr.width) & (vs >= 0) & (vs < intr.height)
    return np.where(inside, vs, 0), np.where(inside, us, 0), inside


class LensDistortionStage(Stage[LensDistortion], spec=LensDistortion):
    def __init__(self, spec: LensDistortion, sensor: SensorConfig):
        super().__init__(spec, sensor)
        self.vs, self.us, self.inside = undistort_map(spec, sensor.intrinsics)

    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        vs, us, inside = self.vs, self.us, self.inside
        z = s.to_depth()
        s.z = np.where(inside, z[vs, us], 0.0)
        s.valid = inside & s.valid[vs, us]
        if s.labels is not None:
            s.labels = np.where(inside, s.labels[vs, us], 0).astype(s.labels.dtype)
        if s.incidence is not None:
            s.incidence = s.incidence[vs, us]
        s.holes = {k: m[vs, us] & inside for k, m in s.holes.items()}
        s.holes["distortion"] = s.hole("distortion") | ~inside


class LateralNoiseStage(Stage[LateralNoise], spec=LateralNoise):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        rng = _need_rng(rng)
        h, w = s.valid.shape
        sigma = np.array([p.sigma_px])
        if p.model == "nguyen":
            th = _grazing_angle(s)
            sigma = p.sigma_px / 0.8 * (0.8 + 0.035 * th / (np.pi / 2 - th))
        draws = rng.integers(0, 2**32, size=h * w, dtype=np.uint32)
        idx = lateral_indices(draws, NORMAL_TABLE, np.ascontiguousarray(sigma, dtype=np.float64),
                              h, w)
        z = s.to_depth()
        inc = s.incidence if s.incidence is not None else np.zeros(0, np.float32)
        lab = s.labels if s.labels is not None else np.zeros(0, np.uint8)
        s.z, s.valid, c2, l2 = gather_state(idx, z, s.valid, np.ascontiguousarray(inc),
                                            np.ascontiguousarray(lab))
        if s.incidence is not None:
            s.incidence = c2.reshape(h, w)
        if s.labels is not None:
            s.labels = l2.reshape(h, w)
        s.holes = {k: m.reshape(-1)[idx].reshape(h, w) for k, m in s.holes.items()}


class AxialNoiseStage(Stage[AxialNoise], spec=AxialNoise):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        rng = _need_rng(rng)
        if p.model == "disparity":
            d = s.to_disparity()
            draws = s.normal_draws(rng)
            s.record(lambda hole: add_noise_drop_inplace(d, s.valid, draws, NORMAL_TABLE,
                                                         p.sigma_px, hole), "noise")
            return
        z = s.to_depth()
        if p.model == "barron_malik":
            idx = np.flatnonzero(s.valid)
            flat = z.reshape(-1)
            z_cm = np.floor(flat[idx] * 100 + 0.5)
            disp = 35130.0 / np.maximum(z_cm, 1.0) + NORMAL_TABLE[s.normal_draws(rng)[idx]] / 6
            dq = np.floor(disp + 0.5)
            ok = dq > 0
            flat[idx] = np.where(ok, 35130.0 / np.where(ok, dq, 1.0) / 100.0, 0.0)
            s.invalidate(z <= 0, "noise")
            return
        if p.model == "khoshelham":
            sigma = 1.425e-3 * z * z
        else:
            sigma = 0.0012 + 0.0019 * (z - 0.4) ** 2
            if p.angle_term:
                th = _grazing_angle(s)
                extra = np.where(th > np.deg2rad(60), 1e-4 / np.sqrt(np.maximum(z, 1e-6)) *
                                 th ** 2 / (np.pi / 2 - th) ** 2, 0.0)
                sigma = sigma + extra
        add_noise_sigma_inplace(z, s.valid, s.normal_draws(rng), NORMAL_TABLE,
                                np.ascontiguousarray(sigma))
        s.invalidate(z <= 0, "noise")


def exact_shadow(s: SensorState, tolerance: float) -> np.ndarray:
    """Shadow mask from the projector-view depth (rectified rig, projector at +b on x)."""
    if s.projector_depth is None:
        raise ValueError("this effect needs a projector-view depth image")
    z = s.to_depth() if s.domain == "z" else np.where(s.valid, s.fb / np.where(
        s.valid, s.active(), 1.0), 0.0)
    h, w = z.shape
    v, u = np.mgrid[0:h, 0:w]
    d = np.zeros_like(z)
    np.divide(s.fb, z, out=d, where=s.valid)
    up = u - d
    lo = np.clip(np.floor(up).astype(np.int64), 0, w - 1)
    hi = np.clip(lo + 1, 0, w - 1)
    pz = s.projector_depth
    near = z * (1.0 - tolerance)
    occl_lo = (pz[v, lo] > 0) & (pz[v, lo] < near)
    occl_hi = (pz[v, hi] > 0) & (pz[v, hi] < near)
    outside = (up < 0) | (up > w - 1)
    return s.valid & ((occl_lo & occl_hi) | outside)


class ProjectorShadowStage(Stage[ProjectorShadow], spec=ProjectorShadow):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        if p.method == "screen_space":
            d = s.to_disparity()
            s.invalidate(screen_space_shadow(d, s.valid, s.baseline_m > 0), "shadow")
            return
        s.invalidate(exact_shadow(s, p.tolerance), "shadow")


class CorrelationWindowStage(Stage[CorrelationWindow], spec=CorrelationWindow):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        d = s.to_disparity()
        if s.pattern is None:
            raise ValueError("correlation_window needs the projector dot pattern")
        dots = dots_from_pattern(d, s.valid, s.pattern, PATTERN_PAD)
        moves = s.labels is not None or s.incidence is not None
        out, ok, src = correlation_window(d, s.valid, dots, p.window // 2, p.frac,
                                          p.inlier_px, p.splat_radius_px, moves)
        # A pixel reports the disparity of the dot whose splat won it, so it takes that
        # dot's ids and incidence too: splats fatten a person's edge onto the wall behind,
        # and those pixels now measure (and are labelled) the person, as lateral noise
        # moves labels with the depth.
        n = src.size
        if s.labels is not None:
            s.labels = gather_if_present(src, np.ascontiguousarray(s.labels), n
                                          ).reshape(s.labels.shape)
        if s.incidence is not None:
            s.incidence = gather_if_present(src, np.ascontiguousarray(s.incidence), n
                                             ).reshape(s.incidence.shape)
        lost = s.valid & ~ok
        s.d = out  # already 0 where not ok
        s.holes["window"] = s.hole("window") | lost
        s.valid = ok


class DropoutStage(Stage[Dropout], spec=Dropout):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        if s.incidence is None:
            raise ValueError("dropout needs the incidence")
        z = s.to_depth()
        # albedo < 0.01 + 0.16 r  <=>  r > (albedo - 0.01) / 0.16, r = z |ray|
        r_max = (p.albedo - 0.01) / 0.16 if p.range_rule else np.inf
        cos_min = np.cos(np.deg2rad(p.max_angle_deg))
        inc = np.ascontiguousarray(s.incidence)
        s.record(lambda hole: dropout_inplace(z, s.valid, inc, s.ray_norm,
                                              cos_min, r_max, hole), "dropout")


class DisparityQuantisationStage(Stage[DisparityQuantisation], spec=DisparityQuantisation):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        d = s.to_disparity()
        lost = quantise_inplace(d, s.valid, p.step_px)
        if lost.any():
            s.holes["noise"] = s.hole("noise") | lost


class RangeDropoutStage(Stage[RangeDropout], spec=RangeDropout):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        rng = _need_rng(rng)
        z = s.to_depth()
        h, w = z.shape
        b = p.blob_px
        cells = rng.random(((h + b - 1) // b, (w + b - 1) // b))
        u = np.repeat(np.repeat(cells, b, 0), b, 1)[:h, :w]
        frac = np.clip((z - p.z_start_m) / (p.z_end_m - p.z_start_m), 0.0, 1.0)
        s.invalidate(s.valid & (u < frac ** p.power), "range")


class RegistrationStage(Stage[Registration], spec=Registration):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        p = self.spec
        h, w = s.valid.shape
        if p.ir_offset_m != 0.0:
            d = s.to_disparity()
            # disparity between this camera and the IR camera: f |ir_offset| / z
            d_ir = np.ascontiguousarray(d * (abs(p.ir_offset_m) / s.baseline_m))
            s.invalidate(screen_space_shadow(d_ir, s.valid, p.ir_offset_m > 0), "registration")
        band = np.zeros((h, w), bool)
        band[:, :min(p.left_px, w)] = True
        band[:, w - min(p.right_px, w):] = True
        band[:min(p.top_px, h)] = True
        band[h - min(p.bottom_px, h):] = True
        if band.any():
            s.invalidate(band, "registration")


class SpeckleFilterStage(Stage[SpeckleFilter], spec=SpeckleFilter):
    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        from scipy import ndimage

        lab, n = ndimage.label(s.valid, structure=ndimage.generate_binary_structure(2, 1))
        if not n:
            return
        area = np.bincount(lab.reshape(-1), minlength=n + 1)
        small = area <= self.spec.max_area_px
        small[0] = False
        s.invalidate(small[lab], "speckle")
