"""A sensor effect outside vhgen: flying pixels removed at disparity jumps."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vhgen.sensor.effects import MEASURE
from vhgen.sensor.spec import EffectSpec, number
from vhgen.sensor.stage import Stage
from vhgen.sensor.state import SensorState


@dataclass(frozen=True)
class EdgeCleanup(EffectSpec, name="edge_cleanup"):
    """Invalidate both pixels of every 4-neighbour pair whose disparities differ by more
    than ``jump_px`` (the mixed 'flying' pixels between a foreground edge and the wall)."""

    jump_px: float = number(2.0, 0.1, 100.0, unit="px")

    READS = MEASURE  # the measurement and its validity; no incidence, no projector pass
    WRITES = MEASURE


class EdgeCleanupStage(Stage[EdgeCleanup], spec=EdgeCleanup):
    """Runtime: one vectorised pass per frame, nothing cached."""

    def apply(self, s: SensorState, rng: np.random.Generator | None) -> None:
        d, v = s.to_disparity(), s.valid
        gy = v[1:] & v[:-1] & (np.abs(d[1:] - d[:-1]) > self.spec.jump_px)
        gx = v[:, 1:] & v[:, :-1] & (np.abs(d[:, 1:] - d[:, :-1]) > self.spec.jump_px)
        edge = np.zeros_like(v)
        edge[1:] |= gy
        edge[:-1] |= gy
        edge[:, 1:] |= gx
        edge[:, :-1] |= gx
        s.invalidate(edge, "edge")  # zeroes them and counts them under holes["edge"]
