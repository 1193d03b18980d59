"""A sensor: intrinsics, baseline, the projector's dot pattern, an ordered effect list and
the output encoding. Pure description (frozen, no caches); :class:`vhgen.sensor.simulator.
SensorModel` compiles it into runtime stages.

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
      - encode: {}               # the output encoding; last if present

Unknown effects or parameters, and orderings that cannot work, are config errors naming
the file and the field. The renderer is asked only for what the effects need
(:attr:`SensorConfig.needs`): the incidence, a projector-view depth image.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vhgen.camera import Intrinsics
from vhgen.errors import ConfigError
from vhgen.sensor import effects as _shipped  # noqa: F401  (registers the shipped effects)
from vhgen.sensor.spec import EffectSpec, Encoding, SpecError, check_order, effect_types
from vhgen.yamlio import check_keys, find_config, load_yaml

_KEYS = {"name", "width", "height", "fx", "fy", "cx", "cy", "baseline_m", "effects",
         "pattern_seed", "dot_density", "description", "backend"}
# where the effects run: "cpu", the numba stages (the reference), or "gl", the compute
# passes of vhgen.render.sensor_gl over the rendered textures
BACKENDS = ("cpu", "gl")
_REQUIRED = {"name", "width", "height", "fx", "fy", "cx", "cy", "baseline_m", "effects"}


def _number(d: dict[str, Any], key: str, source: Path) -> float:
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(source, key, f"must be a number, got {v!r}")
    return float(v)


def parse_effects(items: object, source: str | Path | None
                  ) -> tuple[tuple[EffectSpec, ...], Encoding]:
    """The ``effects:`` list of a sensor file -> (effect specs in order, encoding).

    Raises ConfigError naming ``source`` and ``effects[i].name.param`` for an unknown
    effect or parameter, a bad value, an effect listed twice, ``encode`` not last, or an
    ordering that cannot work (with the reason).
    """
    if not isinstance(items, list):
        raise ConfigError(source, "effects", "must be a list of {effect: {params}}")
    known = effect_types()
    specs: list[EffectSpec] = []
    encoding: Encoding | None = None
    for i, item in enumerate(items):
        if isinstance(item, str):
            item = {item: {}}
        if not isinstance(item, dict) or len(item) != 1:
            raise ConfigError(source, f"effects[{i}]", "must be one effect name with params")
        (name, params), = item.items()
        where = f"effects[{i}].{name}"
        if params is not None and not isinstance(params, dict):
            raise ConfigError(source, where, f"parameters must be a mapping, got {params!r}")
        if encoding is not None:
            raise ConfigError(source, "effects", "encode must come last")
        try:
            if name == Encoding.name:
                encoding = Encoding.from_dict(params)
                continue
            if name not in known:
                raise ConfigError(source, f"effects[{i}]", f"unknown effect {name!r} (known: "
                                  f"{', '.join(sorted([*known, Encoding.name]))})")
            spec = known[name].from_dict(params)
        except SpecError as e:
            raise ConfigError(source, f"{where}.{e.field}", e.message) from None
        except TypeError as e:  # a parameter key that is not a string
            raise ConfigError(source, where, str(e)) from None
        if any(s.name == name for s in specs):
            raise ConfigError(source, "effects", f"{name} is listed twice")
        specs.append(spec)
    bad = check_order(tuple(specs))
    if bad is not None:
        i, reason = bad
        raise ConfigError(source, f"effects[{i}].{specs[i].name}", f"cannot run here: {reason}")
    return tuple(specs), encoding or Encoding()


def check_backend(effects: tuple[EffectSpec, ...], backend: object,
                  source: str | Path | None) -> str:
    """``backend`` validated for ``effects``: one of :data:`BACKENDS`, and with ``gl``,
    every effect one the GL backend can run. Raises ConfigError naming
    ``effects[i].name`` (and the parameter) that it cannot, in one line."""
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise ConfigError(source, "backend", f"must be one of {', '.join(BACKENDS)}, "
                                             f"got {backend!r}")
    if backend == "gl":
        for i, e in enumerate(effects):
            gap = e.gl_unsupported()
            if gap is not None:
                field, reason = gap
                where = f"effects[{i}].{e.name}" + (f".{field}" if field else "")
                raise ConfigError(source, where, f"{reason}: backend gl cannot run this "
                                                 "sensor; use backend: cpu")
    return backend


def sensor_section(value: object, source: str | Path | None) -> tuple[object, object]:
    """A job's ``sensor:`` -> (the preset: a name or a YAML path, the backend or None).

    ``value`` is a preset (``openni_525``, ``my_sensor.yaml``) or ``{preset: ...,
    backend: cpu | gl}``; unknown keys are ConfigErrors naming ``sensor.<key>``. The
    preset is checked and loaded by the caller (a path is relative to the job's file);
    the backend by :meth:`SensorConfig.with_backend`.
    """
    if not isinstance(value, dict):
        return value, None
    check_keys(value, {"preset", "backend"}, {"preset"}, source, "sensor.")
    return value["preset"], value.get("backend")


@dataclass(frozen=True, eq=False)
class SensorConfig:
    """A sensor description; frozen and stateless (see the module docstring)."""

    name: str
    intrinsics: Intrinsics
    baseline_m: float
    effects: tuple[EffectSpec, ...]
    encoding: Encoding = Encoding()
    pattern_seed: int = 0
    dot_density: float = 0.2
    source: str | None = None
    backend: str = "cpu"  # see BACKENDS

    @classmethod
    def load(cls, name_or_path: str | Path) -> SensorConfig:
        """A sensor by bare name (``configs/sensors/<name>.yaml``) or YAML path."""
        path = find_config("sensors", name_or_path)
        d = load_yaml(path)
        check_keys(d, _KEYS, _REQUIRED, path, "")
        for k in ("width", "height"):
            if isinstance(d[k], bool) or not isinstance(d[k], int) or not 8 <= d[k] <= 8192:
                raise ConfigError(path, k, f"must be an integer in [8, 8192], got {d[k]!r}")
        fx, fy, cx, cy, base = (_number(d, k, path) for k in ("fx", "fy", "cx", "cy",
                                                              "baseline_m"))
        if fx <= 0 or fy <= 0 or base <= 0:
            raise ConfigError(path, "fx/fy/baseline_m", "must be positive")
        density = d.get("dot_density", 0.2)
        if isinstance(density, bool) or not isinstance(density, (int, float)) or \
                not 0 < density < 1:
            raise ConfigError(path, "dot_density", f"must be in (0, 1), got {density!r}")
        seed = d.get("pattern_seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ConfigError(path, "pattern_seed", f"must be an integer >= 0, got {seed!r}")
        effects, encoding = parse_effects(d["effects"], path)
        backend = check_backend(effects, d.get("backend", "cpu"), path)
        intr = Intrinsics(d["width"], d["height"], fx, fy, cx, cy)
        return cls(str(d["name"]), intr, base, effects, encoding, seed, float(density),
                   str(path), backend)

    def with_backend(self, backend: object, source: str | Path | None = None
                     ) -> SensorConfig:
        """This sensor run by ``backend`` (see :func:`check_backend`; ``source`` names the
        file that asked for it in the error)."""
        b = check_backend(self.effects, backend, source or self.source)
        return self if b == self.backend else dataclasses.replace(self, backend=b)

    @property
    def needs(self) -> frozenset[str]:
        """What the renderer must provide: a subset of {incidence, projector_depth}."""
        out: set[str] = set()
        for e in self.effects:
            out |= e.needs
        return frozenset(out)

    @property
    def random(self) -> bool:
        """Whether any effect draws random numbers (a frame Generator is then required)."""
        return any(e.random for e in self.effects)

    @property
    def effect_names(self) -> list[str]:
        return [e.name for e in self.effects]

    def effect(self, name: str) -> EffectSpec | None:
        """The spec of the effect called ``name``, or None if not listed."""
        return next((e for e in self.effects if e.name == name), None)

    def to_dict(self) -> dict[str, Any]:
        """Plain description (dataset attrs and the manifest's ``sensor`` column); the
        backend only when it is not the reference ``cpu`` (so CPU stores keep their bytes)."""
        d = {"name": self.name, "intrinsics": self.intrinsics.to_dict(),
             "baseline_m": self.baseline_m, "pattern_seed": self.pattern_seed,
             "dot_density": self.dot_density,
             "effects": [e.to_dict() for e in self.effects] + [self.encoding.to_dict()]}
        if self.backend != "cpu":
            d["backend"] = self.backend
        return d
