"""The ``scene:`` section of a job config (frozen; parsed by :mod:`vhgen.job_config`).

Absent section = today's scene: one person, no floor, no walls (existing configs keep
their bytes)."""

from __future__ import annotations

from dataclasses import dataclass

from vhgen.scene.geometry import PROP, SCENE_CLASSES
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
    # the scene class of each entry of ``kinds`` / ``meshes`` (same length; "prop" unless
    # the config gave the entry a ``class`` of its own)
    kind_classes: tuple[str, ...] = ()
    mesh_classes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        # a config built in code may leave the classes out: every entry is a plain prop
        if not self.kind_classes:
            object.__setattr__(self, "kind_classes", ("prop",) * len(self.kinds))
        if not self.mesh_classes:
            object.__setattr__(self, "mesh_classes", ("prop",) * len(self.meshes))
        if (len(self.kind_classes) != len(self.kinds)
                or len(self.mesh_classes) != len(self.meshes)):
            raise ValueError("kind_classes / mesh_classes must match kinds / meshes")

    @property
    def user_classes(self) -> tuple[str, ...]:
        """Class names beyond the built-in ones, in order of first appearance (kinds, then
        meshes)."""
        names = [c for c in self.kind_classes + self.mesh_classes if c not in SCENE_CLASSES]
        return tuple(dict.fromkeys(names))


@dataclass(frozen=True)
class BackgroundSource:
    """One entry of ``scene.backgrounds``: a file or folder of real depth frames (PCD, or
    16-bit PNG in millimetres), the intrinsics its PNG frames were taken with (fx, fy,
    cx, cy; None = the sensor's), and the scene class of its pixels."""

    path: str
    intrinsics: tuple[float, float, float, float] | None = None
    class_name: str = "real"


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
    # real depth frames people are composited into (vhgen.scene.background); with them the
    # floor is the background's and there is no room or props
    backgrounds: tuple[BackgroundSource, ...] = ()

    @property
    def class_names(self) -> tuple[str, ...]:
        """The names of the ``classes`` array's ids: the built-in five (background, floor,
        wall, prop, person; ids 0-4, fixed), the props' user classes, then the classes of
        real background pixels."""
        user = self.props.user_classes if self.props is not None else ()
        real = tuple(b.class_name for b in self.backgrounds)
        return SCENE_CLASSES + tuple(dict.fromkeys(user + real))

    def class_id(self, name: str) -> int:
        """The ``classes`` id of a class name of this scene (``prop`` = 3)."""
        return PROP if name == "prop" else self.class_names.index(name)

    @property
    def has_geometry(self) -> bool:
        return (self.floor or self.room is not None or self.props is not None
                or bool(self.backgrounds))

    @property
    def is_person_only(self) -> bool:
        """Today's scene: one person and nothing else (drawn as vhgen always drew it)."""
        return not self.has_geometry and self.people == (1, 1)
