"""The ``scene:`` section of a job config (frozen; parsed by :mod:`vhgen.job_config`).

Absent section = today's scene: one person, no floor, no walls (existing configs keep
their bytes)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from vhgen.scene.clutter.kinds import CLUTTER_KINDS, KINDS
from vhgen.scene.geometry import FLOOR, PROP, SCENE_CLASSES, WALL
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


OBJECTS_CLASS = "objects"  # things on surfaces, when no entry of their kind names a class


@dataclass(frozen=True)
class ClutterConfig:
    """Clutter per frame (see :mod:`vhgen.scene.clutter`): how many items (uniform
    integer in ``count``), of which kinds (drawn with ``weights``), each kind entry's scene
    class (default: the kind's name), ``fill``: the range of the fraction of an item's
    shelves and tops covered with things, and ``variants``: how many shapes of each kind
    the job's library holds (built once per worker, then reused: see
    :func:`vhgen.scene.clutter.variant`; 0 draws a new shape for every item)."""

    count: tuple[int, int] = (8, 14)
    kinds: tuple[str, ...] = CLUTTER_KINDS
    classes: tuple[str, ...] = ()
    weights: tuple[float, ...] = ()
    fill: tuple[float, float] = (0.3, 0.9)
    variants: int = 64  # shapes per kind in the job's library (0: every item new)

    def __post_init__(self) -> None:
        if not self.classes:
            object.__setattr__(self, "classes", tuple(self.kinds))
        if not self.weights:
            object.__setattr__(self, "weights", (1.0,) * len(self.kinds))
        if len(self.classes) != len(self.kinds) or len(self.weights) != len(self.kinds):
            raise ValueError("classes / weights must match kinds")

    @property
    def objects_class(self) -> str:
        """The class of things standing on surfaces: the class of the first entry whose
        kind's record says so (``objects``) if there is one, else "objects"."""
        for k, c in zip(self.kinds, self.classes, strict=True):
            if KINDS[k].surface_things:
                return c
        return OBJECTS_CLASS

    @property
    def user_classes(self) -> tuple[str, ...]:
        """The entries' classes in order, then the objects class, without repeats (and
        without the built-in names)."""
        names = [c for c in (*self.classes, self.objects_class) if c not in SCENE_CLASSES]
        return tuple(dict.fromkeys(names))

    @property
    def no_return_classes(self) -> tuple[str, ...]:
        """Classes of kinds whose surface gives no measurement (window glass)."""
        return tuple(dict.fromkeys(c for k, c in zip(self.kinds, self.classes, strict=True)
                                   if not KINDS[k].returns))


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
    clutter: ClutterConfig | None = None

    @cached_property
    def clutter_roles(self) -> dict[str, np.ndarray]:
        """Per clutter class: the ``classes`` ids of its items' face roles (see
        :mod:`vhgen.scene.meshkit`: its own, the things on it, wall, floor), (4,) uint8."""
        if self.clutter is None:
            return {}
        obj = self.class_id(self.clutter.objects_class)
        return {c: np.array([self.class_id(c), obj, WALL, FLOOR], np.uint8)
                for c in self.clutter.classes}

    @property
    def class_names(self) -> tuple[str, ...]:
        """The names of the ``classes`` array's ids: the built-in five (background, floor,
        wall, prop, person; ids 0-4, fixed), the props' user classes, then the clutter's
        classes not named yet, then the classes of real background pixels."""
        own = self.props.user_classes if self.props is not None else ()
        if self.clutter is not None:
            own = tuple(dict.fromkeys(own + self.clutter.user_classes))
        real = tuple(b.class_name for b in self.backgrounds)
        return SCENE_CLASSES + tuple(dict.fromkeys(own + real))

    def class_id(self, name: str) -> int:
        """The ``classes`` id of a class name of this scene (``prop`` = 3)."""
        return PROP if name == "prop" else self.class_names.index(name)

    @property
    def no_return_ids(self) -> tuple[int, ...]:
        """``classes`` ids whose pixels get no measurement (window glass)."""
        if self.clutter is None:
            return ()
        return tuple(self.class_id(c) for c in self.clutter.no_return_classes)

    @property
    def has_geometry(self) -> bool:
        return (self.floor or self.room is not None or self.props is not None
                or bool(self.backgrounds) or self.clutter is not None)

    @property
    def is_person_only(self) -> bool:
        """Today's scene: one person and nothing else (drawn as vhgen always drew it)."""
        return not self.has_geometry and self.people == (1, 1)
