"""The ``scene:`` section of a job config (frozen; parsed by :mod:`vhgen.config`).

Absent section = today's scene: one person, no floor, no walls (existing configs keep
their bytes)."""

from __future__ import annotations

from dataclasses import dataclass

from vhgen.scene.props import PARAMETRIC, PropShape

# Clearances used to place a room around the person and the camera (metres): a person
# with arms out fits in a 0.6 m radius; the camera body needs a little room behind it.
PERSON_CLEARANCE_M = 0.6
CAMERA_CLEARANCE_M = 0.3
BEHIND_M = 1.5  # floor kept beyond the first person when a frame may hold more people
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
class PropsConfig:
    """Props per frame: how many (uniform integer in ``count``), of which kinds (the
    parametric ones by name, plus mesh files loaded at config time), and ``occlusion``:
    the range of the per-frame probability that a prop is put on the line of sight to a
    person (partial occlusion), instead of anywhere on the floor."""

    count: tuple[int, int] = (2, 4)
    kinds: tuple[str, ...] = PARAMETRIC
    meshes: tuple[PropShape, ...] = ()
    occlusion: tuple[float, float] = (0.3, 0.6)


@dataclass(frozen=True)
class SceneConfig:
    """What is around the people: a floor (y = 0), optionally a room's walls and props,
    and how many people (uniform integer in ``people``; default exactly 1)."""

    floor: bool = False
    room: RoomConfig | None = None
    people: tuple[int, int] = (1, 1)
    props: PropsConfig | None = None
    # each person keeps at least this fraction of its width in view past nearer people
    # and tall props (a floor-plan test at placement time; see placement.visible_fraction)
    min_visible_fraction: float = 0.5

    @property
    def has_geometry(self) -> bool:
        return self.floor or self.room is not None or self.props is not None

    @property
    def is_person_only(self) -> bool:
        """Today's scene: one person and nothing else (drawn as vhgen always drew it)."""
        return not self.has_geometry and self.people == (1, 1)
