"""A sensor: intrinsics, baseline, the projector's dot pattern and an ordered effect list.

Configs live in ``configs/sensors/``::

    name: kinect_v1_fast
    width: 640
    height: 480
    fx: 571.26
    ...
    baseline_m: 0.075
    effects:                     # applied in this order; nothing else is computed
      - range_gate: {z_min_m: 0.8, z_max_m: 4.0}
      - axial_noise: {model: disparity, sigma_px: 0.07}
      - disparity_quantisation: {step_px: 0.125}
      - encode: {}

Unknown effects or parameters are config errors naming the field. The renderer is asked
only for what the effects need (:attr:`SensorConfig.needs`): normals, a projector-view
depth image, random numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.camera import Intrinsics
from vhgen.errors import ConfigError
from vhgen.sensor.effects import EFFECTS, HOLE_CAUSES, Effect, SensorState
from vhgen.sensor.structured_light import StructuredLight
from vhgen.yamlio import check_keys, find_config, load_yaml

# the reference path is an effect like the others (registered here: it imports effects)
EFFECTS[StructuredLight.NAME] = StructuredLight

PATTERN_PAD = 160  # projector columns beyond each image side (disparities up to 160 px)


def dot_pattern(seed: int, height: int, width: int, density: float) -> np.ndarray:
    """The projector's binary dot pattern, (height, width + 2 PATTERN_PAD) bool.

    Like the Kinect's, a 3 x 3 tiling of one pseudo-random tile with a bright dot at each
    tile centre; fixed per sensor (seeded), so every frame sees the same pattern.
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xD075]))
    tw = -(-(width + 2 * PATTERN_PAD) // 3)
    th = -(-height // 3)
    tile = rng.random((th, tw)) < density
    tile[th // 2, tw // 2] = True
    return np.tile(tile, (3, 3))[:height, : width + 2 * PATTERN_PAD]


@dataclass(frozen=True, eq=False)
class SensorConfig:
    name: str
    intrinsics: Intrinsics
    baseline_m: float
    effects: tuple[Effect, ...]
    pattern_seed: int = 0
    dot_density: float = 0.2
    source: str | None = None

    @classmethod
    def load(cls, name_or_path: str | Path) -> SensorConfig:
        path = find_config("sensors", name_or_path)
        d = load_yaml(path)
        keys = {"name", "width", "height", "fx", "fy", "cx", "cy", "baseline_m", "effects",
                "pattern_seed", "dot_density", "description"}
        check_keys(d, keys, {"name", "width", "height", "fx", "fy", "cx", "cy", "baseline_m",
                             "effects"}, path, "")
        for k in ("width", "height"):
            if not isinstance(d[k], int) or not 8 <= d[k] <= 8192:
                raise ConfigError(path, k, f"must be an integer in [8, 8192], got {d[k]!r}")
        for k in ("fx", "fy", "cx", "cy", "baseline_m"):
            if isinstance(d[k], bool) or not isinstance(d[k], (int, float)):
                raise ConfigError(path, k, f"must be a number, got {d[k]!r}")
        if d["fx"] <= 0 or d["fy"] <= 0 or d["baseline_m"] <= 0:
            raise ConfigError(path, "fx/fy/baseline_m", "must be positive")
        density = d.get("dot_density", 0.2)
        if not isinstance(density, (int, float)) or not 0 < density < 1:
            raise ConfigError(path, "dot_density", f"must be in (0, 1), got {density!r}")
        if not isinstance(d["effects"], list):
            raise ConfigError(path, "effects", "must be a list of {effect: {params}}")
        effects = []
        for i, item in enumerate(d["effects"]):
            if isinstance(item, str):
                item = {item: {}}
            if not isinstance(item, dict) or len(item) != 1:
                raise ConfigError(path, f"effects[{i}]", "must be one effect name with params")
            (name, params), = item.items()
            if name not in EFFECTS:
                raise ConfigError(path, f"effects[{i}]", f"unknown effect {name!r} (known: "
                                                         f"{', '.join(sorted(EFFECTS))})")
            try:
                effects.append(EFFECTS[name](**(params or {})))
            except ConfigError as e:
                raise ConfigError(path, f"effects[{i}].{e.field}", e.message) from None
        names = [e.NAME for e in effects]
        if len(set(names)) != len(names):
            raise ConfigError(path, "effects", "an effect is listed twice")
        if "encode" in names and names[-1] != "encode":
            raise ConfigError(path, "effects", "encode must come last")
        intr = Intrinsics(d["width"], d["height"], float(d["fx"]), float(d["fy"]),
                          float(d["cx"]), float(d["cy"]))
        return cls(str(d["name"]), intr, float(d["baseline_m"]), tuple(effects),
                   int(d.get("pattern_seed", 0)), float(density), str(path))

    @property
    def needs(self) -> frozenset[str]:
        out: set[str] = set()
        for e in self.effects:
            out |= e.needs
        return frozenset(out)

    @property
    def effect_names(self) -> list[str]:
        return [e.NAME for e in self.effects]

    def effect(self, name: str) -> Effect | None:
        return next((e for e in self.effects if e.NAME == name), None)

    def to_dict(self) -> dict:
        return {"name": self.name, "intrinsics": self.intrinsics.to_dict(),
                "baseline_m": self.baseline_m, "pattern_seed": self.pattern_seed,
                "dot_density": self.dot_density, "effects": [e.to_dict() for e in self.effects]}


@dataclass
class SensorOutput:
    depth_mm: np.ndarray  # (H, W) uint16, 0 = no measurement
    valid: np.ndarray  # (H, W) bool
    labels: np.ndarray | None  # moved with the pixels by geometric effects
    raw11: np.ndarray | None  # (H, W) uint16, 2047 = invalid, when encode.raw11
    disparity: np.ndarray  # (H, W) float64 px, 0 where invalid
    holes: dict  # cause -> pixel count


class SensorModel:
    """Runs a :class:`SensorConfig` on rendered frames."""

    def __init__(self, cfg: SensorConfig):
        self.cfg = cfg
        intr = cfg.intrinsics
        self.pattern = dot_pattern(cfg.pattern_seed, intr.height, intr.width, cfg.dot_density)
        from vhgen.camera import pixel_rays

        rays = pixel_rays(intr)
        self.ray_norm = np.linalg.norm(rays, axis=-1)
        self.rays_unit = np.ascontiguousarray(rays / self.ray_norm[..., None])

    def simulate(self, depth: np.ndarray, rng: np.random.Generator | None, *,
                 labels: np.ndarray | None = None, normals: np.ndarray | None = None,
                 projector_depth: np.ndarray | None = None) -> SensorOutput:
        """Apply the effects in order to a rendered planar depth image (metres, 0 = no hit).

        rng : the frame's generator; required when an effect is random, never drawn from
        otherwise. Raises ValueError when an input an effect needs is missing.
        """
        cfg = self.cfg
        z = np.ascontiguousarray(depth)
        if z.shape != (cfg.intrinsics.height, cfg.intrinsics.width):
            raise ValueError(f"depth {z.shape} does not match the sensor "
                             f"{cfg.intrinsics.height}x{cfg.intrinsics.width}")
        need = cfg.needs
        if "normals" in need and normals is None:
            raise ValueError(f"sensor {cfg.name} needs normals")
        if "projector_depth" in need and projector_depth is None:
            raise ValueError(f"sensor {cfg.name} needs a projector-view depth image")
        if any(e.random for e in cfg.effects) and rng is None:
            raise ValueError(f"sensor {cfg.name} draws noise: pass the frame's Generator")
        from vhgen.sensor.kernels import finish, sanitise

        z, hit = sanitise(z)  # a fresh array: effects may work in place
        s = SensorState(cfg.intrinsics, cfg.baseline_m, z, hit, labels=labels, normals=normals,
                        projector_depth=projector_depth, pattern=self.pattern,
                        rays_unit=self.rays_unit, ray_norm=self.ray_norm)
        s.holes["no_hit"] = ~hit
        for e in cfg.effects:
            e.apply(s, rng)
        in_d = s.domain == "d"
        depth_mm, ok, d = finish(s.d if in_d else s.z, s.valid, s.fb, in_d)
        enc = cfg.effect("encode")
        raw = None
        if enc is not None and enc.params["raw11"]:
            from vhgen.sensor.kernels import encode_raw11

            raw = encode_raw11(d, ok, enc.params["d_off"])
        holes = {c: int(np.count_nonzero(m)) for c, m in s.holes.items() if c in HOLE_CAUSES}
        return SensorOutput(depth_mm, ok, s.labels, raw, d, holes)
