"""Typed, validated effect specs: the description half of a sensor effect.

An effect is a frozen dataclass whose fields are its parameters. Each field carries its
type, unit and range in :func:`number`, :func:`choice` or :func:`flag` metadata, so the
class is the documentation. Construction parses and validates every field (in the style
of zarr-python's metadata classes: ``parse_*`` on the way in, plain values after):
integers must be integers, odd windows odd, numbers finite and inside their range.
A failing field raises :class:`SpecError` naming the field; the sensor loader adds the
file and the position in the effect list.

An effect also declares which channels of the per-frame state it reads and writes
(:data:`CHANNELS`), so a sensor whose ordering cannot work is refused when it is loaded
(see :func:`check_order`), never on the first frame.

Subclasses register themselves under their ``name`` (``class Foo(EffectSpec,
name="foo")``); the runtime half (what the effect does to a frame) is a
:class:`vhgen.sensor.stage.Stage` registered for the spec class.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Self

# What an effect may read or write. depth_m / disparity: the measurement, in metres
# (planar z) or pixels (d = f b / z); the state converts between them on demand, so either
# can follow either. valid: the validity mask; holes: per-cause hole masks; labels,
# incidence: rendered ground truth aligned with the pixels (|cos| of the angle between
# surface normal and viewing ray); projector_depth: planar depth
# rendered from the projector on the ideal pinhole grid; pattern: the projector's dots;
# pixel_grid: the pixel lattice itself (written by effects that resample the image
# through a lens model, after which channels not carried along no longer line up).
CHANNELS = frozenset({"depth_m", "disparity", "valid", "holes", "labels", "incidence",
                      "projector_depth", "pattern", "pixel_grid"})
# channels the renderer provides on request (SensorConfig.needs)
RENDERED = frozenset({"incidence", "projector_depth"})


class SpecError(ValueError):
    """A bad effect parameter: ``field`` and a message; the loader adds file and position."""

    def __init__(self, field: str, message: str):
        self.field = field
        self.message = message
        super().__init__(f"{field}: {message}")


@dataclass(frozen=True)
class Number:
    """A numeric parameter: float (ints accepted) or, with ``integer``, an int (a float
    with no fraction, such as 9.0, is taken as that int)."""

    lo: float | None = None
    hi: float | None = None
    unit: str = ""
    integer: bool = False
    odd: bool = False

    def parse(self, name: str, v: object) -> float | int:
        kind = "an integer" if self.integer else "a number"
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SpecError(name, f"must be {kind}, got {v!r}")
        if not math.isfinite(v):
            raise SpecError(name, f"must be finite, got {v!r}")
        # 9.0 (older sensor files wrote integers as floats) is 9; 9.5 is an error
        if self.integer and not float(v).is_integer():
            raise SpecError(name, f"must be {kind}, got {v!r}")
        if (self.lo is not None and v < self.lo) or (self.hi is not None and v > self.hi):
            raise SpecError(name, f"{v!r} is outside [{self.lo}, {self.hi}]"
                                  + (f" {self.unit}" if self.unit else ""))
        if self.odd and int(v) % 2 != 1:
            raise SpecError(name, f"must be odd, got {v!r}")
        return int(v) if self.integer else float(v)


@dataclass(frozen=True)
class Choice:
    """One of a fixed set of strings."""

    options: tuple[str, ...]

    def parse(self, name: str, v: object) -> str:
        if not isinstance(v, str) or v not in self.options:
            raise SpecError(name, f"{v!r} is not one of {', '.join(self.options)}")
        return v


@dataclass(frozen=True)
class Flag:
    """true / false."""

    def parse(self, name: str, v: object) -> bool:
        if not isinstance(v, bool):
            raise SpecError(name, f"must be true/false, got {v!r}")
        return v


def number(default: float, lo: float | None = None, hi: float | None = None, *,
           unit: str = "", integer: bool = False, odd: bool = False) -> Any:
    """A numeric field of an effect spec (use as the dataclass field's default)."""
    return dataclasses.field(default=default, metadata={
        "kind": Number(lo, hi, unit, integer, odd)})


def choice(default: str, *options: str) -> Any:
    """A string field taking one of ``options``."""
    return dataclasses.field(default=default, metadata={"kind": Choice(options)})


def flag(default: bool) -> Any:
    """A boolean field."""
    return dataclasses.field(default=default, metadata={"kind": Flag()})


@dataclass(frozen=True)
class Params:
    """A frozen set of typed parameters, parsed and validated on construction."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            kind = f.metadata.get("kind")
            if isinstance(kind, (Number, Choice, Flag)):
                object.__setattr__(self, f.name, kind.parse(f.name, getattr(self, f.name)))
        self.check()

    def check(self) -> None:
        """Cross-field checks; raise :class:`SpecError`."""

    @classmethod
    def from_dict(cls, params: Mapping[str, object] | None) -> Self:
        """Parse YAML parameters; unknown keys are errors (:class:`SpecError`)."""
        params = dict(params or {})
        allowed = [f.name for f in dataclasses.fields(cls)]
        for k in params:
            if k not in allowed:
                raise SpecError(str(k), f"unknown parameter (allowed: "
                                        f"{', '.join(allowed) or 'none'})")
        return cls(**params)

    def values(self) -> dict[str, object]:
        """``{param: value}`` in declaration order."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


_REGISTRY: dict[str, type[EffectSpec]] = {}


def effect_types() -> Mapping[str, type[EffectSpec]]:
    """Every registered effect spec by name (a copy)."""
    return dict(_REGISTRY)


@dataclass(frozen=True)
class EffectSpec(Params):
    """Base of every effect spec: a frozen dataclass of validated parameters.

    Subclasses pass ``name=`` in the class statement and set ``READS`` / ``WRITES``
    (subsets of :data:`CHANNELS`) and ``RANDOM`` as class attributes, or override the
    properties ``reads`` / ``writes`` / ``random`` when they depend on the parameters.
    """

    name: ClassVar[str] = ""
    READS: ClassVar[frozenset[str]] = frozenset()
    WRITES: ClassVar[frozenset[str]] = frozenset()
    RANDOM: ClassVar[bool] = False
    # a GL pass exists for it (vhgen/render/sensor_gl.py; a test checks the two agree);
    # parameter values it cannot run are named by gl_unsupported
    GL: ClassVar[bool] = False

    def __init_subclass__(cls, name: str = "", **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if name:
            if name in _REGISTRY or name == Encoding.name:
                raise TypeError(f"effect name {name!r} is taken")
            bad = (cls.READS | cls.WRITES) - CHANNELS
            if bad:
                raise TypeError(f"effect {name!r} declares unknown channels {sorted(bad)}")
            cls.name = name
            _REGISTRY[name] = cls

    def to_dict(self) -> dict[str, dict[str, object]]:
        """``{name: {param: value}}``, as written in a sensor file and in dataset attrs."""
        return {self.name: self.values()}

    @property
    def reads(self) -> frozenset[str]:
        """Channels this effect reads (see :data:`CHANNELS`)."""
        return self.READS

    @property
    def writes(self) -> frozenset[str]:
        """Channels this effect writes."""
        return self.WRITES

    @property
    def random(self) -> bool:
        """Whether this configured effect draws random numbers."""
        return self.RANDOM

    @property
    def needs(self) -> frozenset[str]:
        """What the renderer must provide for it (incidence, projector_depth)."""
        return self.reads & RENDERED

    def gl_unsupported(self) -> tuple[str, str] | None:
        """``(field, reason)`` when ``backend: gl`` cannot run this configured effect (field
        "" for the effect as a whole), None when it can. Checked when the sensor is loaded,
        so a sensor the GL backend cannot run never reaches a frame."""
        if not self.GL:
            return "", "has no GL pass yet"
        return None


def check_order(effects: tuple[EffectSpec, ...]) -> tuple[int, str] | None:
    """``(index, reason)`` of the first effect that cannot run where it is listed, or None.

    An effect that resamples the pixel grid (writes ``pixel_grid``) leaves every channel
    it does not write (carry along) on the old grid; a later effect reading such a channel
    would mix two grids.
    """
    stale: dict[str, str] = {}  # channel -> the effect that left it behind
    for i, e in enumerate(effects):
        for ch in sorted(e.reads & stale.keys()):
            return i, (f"{e.name} reads {ch}, which is rendered on the ideal pinhole grid, "
                       f"but {stale[ch]} has already resampled the pixels through its lens "
                       f"model; list {e.name} before {stale[ch]}")
        if "pixel_grid" in e.writes:
            for ch in RENDERED - e.writes:
                stale.setdefault(ch, e.name)
        for ch in e.writes - {"pixel_grid"}:
            stale.pop(ch, None)
    return None


@dataclass(frozen=True)
class Encoding(Params):
    """E10, the output encoding (the ``encode`` entry of a sensor file, which comes last).

    Depth is always written as uint16 mm (0 = no measurement, > 65.535 m invalid); with
    ``raw11`` the 11-bit raw value k_d = round(d_off - 8 d) is kept as well (2047 =
    invalid, values outside 0..2046 invalid).
    """

    raw11: bool = flag(False)
    d_off: float = number(1090.0, 0.0, 4096.0, unit="raw units")

    name: ClassVar[str] = "encode"

    def to_dict(self) -> dict[str, dict[str, object]]:
        return {self.name: self.values()}
