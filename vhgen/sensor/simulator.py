"""The sensor runtime: a :class:`SensorConfig` compiled into stages, run on rendered frames.

:class:`SensorModel` owns everything that is computed once per sensor (the dot pattern,
viewing rays, each stage's caches); the config it was built from stays a plain, frozen
description. The output encoding is applied here and nowhere else.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from vhgen.camera import pixel_rays
from vhgen.sensor import stages as _stages  # noqa: F401  (registers the shipped stages)
from vhgen.sensor import structured_light as _reference  # noqa: F401  (and the reference)
from vhgen.sensor.pattern import PATTERN_PAD, dot_pattern
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.sensor_kernels import encode_raw11, finish, sanitise
from vhgen.sensor.stage import Stage, compile_stage
from vhgen.sensor.state import SensorState

__all__ = ["PATTERN_PAD", "FrameSensor", "SensorConfig", "SensorModel", "SensorOutput",
           "dot_pattern"]


@dataclass
class SensorOutput:
    """One simulated frame; arrays are (H, W)."""

    depth_mm: np.ndarray  # uint16, 0 = no measurement
    valid: np.ndarray  # bool
    labels: np.ndarray | None  # moved with the pixels by geometric effects
    raw11: np.ndarray | None  # uint16, 2047 = invalid, when the encoding keeps raw11
    disparity: np.ndarray  # float64 px, 0 where invalid
    holes: dict[str, int]  # cause -> pixel count
    hole_masks: dict[str, np.ndarray] | None = None  # cause -> (H, W) bool, the pixels


class FrameSensor(Protocol):
    """What runs a sensor on frames: :class:`SensorModel` (``backend: cpu``) or the GL
    passes (``backend: gl``, :class:`vhgen.render.sensor_gl.GLSensorModel`)."""

    cfg: SensorConfig

    def simulate(self, depth: np.ndarray, rng: np.random.Generator | None, *,
                 labels: np.ndarray | None = None, incidence: np.ndarray | None = None,
                 projector_depth: np.ndarray | None = None) -> SensorOutput:
        """One frame's output (see :meth:`SensorModel.simulate`)."""
        ...


class SensorModel:
    """Runs a :class:`SensorConfig` on rendered frames."""

    def __init__(self, cfg: SensorConfig):
        self.cfg = cfg
        intr = cfg.intrinsics
        self.pattern = dot_pattern(cfg.pattern_seed, intr.height, intr.width, cfg.dot_density)
        self.pattern.setflags(write=False)
        rays = pixel_rays(intr)
        self.ray_norm = np.linalg.norm(rays, axis=-1)
        self.stages: tuple[Stage[Any], ...] = tuple(compile_stage(e, cfg) for e in cfg.effects)

    def simulate(self, depth: np.ndarray, rng: np.random.Generator | None, *,
                 labels: np.ndarray | None = None, incidence: np.ndarray | None = None,
                 projector_depth: np.ndarray | None = None) -> SensorOutput:
        """Apply the effects in order to a rendered planar depth image.

        depth : (H, W) float32/64 metres, 0 (or NaN, inf, <= 0) = no hit. labels : (H, W)
        uint8 (or packed uint32 ids); incidence : (H, W) |cos| of the angle between
        surface normal and viewing ray, in [0, 1]; projector_depth : (H, W) planar depth seen
        from the projector. rng : the frame's generator; required when an effect is
        random, never drawn from otherwise. Raises ValueError when an input an effect
        needs is missing.
        """
        cfg = self.cfg
        z = np.ascontiguousarray(depth)
        if z.shape != (cfg.intrinsics.height, cfg.intrinsics.width):
            raise ValueError(f"depth {z.shape} does not match the sensor "
                             f"{cfg.intrinsics.height}x{cfg.intrinsics.width}")
        need = cfg.needs
        if "incidence" in need and incidence is None:
            raise ValueError(f"sensor {cfg.name} needs the incidence (|cos| of the angle "
                             "between surface normal and viewing ray)")
        if "projector_depth" in need and projector_depth is None:
            raise ValueError(f"sensor {cfg.name} needs a projector-view depth image")
        if cfg.random and rng is None:
            raise ValueError(f"sensor {cfg.name} draws noise: pass the frame's Generator")
        z, hit = sanitise(z)  # a fresh array: effects may work in place
        s = SensorState(cfg.intrinsics, cfg.baseline_m, z, hit, labels=labels,
                        incidence=None if incidence is None else
                        np.ascontiguousarray(incidence, dtype=np.float32),
                        projector_depth=projector_depth, pattern=self.pattern,
                        ray_norm=self.ray_norm)
        s.holes["no_hit"] = ~hit
        for stage in self.stages:
            stage.apply(s, rng)
        in_d = s.domain == "d"
        depth_mm, ok, d = finish(s.active(), s.valid, s.fb, in_d)
        enc = cfg.encoding
        raw = encode_raw11(d, ok, enc.d_off) if enc.raw11 else None
        holes = {c: int(np.count_nonzero(m)) for c, m in s.holes.items()}
        return SensorOutput(depth_mm, ok, s.labels, raw, d, holes, s.holes)
