"""Depth sensor models (NumPy and numba kernels; no GL, no Ray)."""

from vhgen.sensor.effects import EFFECTS, SensorState
from vhgen.sensor.model import SensorConfig, SensorModel, SensorOutput, dot_pattern

__all__ = ["EFFECTS", "SensorConfig", "SensorModel", "SensorOutput", "SensorState",
           "dot_pattern"]
