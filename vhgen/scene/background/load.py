"""A job's real backgrounds, read once (pure): every frame of the config's sources read,
checked against the sensor, its floor found and its free floor mapped
(:mod:`vhgen.scene.background.floor`); a frame without a floor or without free floor is
reported in one line and left out. Called by ``prepare_job``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.camera import Intrinsics
from vhgen.errors import BackgroundError, ConfigError, DepthFileError
from vhgen.scene.background.background_frame import FloorPlane, PlacedBackground
from vhgen.scene.background.floor import estimate_floor, free_floor, reachable
from vhgen.scene.scene_config import BackgroundSource

# a background whose free floor holds no disc this wide is left out: a person standing
# with the arms down needs about 0.4 m, and 9 cm more for the gap and the spot's jitter
MIN_FREE_RADIUS_M = 0.5


# -- the job's backgrounds --------------------------------------------------------------
def intrinsics_mismatch(given: Intrinsics | Sequence[float], sensor: Intrinsics) -> str | None:
    """Why a background's intrinsics (an Intrinsics or fx, fy, cx, cy) are not the
    sensor's, or None when they are: focal lengths within 0.2%, principal point within
    1 px (less than 0.7 px anywhere in a 640 px image). People are rendered and sensed
    with the sensor's camera, so the real frame must come from that camera."""
    g = (given.fx, given.fy, given.cx, given.cy) if isinstance(given, Intrinsics) else tuple(given)
    s = (sensor.fx, sensor.fy, sensor.cx, sensor.cy)
    if (abs(g[0] - s[0]) <= 2e-3 * s[0] and abs(g[1] - s[1]) <= 2e-3 * s[1]
            and abs(g[2] - s[2]) <= 1.0 and abs(g[3] - s[3]) <= 1.0):
        return None
    return (f"intrinsics fx {g[0]:g} fy {g[1]:g} cx {g[2]:g} cy {g[3]:g} are not the "
            f"sensor's ({s[0]:g}, {s[1]:g}, {s[2]:g}, {s[3]:g}): people are rendered and "
            "sensed with the sensor's camera, so a background must be taken by it (a "
            "sensor fitted to these frames: vhgen sensor fit)")


@dataclass(frozen=True, eq=False)
class Backgrounds:
    """A job's usable backgrounds, read once by :func:`load_backgrounds`.

    depth_mm (N, H, W) uint16 and clearance (N, Z, X) uint8 cm (see :func:`free_floor`,
    zero-padded to a common size) are single read-only arrays, so a job with hundreds of
    backgrounds reaches its workers as two memory-mapped files (local workers) or shared
    objects (Ray), not one copy per worker. origins (N, 2) float64: each grid's cell
    [0, 0] centre (x, z). skipped: one line per file or entry left out.
    """

    files: tuple[str, ...]
    class_names: tuple[str, ...]
    floors: tuple[FloorPlane, ...]
    depth_mm: np.ndarray
    clearance: np.ndarray
    origins: np.ndarray
    skipped: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.files)

    def get(self, i: int) -> PlacedBackground:
        return PlacedBackground(i, self.files[i], self.floors[i], self.depth_mm[i],
                                self.class_names[i])


def load_backgrounds(sources: Sequence[BackgroundSource], intr: Intrinsics,
                     reach: tuple[float, float], warn: Callable[[str], None],
                     config: str | None = None) -> Backgrounds:
    """Read every frame of ``sources`` (files and folders, see
    :func:`vhgen.depthfile.depth_files`), check it, find its floor and free floor.

    A frame of another size than the sensor's ``intr``, with other intrinsics (see
    :func:`intrinsics_mismatch`; a PNG has the entry's given ones, or the sensor's), with
    no floor, or whose free floor within ``reach`` holds no disc of MIN_FREE_RADIUS_M, or
    that cannot be read, is one ``warn`` line naming the file, and is left out; a folder
    that leaves nothing is one line naming its field. No usable frame at all:
    ConfigError naming ``scene.backgrounds`` (of the config file ``config``).
    """
    from vhgen.depthfile import depth_files, read_depth

    files, classes, floors, depths, grids, origins, skipped = [], [], [], [], [], [], []

    def skip(msg: str) -> None:
        skipped.append(msg)
        warn(msg)

    for i, src in enumerate(sources):
        given = (Intrinsics(intr.width, intr.height, *src.intrinsics)
                 if src.intrinsics is not None else intr)
        found = 0
        for f in depth_files([src.path]):
            try:
                frame = read_depth(f, given if f.suffix.lower() == ".png" else None)
                h, w = frame.depth_mm.shape
                if (w, h) != (intr.width, intr.height):
                    raise BackgroundError(f, f"{w}x{h} px, the sensor's frames are "
                                          f"{intr.width}x{intr.height}")
                bad = intrinsics_mismatch(frame.intrinsics or given, intr)
                if bad:
                    raise BackgroundError(f, bad)
                floor = estimate_floor(frame.depth_mm, intr, str(f))
                origin, clear = free_floor(frame.depth_mm, intr, floor)
                room = clear[reachable(origin, clear, reach)]
                widest = float(room.max(initial=0)) / 100.0
                if widest < MIN_FREE_RADIUS_M:
                    raise BackgroundError(f, f"no free floor: the widest free circle "
                                          f"{reach[0]:g}-{reach[1]:g} m from the camera "
                                          f"(camera.distance_m) has a radius of {widest:.2f}"
                                          f" m (at least {MIN_FREE_RADIUS_M} m needed)")
            except (DepthFileError, BackgroundError) as e:
                skip(f"skipped background {e}")
                continue
            files.append(str(f))
            classes.append(src.class_name)
            floors.append(floor)
            depths.append(frame.depth_mm)
            grids.append(clear)
            origins.append(origin)
            found += 1
        if not found and Path(src.path).is_dir():  # a file has said why in its line
            skip(f"scene.backgrounds[{i}]: no usable depth frame in {src.path}")
    if not files:
        raise ConfigError(config, "scene.backgrounds", f"no usable background frame in "
                          f"{len(sources)} entr{'y' if len(sources) == 1 else 'ies'} "
                          f"({len(skipped)} line{'s' if len(skipped) != 1 else ''} above say "
                          "why)")
    gz = max(g.shape[0] for g in grids)
    gx = max(g.shape[1] for g in grids)
    clearance = np.zeros((len(grids), gz, gx), np.uint8)
    for k, g in enumerate(grids):
        clearance[k, :g.shape[0], :g.shape[1]] = g
    depth = np.stack(depths)
    for a in (depth, clearance):
        a.setflags(write=False)
    return Backgrounds(tuple(files), tuple(classes), tuple(floors), depth, clearance,
                       np.array(origins, np.float64), tuple(skipped))
