"""The ``scene:`` section of a job config (frozen; parsed by :mod:`vhgen.config`).

Absent section = today's scene: one person, no floor, no walls (existing configs keep
their bytes)."""

from __future__ import annotations

from dataclasses import dataclass

# Clearances used to place a room around the person and the camera (metres): a person
# with arms out fits in a 0.6 m radius; the camera body needs a little room behind it.
PERSON_CLEARANCE_M = 0.6
CAMERA_CLEARANCE_M = 0.3
OPEN_FLOOR_HALF_M = 10.0  # half side of the floor when there are no walls


@dataclass(frozen=True)
class RoomConfig:
    """A rectangular room sampled per frame: size ranges, wall height, and how far its
    axes turn away from the camera's viewing direction (degrees)."""

    width_m: tuple[float, float] = (4.0, 7.0)
    depth_m: tuple[float, float] = (4.0, 7.0)
    height_m: tuple[float, float] = (2.4, 3.0)
    yaw_deg: tuple[float, float] = (-25.0, 25.0)


@dataclass(frozen=True)
class SceneConfig:
    """What is around the people: a floor (y = 0) and optionally a room's walls."""

    floor: bool = False
    room: RoomConfig | None = None

    @property
    def has_geometry(self) -> bool:
        return self.floor or self.room is not None
