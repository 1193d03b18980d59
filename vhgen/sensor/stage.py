"""The runtime half of an effect: a stage compiled from a spec for one sensor.

A stage is built once per :class:`vhgen.sensor.simulator.SensorModel` (so it may own caches:
undistortion maps, kernels' scratch) and applied to every frame. Stage classes register
themselves for their spec class (``class FooStage(Stage, spec=Foo)``).
"""

from __future__ import annotations

from typing import Any, ClassVar, Generic, TypeVar

import numpy as np

from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.spec import EffectSpec
from vhgen.sensor.state import SensorState

S = TypeVar("S", bound=EffectSpec)
_STAGES: dict[type[EffectSpec], type[Stage[Any]]] = {}


class Stage(Generic[S]):
    """Base of every runtime stage: ``apply`` one frame's state in place."""

    SPEC: ClassVar[type[EffectSpec]]

    def __init_subclass__(cls, spec: type[EffectSpec] | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if spec is not None:
            if spec in _STAGES:
                raise TypeError(f"effect {spec.name!r} has two stages "
                                f"({_STAGES[spec].__qualname__}, {cls.__qualname__})")
            cls.SPEC = spec
            _STAGES[spec] = cls

    def __init__(self, spec: S, sensor: SensorConfig):
        self.spec = spec
        self.sensor = sensor

    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        """Act on ``s`` in place; ``rng`` is the frame's generator (None if not random)."""
        raise NotImplementedError


def compile_stage(spec: EffectSpec, sensor: SensorConfig) -> Stage[Any]:
    """The runtime stage of ``spec`` for ``sensor``."""
    cls = _STAGES.get(type(spec))
    if cls is None:
        raise TypeError(f"effect {spec.name!r} ({type(spec).__qualname__}) has no Stage; "
                        f"define one with `class ...(Stage, spec={type(spec).__name__})`")
    return cls(spec, sensor)
