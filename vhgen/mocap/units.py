"""Length units of BVH files: names, and detection from the skeleton's size.

Detection compares the rest-pose height (joints and End Sites) with an adult's ~1.7 m
under each candidate unit and picks the nearest in log scale. A child recorded in inches
can look like an adult in CMU units (factor 2.2), so maps declare their dialect's unit and
configs can override it; ``auto`` is the fallback.
"""

from __future__ import annotations

import numpy as np

from vhgen.errors import ConfigError

UNITS_M = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "cmu": (1.0 / 0.45) * 2.54 / 100.0,  # 0.056444 m: CMU/ASF units (CMU FAQ)
}
ADULT_HEIGHT_M = 1.7


def parse_units(value, source=None, field: str = "units") -> float | None:
    """A unit name, a positive number of metres per unit, or 'auto' (returns None)."""
    if value is None or value == "auto":
        return None
    if isinstance(value, str):
        if value not in UNITS_M:
            raise ConfigError(source, field, f"unknown unit {value!r} (one of "
                                             f"{', '.join(UNITS_M)}, auto, or metres per unit)")
        return UNITS_M[value]
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0:
        return float(value)
    raise ConfigError(source, field, f"must be a unit name or a positive number, got {value!r}")


def skeleton_height(rest_positions: np.ndarray, end_sites_world: np.ndarray) -> float:
    """Vertical extent of the rest pose (joints and End Sites), in file units."""
    pts = np.vstack([rest_positions, end_sites_world[np.isfinite(end_sites_world).all(1)]])
    return float(pts[:, 1].max() - pts[:, 1].min())


def detect_units(height: float) -> tuple[str, float]:
    """(name, metres per unit) whose reading of ``height`` is nearest to an adult's."""
    if not height > 0:
        raise ValueError("skeleton has no height")
    name = min(UNITS_M, key=lambda u: abs(np.log(height * UNITS_M[u] / ADULT_HEIGHT_M)))
    return name, UNITS_M[name]


def estimate_units(height: float, tolerance: float = 1.3) -> tuple[str, float]:
    """Like :func:`detect_units`, but when no named unit reads ``height`` within a factor
    ``tolerance`` of an adult's height, the unit is taken from the skeleton's size alone:
    ("scaled", 1.7 m / height). For skeletons in unusual units (e.g. ~4 cm per unit)."""
    name, m = detect_units(height)
    if abs(np.log(height * m / ADULT_HEIGHT_M)) <= np.log(tolerance):
        return name, m
    return "scaled", ADULT_HEIGHT_M / height
