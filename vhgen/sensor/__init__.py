"""Depth sensor models (pure NumPy)."""

from vhgen.sensor.kinect import depth_to_mm, quantise_disparity, simulate

__all__ = ["depth_to_mm", "quantise_disparity", "simulate"]
