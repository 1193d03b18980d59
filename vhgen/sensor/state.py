"""The per-frame working state the runtime stages act on, and the fast N(0, 1) table.

The state holds the image in the depth domain (planar z, metres) or the disparity domain
(d = f b / z, px, float64) and converts lazily, only on valid pixels, so invalid pixels
never produce inf or NaN.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vhgen.assets import vhgen_home
from vhgen.camera import Intrinsics
from vhgen.sensor.sensor_kernels import invert_inplace, remove_pixels

# hole causes of the shipped effects (an added effect may record its own)
HOLE_CAUSES = ("no_hit", "range", "distortion", "shadow", "dropout", "window", "noise",
               "matching", "registration", "speckle")


NORMAL_TABLE_FILE = "normal_table_v1.npy"


def compute_normal_table() -> np.ndarray:
    """65536 quantiles of N(0, 1), rescaled to unit variance (tails cut at 4.3 sigma)."""
    from scipy.special import ndtri

    t = ndtri((np.arange(65536) + 0.5) / 65536)
    return (t / t.std()).astype(np.float64)


def load_normal_table(cache: Path | None = None) -> np.ndarray:
    """:func:`compute_normal_table`, computed once per machine and kept beside the compiled
    kernels (``$VHGEN_HOME/cache``): importing scipy.special costs every worker process
    about 0.2 s of its start-up, reading the 512 KB file a millisecond. A file that is
    unreadable or not a plausible table is recomputed (and rewritten if possible)."""
    path = (cache or vhgen_home() / "cache") / NORMAL_TABLE_FILE
    try:
        t = np.load(path, allow_pickle=False)
        if (t.shape == (65536,) and t.dtype == np.float64 and np.isfinite(t).all()
                and (np.diff(t) > 0).all() and abs(float(t.std()) - 1.0) < 1e-12):
            return t
    except (OSError, ValueError, EOFError):
        pass
    t = compute_normal_table()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")  # atomic: no torn reads
        with open(tmp, "wb") as f:
            np.save(f, t, allow_pickle=False)
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only cache: compute it in every process
    return t


NORMAL_TABLE = load_normal_table()
NORMAL_TABLE.setflags(write=False)


@dataclass
class SensorState:
    """Per-frame working state. Arrays are (H, W) unless noted."""

    intr: Intrinsics
    baseline_m: float
    z: np.ndarray | None  # float64 metres (depth domain), 0 where invalid
    valid: np.ndarray  # bool
    labels: np.ndarray | None = None
    incidence: np.ndarray | None = None  # (H, W) float32 |cos|, surface normal vs ray
    projector_depth: np.ndarray | None = None  # planar depth seen from the projector
    d: np.ndarray | None = None  # float64 px (disparity domain) when domain == "d"
    domain: str = "z"
    holes: dict[str, np.ndarray] = field(default_factory=dict)  # cause -> removed pixels
    ray_norm: np.ndarray | None = None  # (H, W) |ray| for z = 1
    pattern: np.ndarray | None = None  # the projector's binary dot pattern

    @property
    def fb(self) -> float:
        """f b, px m: disparity d = fb / z."""
        return self.intr.fx * self.baseline_m

    def to_disparity(self) -> np.ndarray:
        """Switch to the disparity domain (in place: the depth array becomes d)."""
        if self.domain == "z":
            assert self.z is not None
            invert_inplace(self.z, self.valid, self.fb)
            self.d, self.z = self.z, None
            self.domain = "d"
        assert self.d is not None
        return self.d

    def to_depth(self) -> np.ndarray:
        """Switch to the depth domain (in place: the disparity array becomes z)."""
        if self.domain == "d":
            assert self.d is not None
            invert_inplace(self.d, self.valid, self.fb)
            self.z, self.d = self.d, None
            self.domain = "z"
        assert self.z is not None
        return self.z

    def active(self) -> np.ndarray:
        """The measurement array of the current domain."""
        a = self.z if self.domain == "z" else self.d
        assert a is not None
        return a

    def incidence_cos(self) -> np.ndarray:
        """|cos| of the incidence angle per pixel, (H, W) float64 (needs the incidence)."""
        if self.incidence is None:
            raise ValueError("this effect needs the incidence")
        return self.incidence.astype(np.float64)

    def normal_draws(self, rng: np.random.Generator) -> np.ndarray:
        """One uint16 draw per pixel, to be mapped through NORMAL_TABLE (fast N(0, 1))."""
        return rng.integers(0, 65536, size=self.valid.size, dtype=np.uint16)

    def hole(self, cause: str) -> np.ndarray:
        """The hole mask of ``cause`` (a fresh all-False mask if none yet)."""
        h = self.holes.get(cause)
        return np.zeros_like(self.valid) if h is None else h

    def record(self, kernel: Callable[[np.ndarray], int], cause: str) -> None:
        """Run ``kernel(hole_mask)``, a fused pass that removes pixels itself, marking them
        in the cause's hole mask; it returns how many it removed."""
        hole = self.hole(cause)
        if kernel(hole):
            self.holes[cause] = hole

    def invalidate(self, mask: np.ndarray, cause: str) -> None:
        """Remove ``mask`` pixels (recording why) and zero them in the active domain."""
        arr = self.active()
        self.record(lambda hole: remove_pixels(np.ascontiguousarray(mask), self.valid, arr,
                                               hole), cause)
