"""Depth sensor models: effect specs (pure description, imported with ``vhgen``) and their
runtime (:mod:`vhgen.sensor.simulator`, NumPy and numba kernels; no GL, no Ray)."""

from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.spec import EffectSpec, Encoding, effect_types

__all__ = ["EffectSpec", "Encoding", "SensorConfig", "effect_types"]
