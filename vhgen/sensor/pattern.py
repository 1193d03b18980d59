"""The projector's dot pattern (pure NumPy, fixed per sensor)."""

from __future__ import annotations

import numpy as np

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
