"""Real frames in: the statistics of every readable depth file under some paths."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from vhgen.camera import Intrinsics
from vhgen.depthfile import iter_depth_files
from vhgen.errors import DepthFileError
from vhgen.realism.stats import FrameStats, frame_stats


def _say(msg: str) -> None:
    logging.getLogger("vhgen.realism").warning(msg)


@dataclass
class RealFrames:
    """The statistics of the readable real frames, the files they came from, their
    (median) focal length and the intrinsics of the first frame that had them."""

    stats: list[FrameStats]
    files: list[str]
    fx: float | None
    intrinsics: Intrinsics | None


def real_stats(paths: Sequence[str], intrinsics: Intrinsics | None = None,
               fx: float | None = None, warn: Callable[[str], None] = _say) -> RealFrames:
    """Statistics of every readable real frame under ``paths`` (files or folders). A file
    that cannot be read is reported through ``warn`` (one line) and skipped. A frame
    without intrinsics (a PNG) uses ``fx``; a PNG with neither is reported and skipped."""
    out = RealFrames([], [], None, intrinsics)
    fxs: list[float] = []
    for item in iter_depth_files(paths, intrinsics):
        if isinstance(item, DepthFileError):
            warn(f"skipped {item}")
            continue
        f = item.intrinsics.fx if item.intrinsics is not None else fx
        if f is None:
            warn(f"skipped {item.path}: no intrinsics (a PNG): give --fx")
            continue
        if out.intrinsics is None and item.intrinsics is not None:
            out.intrinsics = item.intrinsics
        out.stats.append(frame_stats(item.depth_mm, f))
        out.files.append(item.path)
        fxs.append(f)
    out.fx = float(np.median(fxs)) if fxs else None
    return out
