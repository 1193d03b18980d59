"""Sensor effects (E1-E10 of shared/design/sensor-kinect-v1.md), one class each.

Every effect declares its parameters (with defaults and ranges) and what it needs
(``normals``, ``projector_depth``, random numbers), and acts on a :class:`SensorState`.
The state holds the image in the depth domain (planar z, metres) or the disparity domain
(d = f b / z, px, float64) and converts lazily, only on valid pixels, so invalid pixels
never produce inf or NaN. Effects that move pixels (lens distortion, lateral noise) move
labels and normals with them, so the ground truth stays aligned with the depth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vhgen.camera import Intrinsics
from vhgen.errors import ConfigError

HOLE_CAUSES = ("no_hit", "range", "distortion", "shadow", "dropout", "window", "noise",
               "matching")


@dataclass
class SensorState:
    """Per-frame working state. Arrays are (H, W)."""

    intr: Intrinsics
    baseline_m: float
    z: np.ndarray  # float64 metres (depth domain), 0 where invalid
    valid: np.ndarray  # bool
    labels: np.ndarray | None = None
    normals: np.ndarray | None = None  # (H, W, 3) camera frame, facing the camera
    projector_depth: np.ndarray | None = None  # planar depth seen from the projector
    d: np.ndarray | None = None  # float64 px (disparity domain) when domain == "d"
    domain: str = "z"
    holes: dict = field(default_factory=dict)  # cause -> bool mask of pixels it removed
    rays_unit: np.ndarray | None = None  # (H, W, 3) unit viewing rays (cached per sensor)
    ray_norm: np.ndarray | None = None  # (H, W) |ray| for z = 1
    pattern: np.ndarray | None = None  # the projector's binary dot pattern

    @property
    def fb(self) -> float:
        return self.intr.fx * self.baseline_m

    def to_disparity(self) -> np.ndarray:
        """Switch to the disparity domain (in place: the depth array becomes d)."""
        if self.domain == "z":
            from vhgen.sensor.kernels import invert_inplace

            invert_inplace(self.z, self.valid, self.fb)
            self.d, self.z = self.z, None
            self.domain = "d"
        return self.d

    def to_depth(self) -> np.ndarray:
        if self.domain == "d":
            from vhgen.sensor.kernels import invert_inplace

            invert_inplace(self.d, self.valid, self.fb)
            self.z, self.d = self.d, None
            self.domain = "z"
        return self.z

    def normals_cos(self) -> np.ndarray:
        """|cos| of the incidence angle per pixel (needs normals)."""
        from vhgen.sensor.kernels import incidence_cos

        return incidence_cos(np.ascontiguousarray(self.normals), self.rays_unit)

    def normal_draws(self, rng: np.random.Generator) -> np.ndarray:
        """One uint16 draw per pixel, to be mapped through NORMAL_TABLE (fast N(0, 1))."""
        return rng.integers(0, 65536, size=self.valid.size, dtype=np.uint16)

    def record(self, kernel, cause: str) -> None:
        """Run ``kernel(hole_mask)``, a fused pass that removes pixels itself, marking them
        in the cause's hole mask; it returns how many it removed."""
        hole = self.holes.get(cause)
        if hole is None:
            hole = np.zeros_like(self.valid)
        if kernel(hole):
            self.holes[cause] = hole

    def invalidate(self, mask: np.ndarray, cause: str) -> None:
        """Remove ``mask`` pixels (recording why) and zero them in the active domain."""
        from vhgen.sensor.kernels import remove_pixels

        arr = self.z if self.domain == "z" else self.d
        self.record(lambda hole: remove_pixels(np.ascontiguousarray(mask), self.valid, arr,
                                               hole), cause)


@dataclass(frozen=True)
class Param:
    default: object
    lo: float | None = None
    hi: float | None = None
    choices: tuple | None = None


class Effect:
    """Base class: subclasses set NAME, PARAMS, NEEDS and implement ``apply``."""

    NAME = ""
    PARAMS: dict[str, Param] = {}
    NEEDS: frozenset[str] = frozenset()
    RANDOM = False

    def __init__(self, **params):
        self.params = {}
        for k in params:
            if k not in self.PARAMS:
                raise ConfigError(None, f"{self.NAME}.{k}", f"unknown parameter (allowed: "
                                                            f"{', '.join(self.PARAMS) or 'none'})")
        for k, spec in self.PARAMS.items():
            v = params.get(k, spec.default)
            if spec.choices is not None:
                if v not in spec.choices:
                    raise ConfigError(None, f"{self.NAME}.{k}",
                                      f"{v!r} is not one of {', '.join(map(str, spec.choices))}")
            elif isinstance(spec.default, bool):
                if not isinstance(v, bool):
                    raise ConfigError(None, f"{self.NAME}.{k}", f"must be true/false, got {v!r}")
            else:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                    raise ConfigError(None, f"{self.NAME}.{k}", f"must be a number, got {v!r}")
                if (spec.lo is not None and v < spec.lo) or (spec.hi is not None and v > spec.hi):
                    raise ConfigError(None, f"{self.NAME}.{k}",
                                      f"{v!r} is outside [{spec.lo}, {spec.hi}]")
                v = float(v)
            self.params[k] = v
        self.check()

    def check(self) -> None:
        """Cross-parameter checks."""

    @property
    def needs(self) -> frozenset[str]:
        return self.NEEDS

    @property
    def random(self) -> bool:
        """Whether this configured effect draws random numbers."""
        return self.RANDOM

    def to_dict(self) -> dict:
        return {self.NAME: dict(self.params)}

    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        raise NotImplementedError


def _normal_table() -> np.ndarray:
    """65536 quantiles of N(0, 1), rescaled to unit variance (tails cut at 4.3 sigma)."""
    from scipy.special import ndtri

    t = ndtri((np.arange(65536) + 0.5) / 65536)
    return (t / t.std()).astype(np.float64)


NORMAL_TABLE = _normal_table()


def _incidence_cos(s: SensorState) -> np.ndarray:
    """cos of the angle between each pixel's viewing ray and the surface normal."""
    return s.normals_cos()


class RangeGate(Effect):
    """E2: valid iff z_min <= z <= z_max (and the pixel hit something)."""

    NAME = "range_gate"
    PARAMS = {"z_min_m": Param(0.8, 0.0, 60.0), "z_max_m": Param(4.0, 0.01, 65.0)}

    def check(self):
        if self.params["z_min_m"] >= self.params["z_max_m"]:
            raise ConfigError(None, f"{self.NAME}.z_min_m", "must be below z_max_m")

    def apply(self, s, rng):
        from vhgen.sensor.kernels import gate_inplace

        z = s.to_depth()
        s.record(lambda hole: gate_inplace(z, s.valid, self.params["z_min_m"],
                                           self.params["z_max_m"], hole), "range")


class LensDistortion(Effect):
    """E9: Brown-Conrady distortion of the IR camera (Burrus' Kinect calibration).

    The rendered image is ideal pinhole; each output (distorted) pixel takes the nearest
    ideal pixel its undistorted ray passes through (no interpolation, so no invented
    surfaces); rays leaving the image become holes.
    """

    NAME = "lens_distortion"
    PARAMS = {"k1": Param(-0.26386, -2, 2), "k2": Param(0.99967, -5, 5),
              "p1": Param(-7.63e-4, -0.1, 0.1), "p2": Param(5.035e-3, -0.1, 0.1),
              "k3": Param(-1.30536, -10, 10)}

    def __init__(self, **params):
        super().__init__(**params)
        self._map = None

    def _undistort_map(self, intr: Intrinsics):
        p = self.params
        v, u = np.mgrid[0:intr.height, 0:intr.width].astype(np.float64)
        xd, yd = (u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy
        x, y = xd.copy(), yd.copy()
        for _ in range(20):  # fixed-point inversion of the forward model
            r2 = x * x + y * y
            radial = 1 + p["k1"] * r2 + p["k2"] * r2 * r2 + p["k3"] * r2 ** 3
            dx = 2 * p["p1"] * x * y + p["p2"] * (r2 + 2 * x * x)
            dy = p["p1"] * (r2 + 2 * y * y) + 2 * p["p2"] * x * y
            x, y = (xd - dx) / radial, (yd - dy) / radial
        us = np.rint(x * intr.fx + intr.cx).astype(np.int64)
        vs = np.rint(y * intr.fy + intr.cy).astype(np.int64)
        inside = (us >= 0) & (us < intr.width) & (vs >= 0) & (vs < intr.height)
        return np.where(inside, vs, 0), np.where(inside, us, 0), inside

    def apply(self, s, rng):
        if self._map is None or self._map[0].shape != s.z.shape:
            self._map = self._undistort_map(s.intr)
        vs, us, inside = self._map
        z = s.to_depth()
        s.z = np.where(inside, z[vs, us], 0.0)
        s.valid = inside & s.valid[vs, us]
        if s.labels is not None:
            s.labels = np.where(inside, s.labels[vs, us], 0).astype(s.labels.dtype)
        if s.normals is not None:
            s.normals = s.normals[vs, us]
        s.holes = {k: m[vs, us] & inside for k, m in s.holes.items()}
        s.holes["distortion"] = s.holes.get("distortion", np.zeros_like(inside)) | ~inside


class LateralNoise(Effect):
    """E7: each pixel shows the surface at (u, v) + N(0, sigma^2) px (ICL-NUIM), taken from
    the nearest pixel (ICL interpolates bilinearly and so invents depths across edges).

    ``nguyen``: sigma grows at grazing angles, 0.8 + 0.035 theta / (pi/2 - theta) px
    (theta clamped at 85 deg), times ``sigma_px`` / 0.8.
    """

    NAME = "lateral_noise"
    PARAMS = {"sigma_px": Param(0.5, 0.0, 10.0), "model": Param("icl", choices=("icl", "nguyen"))}
    RANDOM = True

    @property
    def needs(self):
        return frozenset({"normals"}) if self.params["model"] == "nguyen" else frozenset()

    def apply(self, s, rng):
        from vhgen.sensor.kernels import lateral_indices

        h, w = s.valid.shape
        sigma = np.array([self.params["sigma_px"]])
        if self.params["model"] == "nguyen":
            th = np.minimum(np.arccos(np.clip(_incidence_cos(s), 0, 1)), np.deg2rad(85))
            sigma = self.params["sigma_px"] / 0.8 * (0.8 + 0.035 * th / (np.pi / 2 - th))
        draws = rng.integers(0, 2**32, size=h * w, dtype=np.uint32)
        idx = lateral_indices(draws, NORMAL_TABLE, np.ascontiguousarray(sigma, dtype=np.float64),
                              h, w)
        from vhgen.sensor.kernels import gather_state

        z = s.to_depth()
        nrm = s.normals if s.normals is not None else np.zeros((0, 3), np.float32)
        lab = s.labels if s.labels is not None else np.zeros(0, np.uint8)
        s.z, s.valid, n2, l2 = gather_state(idx, z, s.valid, np.ascontiguousarray(nrm),
                                            np.ascontiguousarray(lab))
        if s.normals is not None:
            s.normals = n2.reshape(h, w, 3)
        if s.labels is not None:
            s.labels = l2.reshape(h, w)
        s.holes = {k: m.reshape(-1)[idx].reshape(h, w) for k, m in s.holes.items()}


class AxialNoise(Effect):
    """E6: depth noise along the ray, selectable models.

    * ``disparity``: d += N(0, sigma_px) before quantisation (K&E: ~0.062 px; Nguyen:
      0.07-0.08 px at 1-4 m);
    * ``khoshelham``: sigma_z = 1.425e-3 z^2 m (Khoshelham & Elberink 2012);
    * ``nguyen``: sigma_z = 0.0012 + 0.0019 (z - 0.4)^2 m, plus 0.0001 / sqrt(z) *
      theta^2 / (pi/2 - theta)^2 m beyond 60 deg incidence (Nguyen et al. 2012; theta
      clamped at 85 deg so grazing pixels never divide by zero) when normals are on;
    * ``barron_malik``: the ICL-NUIM model z_cm' = 35130 / round(35130 / round(z_cm) +
      N(0, 1) / 6) with the +0.5 of the published code removed: it biased every depth
      nearer by about z^2 / (2 * 35130) cm.
    Pixels whose noisy disparity is <= 0 become holes (cause ``noise``).
    """

    NAME = "axial_noise"
    PARAMS = {"model": Param("disparity", choices=("disparity", "khoshelham", "nguyen",
                                                   "barron_malik")),
              "sigma_px": Param(0.07, 0.0, 5.0), "angle_term": Param(False)}
    RANDOM = True

    @property
    def needs(self):
        return frozenset({"normals"}) if self.params["angle_term"] else frozenset()

    def apply(self, s, rng):
        from vhgen.sensor.kernels import add_noise_sigma_inplace

        model = self.params["model"]
        if model == "disparity":
            from vhgen.sensor.kernels import add_noise_drop_inplace

            d = s.to_disparity()
            draws = s.normal_draws(rng)
            s.record(lambda hole: add_noise_drop_inplace(d, s.valid, draws, NORMAL_TABLE,
                                                         self.params["sigma_px"], hole), "noise")
            return
        z = s.to_depth()
        if model == "barron_malik":
            idx = np.flatnonzero(s.valid)
            flat = z.reshape(-1)
            z_cm = np.floor(flat[idx] * 100 + 0.5)
            disp = 35130.0 / np.maximum(z_cm, 1.0) + NORMAL_TABLE[s.normal_draws(rng)[idx]] / 6
            dq = np.floor(disp + 0.5)
            ok = dq > 0
            flat[idx] = np.where(ok, 35130.0 / np.where(ok, dq, 1.0) / 100.0, 0.0)
            s.invalidate(z <= 0, "noise")
            return
        if model == "khoshelham":
            sigma = 1.425e-3 * z * z
        else:
            sigma = 0.0012 + 0.0019 * (z - 0.4) ** 2
            if self.params["angle_term"]:
                th = np.minimum(np.arccos(np.clip(_incidence_cos(s), 0, 1)), np.deg2rad(85))
                extra = np.where(th > np.deg2rad(60), 1e-4 / np.sqrt(np.maximum(z, 1e-6)) *
                                 th ** 2 / (np.pi / 2 - th) ** 2, 0.0)
                sigma = sigma + extra
        add_noise_sigma_inplace(z, s.valid, s.normal_draws(rng), NORMAL_TABLE,
                                np.ascontiguousarray(sigma))
        s.invalidate(z <= 0, "noise")


class ProjectorShadow(Effect):
    """E4: pixels the projector cannot light.

    ``screen_space``: the reverse running-minimum rule on disparity (cheap; misses occluders
    outside the image). ``exact``: each pixel is looked up in a depth image rendered from
    the projector (at +baseline along x); it is shadowed when the projector sees a surface
    nearer than the pixel's own by more than ``tolerance`` (relative).
    """

    NAME = "projector_shadow"
    PARAMS = {"method": Param("screen_space", choices=("screen_space", "exact")),
              "tolerance": Param(0.01, 0.0, 0.5)}

    @property
    def needs(self):
        return frozenset({"projector_depth"}) if self.params["method"] == "exact" else \
            frozenset()

    def apply(self, s, rng):
        from vhgen.sensor.kernels import screen_space_shadow

        if self.params["method"] == "screen_space":
            d = s.to_disparity()
            s.invalidate(screen_space_shadow(d, s.valid, s.baseline_m > 0), "shadow")
            return
        s.invalidate(exact_shadow(s, self.params["tolerance"]), "shadow")


def exact_shadow(s: SensorState, tolerance: float) -> np.ndarray:
    """Shadow mask from the projector-view depth (rectified rig, projector at +b on x)."""
    z = s.to_depth() if s.domain == "z" else np.where(s.valid, s.fb / np.where(
        s.valid, s.d, 1.0), 0.0)
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


class CorrelationWindow(Effect):
    """E5: the dot-gated 9x9 correlation window (edge fattening, thin-structure loss,
    fill between dots), compiled with numba. Thresholds: BlenSor's 1/1.5 (``frac``), the
    ICL-NUIM value is 1/1.2. Dots come from the sensor's projector pattern."""

    NAME = "correlation_window"
    PARAMS = {"window": Param(9, 3, 31), "frac": Param(1 / 1.5, 0.0, 1.0),
              "inlier_px": Param(0.1, 0.0, 10.0), "splat_radius_px": Param(3.1, 0.0, 10.0)}

    def check(self):
        if int(self.params["window"]) % 2 != 1:
            raise ConfigError(None, f"{self.NAME}.window", "must be odd")

    def apply(self, s, rng):
        from vhgen.sensor.kernels import correlation_window, dots_from_pattern
        from vhgen.sensor.model import PATTERN_PAD

        d = s.to_disparity()
        if s.pattern is None:
            raise ValueError("correlation_window needs the projector dot pattern")
        dots = dots_from_pattern(d, s.valid, s.pattern, PATTERN_PAD)
        out, ok = correlation_window(d, s.valid, dots,
                                     int(self.params["window"]) // 2, self.params["frac"],
                                     self.params["inlier_px"], self.params["splat_radius_px"])
        # pixels that had a valid surface but no accepted dot reached them
        # Splats fatten edges onto pixels the surface did not cover: those pixels now carry
        # a measurement while their label stays what was rendered there (the truth).
        lost = s.valid & ~ok
        s.d = np.where(ok, out, 0.0)
        s.holes["window"] = s.holes.get("window", np.zeros_like(ok)) | lost
        s.valid = ok


class Dropout(Effect):
    """E8: no return at grazing incidence (angle to the ray above ``max_angle_deg``) and,
    BlenSor's rule, from dark or far surfaces: invalid if albedo < 0.01 + 0.16 r (r in m)."""

    NAME = "dropout"
    PARAMS = {"max_angle_deg": Param(80.0, 0.0, 90.0), "albedo": Param(1.0, 0.0, 1.0)}
    NEEDS = frozenset({"normals"})

    def apply(self, s, rng):
        from vhgen.sensor.kernels import dropout_mask

        z = s.to_depth()
        # albedo < 0.01 + 0.16 r  <=>  r > (albedo - 0.01) / 0.16, r = z |ray|
        r_max = (self.params["albedo"] - 0.01) / 0.16
        cos_min = np.cos(np.deg2rad(self.params["max_angle_deg"]))
        s.invalidate(dropout_mask(z, s.valid, np.ascontiguousarray(s.normals), s.rays_unit,
                                  s.ray_norm, cos_min, r_max), "dropout")


class DisparityQuantisation(Effect):
    """E3: disparity in steps of ``step_px`` (1/8 px), rounded half up:
    d_q = floor(d / step + 0.5) * step. A pixel quantised to d <= 0 becomes a hole."""

    NAME = "disparity_quantisation"
    PARAMS = {"step_px": Param(0.125, 1e-4, 1.0)}

    def apply(self, s, rng):
        from vhgen.sensor.kernels import quantise_inplace

        d = s.to_disparity()
        lost = quantise_inplace(d, s.valid, self.params["step_px"])
        if lost.any():
            s.holes["noise"] = s.holes.get("noise", np.zeros_like(lost)) | lost


class Encode(Effect):
    """E10: output encodings. Depth is always written as uint16 mm (0 = no measurement,
    > 65.535 m invalid); with ``raw11`` the 11-bit raw value k_d = round(d_off - 8 d) is kept
    as well (2047 = invalid, values outside 0..2046 invalid)."""

    NAME = "encode"
    PARAMS = {"raw11": Param(False), "d_off": Param(1090.0, 0.0, 4096.0)}

    def apply(self, s, rng):
        pass  # the model reads these parameters when it writes the outputs


EFFECTS: dict[str, type[Effect]] = {cls.NAME: cls for cls in (
    RangeGate, LensDistortion, LateralNoise, AxialNoise, ProjectorShadow, CorrelationWindow,
    Dropout, DisparityQuantisation, Encode)}
