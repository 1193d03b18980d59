"""The shipped sensor effects (E1-E9 of shared/design/sensor-kinect-v1.md) as typed specs.

Each class is a frozen dataclass: its fields are the parameters (type, unit, range in the
field), its ``READS`` / ``WRITES`` the state channels it touches. What each effect does to
a frame lives in :mod:`vhgen.sensor.stages` (and :mod:`vhgen.sensor.structured_light`);
this module is pure description and imports neither numba nor scipy. Effects that move
pixels (lens distortion, lateral noise, the correlation window's splats) move labels and
the incidence with them, so the ground truth stays aligned with the depth. E10, the output
encoding, is :class:`vhgen.sensor.spec.Encoding`.
"""

from __future__ import annotations

from dataclasses import dataclass

from vhgen.sensor.spec import EffectSpec, SpecError, choice, flag, number

MEASURE = frozenset({"depth_m", "disparity", "valid", "holes"})


@dataclass(frozen=True)
class RangeGate(EffectSpec, name="range_gate"):
    """E2: valid iff z_min <= z <= z_max (and the pixel hit something)."""

    z_min_m: float = number(0.8, 0.0, 60.0, unit="m")
    z_max_m: float = number(4.0, 0.01, 65.0, unit="m")

    READS = frozenset({"depth_m", "valid"})
    WRITES = frozenset({"valid", "holes"})
    GL = True

    def check(self) -> None:
        if self.z_min_m >= self.z_max_m:
            raise SpecError("z_min_m", f"must be below z_max_m ({self.z_max_m})")


@dataclass(frozen=True)
class LensDistortion(EffectSpec, name="lens_distortion"):
    """E9: Brown-Conrady distortion of the IR camera (Burrus' Kinect calibration).

    The rendered image is ideal pinhole; each output (distorted) pixel takes the nearest
    ideal pixel its undistorted ray passes through (no interpolation, so no invented
    surfaces); rays leaving the image become holes. Labels and the incidence move with the
    pixels; the projector-view depth does not (it stays on the pinhole grid), so effects
    reading it must come first.
    """

    k1: float = number(-0.26386, -2, 2)
    k2: float = number(0.99967, -5, 5)
    p1: float = number(-7.63e-4, -0.1, 0.1)
    p2: float = number(5.035e-3, -0.1, 0.1)
    k3: float = number(-1.30536, -10, 10)

    READS = MEASURE
    WRITES = MEASURE | {"labels", "incidence", "pixel_grid"}  # labels, incidence: when given
    GL = True


@dataclass(frozen=True)
class LateralNoise(EffectSpec, name="lateral_noise"):
    """E7: each pixel shows the surface at (u, v) + N(0, sigma^2) px (ICL-NUIM), taken from
    the nearest pixel (ICL interpolates bilinearly and so invents depths across edges).

    ``nguyen``: sigma grows at grazing angles, 0.8 + 0.035 theta / (pi/2 - theta) px
    (theta clamped at 85 deg), times ``sigma_px`` / 0.8.
    """

    sigma_px: float = number(0.5, 0.0, 10.0, unit="px")
    model: str = choice("icl", "icl", "nguyen")

    RANDOM = True
    WRITES = MEASURE | {"labels", "incidence"}  # moved with the pixels when given
    GL = True

    @property
    def reads(self) -> frozenset[str]:
        return MEASURE | {"incidence"} if self.model == "nguyen" else MEASURE


@dataclass(frozen=True)
class AxialNoise(EffectSpec, name="axial_noise"):
    """E6: depth noise along the ray, selectable models.

    * ``disparity``: d += N(0, sigma_px) before quantisation (K&E: ~0.062 px; Nguyen:
      0.07-0.08 px at 1-4 m);
    * ``khoshelham``: sigma_z = 1.425e-3 z^2 m (Khoshelham & Elberink 2012);
    * ``nguyen``: sigma_z = 0.0012 + 0.0019 (z - 0.4)^2 m, plus 0.0001 / sqrt(z) *
      theta^2 / (pi/2 - theta)^2 m beyond 60 deg incidence (Nguyen et al. 2012; theta
      clamped at 85 deg so grazing pixels never divide by zero) when ``angle_term``;
    * ``barron_malik``: the ICL-NUIM model z_cm' = 35130 / round(35130 / round(z_cm) +
      N(0, 1) / 6) with the +0.5 of the published code removed: it biased every depth
      nearer by about z^2 / (2 * 35130) cm.
    Pixels whose noisy disparity is <= 0 become holes (cause ``noise``).
    """

    model: str = choice("disparity", "disparity", "khoshelham", "nguyen", "barron_malik")
    sigma_px: float = number(0.07, 0.0, 5.0, unit="px")
    angle_term: bool = flag(False)

    RANDOM = True
    WRITES = MEASURE
    GL = True

    @property
    def reads(self) -> frozenset[str]:
        return MEASURE | {"incidence"} if self.angle_term else MEASURE


@dataclass(frozen=True)
class ProjectorShadow(EffectSpec, name="projector_shadow"):
    """E4: pixels the projector cannot light.

    ``screen_space``: the reverse running-minimum rule on disparity (cheap; misses occluders
    outside the image). ``exact``: each pixel is looked up in a depth image rendered from
    the projector (at +baseline along x); it is shadowed when the projector sees a surface
    nearer than the pixel's own by more than ``tolerance`` (relative).
    """

    method: str = choice("screen_space", "screen_space", "exact")
    tolerance: float = number(0.01, 0.0, 0.5, unit="relative")

    WRITES = MEASURE
    GL = True

    @property
    def reads(self) -> frozenset[str]:
        return MEASURE | {"projector_depth"} if self.method == "exact" else MEASURE


@dataclass(frozen=True)
class CorrelationWindow(EffectSpec, name="correlation_window"):
    """E5: the dot-gated correlation window (edge fattening, thin-structure loss, fill
    between dots), compiled with numba. Thresholds: BlenSor's 1/1.5 (``frac``), the
    ICL-NUIM value is 1/1.2. Dots come from the sensor's projector pattern. A pixel a dot's
    splat reaches measures that dot's surface and takes its labels and incidence: a
    person's fattened edge over the wall is labelled the person, as its depth says."""

    window: int = number(9, 3, 31, unit="px", integer=True, odd=True)
    frac: float = number(1 / 1.5, 0.0, 1.0)
    inlier_px: float = number(0.1, 0.0, 10.0, unit="px")
    splat_radius_px: float = number(3.1, 0.0, 10.0, unit="px")

    READS = MEASURE | {"pattern"}
    WRITES = MEASURE | {"labels", "incidence"}  # moved with the splats when given
    GL = True


@dataclass(frozen=True)
class Dropout(EffectSpec, name="dropout"):
    """E8: no return at grazing incidence (angle to the ray above ``max_angle_deg``) and,
    BlenSor's rule, from dark or far surfaces: invalid if albedo < 0.01 + 0.16 r (r in m).
    ``range_rule: false`` drops BlenSor's rule (with albedo 1 it is a hard cut at a range
    of 6.19 m, which OpenNI depth runs past): ``range_dropout`` models the loss at range."""

    max_angle_deg: float = number(80.0, 0.0, 90.0, unit="deg")
    albedo: float = number(1.0, 0.0, 1.0)
    range_rule: bool = flag(True)

    READS = MEASURE | {"incidence"}
    WRITES = MEASURE
    GL = True


@dataclass(frozen=True)
class DisparityQuantisation(EffectSpec, name="disparity_quantisation"):
    """E3: disparity in steps of ``step_px`` (1/8 px), rounded half up:
    d_q = floor(d / step + 0.5) * step. A pixel quantised to d <= 0 becomes a hole."""

    step_px: float = number(0.125, 1e-4, 1.0, unit="px")

    READS = MEASURE
    WRITES = MEASURE
    GL = True


@dataclass(frozen=True)
class StructuredLight(EffectSpec, name="structured_light"):
    """The structured-light reference path (see :mod:`vhgen.sensor.structured_light`):
    the dot pattern cast on the scene, an IR image, ZNCC block matching over
    ``search_px`` integer disparities from ``d_min_px``, 1/8 px refinement."""

    window: int = number(9, 3, 31, unit="px", integer=True, odd=True)
    search_px: int = number(64, 8, 256, unit="px", integer=True)
    d_min_px: int = number(7, 0, 200, unit="px", integer=True)
    min_zncc: float = number(0.5, -1.0, 1.0)
    albedo: float = number(1.0, 0.0, 1.0)
    ir_noise: bool = flag(True)

    READS = MEASURE | {"projector_depth", "incidence", "pattern"}
    WRITES = MEASURE

    @property
    def random(self) -> bool:
        return self.ir_noise


@dataclass(frozen=True)
class RangeDropout(EffectSpec, name="range_dropout"):
    """Returns fading with range instead of a hard gate: a pixel at planar depth z is lost
    with probability p(z) = clip((z - z_start) / (z_end - z_start), 0, 1) ** ``power``,
    decided per ``blob_px`` x ``blob_px`` cell of the image (one uniform draw per cell,
    compared with each pixel's own p), so far surfaces break up into blobs, as real ones
    do, rather than salt and pepper. Holes are counted under ``range``."""

    z_start_m: float = number(4.0, 0.0, 60.0, unit="m")
    z_end_m: float = number(10.0, 0.01, 65.0, unit="m")
    power: float = number(2.0, 0.1, 10.0)
    blob_px: int = number(4, 1, 64, unit="px", integer=True)

    RANDOM = True
    READS = MEASURE
    WRITES = MEASURE
    GL = True

    def check(self) -> None:
        if self.z_start_m >= self.z_end_m:
            raise SpecError("z_start_m", f"must be below z_end_m ({self.z_end_m})")


@dataclass(frozen=True)
class Registration(EffectSpec, name="registration"):
    """Depth registered to another camera (OpenNI's depth-to-RGB registration), as seen in
    that camera's image: the sensor's camera is the RGB camera, the IR camera that measured
    the depth sits ``ir_offset_m`` from it along x (negative: on the side away from the
    projector, as on the Kinect). Pixels the IR camera could not see (hidden behind a
    nearer surface from its viewpoint: a band of f |ir_offset| (1/z_near - 1/z_far) px on
    the side of near objects away from the projector's shadow) and the band along the
    image border that lies outside the IR camera's view (``left_px`` ... ``bottom_px``)
    have no measurement. Holes are counted under ``registration``."""

    ir_offset_m: float = number(-0.025, -0.5, 0.5, unit="m")
    left_px: int = number(0, 0, 1000, unit="px", integer=True)
    right_px: int = number(0, 0, 1000, unit="px", integer=True)
    top_px: int = number(0, 0, 1000, unit="px", integer=True)
    bottom_px: int = number(0, 0, 1000, unit="px", integer=True)

    READS = MEASURE
    WRITES = MEASURE
    GL = True


@dataclass(frozen=True)
class SpeckleFilter(EffectSpec, name="speckle_filter"):
    """Isolated measurements removed: every 4-connected component of valid pixels of at
    most ``max_area_px`` pixels becomes a hole (cause ``speckle``). Real OpenNI frames hold
    no such islands (the bench statistic ``speckles``), while per-pixel effects leave
    single valid pixels among holes."""

    max_area_px: int = number(200, 1, 100000, unit="px", integer=True)

    READS = MEASURE
    WRITES = MEASURE
    GL = True
