"""The ``scene:`` section of a job config: its frozen dataclasses and their parser,
:func:`parse_scene` (the room, the people, props, clutter and real backgrounds, each field
checked with a message naming the file and the field; :mod:`vhgen.job_config` composes
the sections).

Absent section = today's scene: one person, no floor, no walls (existing configs keep
their bytes)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.camera import CameraConfig
from vhgen.errors import ConfigError
from vhgen.scene.clutter.kinds import CLUTTER_KINDS, KINDS
from vhgen.scene.geometry import FLOOR, MAX_SCENE_CLASSES, PROP, SCENE_CLASSES, WALL
from vhgen.scene.props import PARAMETRIC, PropShape, load_mesh
from vhgen.yamlio import check_keys, int_range, number, number_range

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
class LineupConfig:
    """People standing side by side, as a group stands for a photo or a talk: in a share
    of the frames (``share``), every further person stands beside the line's left or
    right end, ``gap_m`` from its neighbour's footprint, moved up to ``depth_m`` towards
    or away from the camera, turned to face the camera within ``facing_deg``; the line
    runs across the view, turned by up to ``tilt_deg``. A person with no room at either
    end is placed as without a line (anywhere in view)."""

    share: float = 1.0
    gap_m: tuple[float, float] = (0.0, 0.25)
    depth_m: float = 0.3
    facing_deg: float = 30.0
    tilt_deg: float = 15.0


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
    # this many consecutive frames share one camera, room, props and clutter (a sensor
    # standing in a furnished room while people come and go; see
    # vhgen.scene.layout.layout_shared); 1: every frame lays out its own
    layout_frames: int = 1
    # people side by side in a share of the frames (None: never; see LineupConfig)
    lineup: LineupConfig | None = None

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


# -- parsing the ``scene:`` section ------------------------------------------------------
# a class name: starts with a letter, then letters, digits, _ or - (it names a class in
# the store's attributes and in tools' legends)
_CLASS_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,63}")


def _prop_class(d: dict, src, field: str) -> str:
    """The optional ``class`` of a prop entry ("prop" when absent)."""
    name = d.get("class", "prop")
    if not isinstance(name, str) or not _CLASS_NAME.fullmatch(name):
        raise ConfigError(src, field, f"must be a name (a letter, then letters, digits, _ "
                          f"or -; at most 64), got {name!r}")
    if name in SCENE_CLASSES and name != "prop":
        raise ConfigError(src, field, f"{name!r} is a built-in scene class "
                          f"({', '.join(SCENE_CLASSES)}); give props a name of their own")
    return name


def _props(d: Any, src) -> PropsConfig:
    if d is True:
        d = {}
    check_keys(d, {"count", "kinds", "meshes", "occlusion"}, set(), src, "scene.props.")
    pd = PropsConfig()
    kinds_in = d.get("kinds", list(pd.kinds))
    if not isinstance(kinds_in, list):
        raise ConfigError(src, "scene.props.kinds", f"must be a list of {', '.join(PARAMETRIC)}"
                          f" (or {{kind, class}} mappings), got {kinds_in!r}")
    kinds, kind_classes = [], []
    for i, k in enumerate(kinds_in):
        field = f"scene.props.kinds[{i}]"
        if isinstance(k, dict):
            check_keys(k, {"kind", "class"}, {"kind"}, src, field + ".")
            kind_classes.append(_prop_class(k, src, field + ".class"))
            field, k = field + ".kind", k["kind"]
        else:
            kind_classes.append("prop")
        if k not in PARAMETRIC:
            raise ConfigError(src, field, f"must be one of {', '.join(PARAMETRIC)}, got {k!r}")
        kinds.append(k)
    meshes, mesh_classes = [], []
    for i, m in enumerate(d.get("meshes") or []):
        field = f"scene.props.meshes[{i}]"
        if isinstance(m, str):
            m = {"path": m}
        if not isinstance(m, dict):
            raise ConfigError(src, field, f"must be a path or {{path, scale, class}}, got {m!r}")
        check_keys(m, {"path", "scale", "class"}, {"path"}, src, field + ".")
        scale = number(m, "scale", src, field + ".", lo=1e-4, hi=1e4, default=1.0)
        mesh_classes.append(_prop_class(m, src, field + ".class"))
        path = Path(str(m["path"])).expanduser()
        if not path.is_absolute() and src is not None:
            path = Path(src).parent / path
        meshes.append(load_mesh(path, scale, src, field + ".path"))
    if not kinds and not meshes:
        raise ConfigError(src, "scene.props.kinds", "no kinds and no meshes: nothing to place")
    props = PropsConfig(int_range(d, "count", src, "scene.props.", pd.count, 0, 64),
                        tuple(kinds), tuple(meshes),
                        number_range(d, "occlusion", src, "scene.props.", pd.occlusion, lo=0, hi=1),
                        tuple(kind_classes), tuple(mesh_classes))
    room = MAX_SCENE_CLASSES - len(SCENE_CLASSES)
    if len(props.user_classes) > room:
        raise ConfigError(src, "scene.props", f"{len(props.user_classes)} user classes; "
                          f"the uint8 classes array holds {room} besides the built-in "
                          f"{len(SCENE_CLASSES)}")
    return props


def _backgrounds(v: Any, src) -> tuple[BackgroundSource, ...]:
    """``scene.backgrounds``: files or folders of real depth frames, each a path or
    ``{path, intrinsics: {fx, fy, cx, cy}, class}``. Paths are relative to the config file
    and must exist (the frames themselves are read by ``prepare_job``)."""
    if isinstance(v, (str, dict)):
        v = [v]
    if not isinstance(v, list) or not v:
        raise ConfigError(src, "scene.backgrounds", "must be a file or folder of real depth "
                          f"frames (PCD, 16-bit PNG), or a list of them, got {v!r}")
    out = []
    for i, e in enumerate(v):
        field = f"scene.backgrounds[{i}]"
        if isinstance(e, str):
            e = {"path": e}
        if not isinstance(e, dict):
            raise ConfigError(src, field, f"must be a path or {{path, intrinsics, class}}, "
                              f"got {e!r}")
        check_keys(e, {"path", "intrinsics", "class"}, {"path"}, src, field + ".")
        if not isinstance(e["path"], str) or not e["path"]:
            raise ConfigError(src, field + ".path", f"must be a path, got {e['path']!r}")
        p = Path(e["path"]).expanduser()
        if not p.is_absolute() and src is not None:
            p = Path(src).parent / p
        if not p.exists():
            raise ConfigError(src, field + ".path", f"no such file or folder: {p}")
        intr = None
        if "intrinsics" in e:
            k = e["intrinsics"]
            check_keys(k, {"fx", "fy", "cx", "cy"}, {"fx", "fy", "cx", "cy"}, src,
                       field + ".intrinsics.")
            intr = (number(k, "fx", src, field + ".intrinsics.", lo=1.0),
                    number(k, "fy", src, field + ".intrinsics.", lo=1.0),
                    number(k, "cx", src, field + ".intrinsics."),
                    number(k, "cy", src, field + ".intrinsics."))
        cls = _prop_class({"class": e.get("class", "real")}, src, field + ".class")
        out.append(BackgroundSource(str(p.resolve()), intr, cls))
    return tuple(out)


def _clutter(d: Any, src, props: PropsConfig | None) -> ClutterConfig:
    """The ``scene.clutter`` section: count, kinds (names or {kind, class, weight}), fill,
    variants."""
    if d is True:
        d = {}
    check_keys(d, {"count", "kinds", "fill", "variants"}, set(), src, "scene.clutter.")
    cd = ClutterConfig()
    kinds_in = d.get("kinds", list(cd.kinds))
    if not isinstance(kinds_in, list) or not kinds_in:
        raise ConfigError(src, "scene.clutter.kinds", f"must be a non-empty list of "
                          f"{', '.join(KINDS)} (or {{kind, class, weight}} "
                          f"mappings), got {kinds_in!r}")
    kinds, classes, weights = [], [], []
    for i, k in enumerate(kinds_in):
        field = f"scene.clutter.kinds[{i}]"
        cls, weight = None, 1.0
        if isinstance(k, dict):
            check_keys(k, {"kind", "class", "weight"}, {"kind"}, src, field + ".")
            if "class" in k:
                cls = _prop_class(k, src, field + ".class")
            weight = number(k, "weight", src, field + ".", lo=0.0, hi=1e6, default=1.0)
            if weight <= 0:
                raise ConfigError(src, field + ".weight", f"must be > 0, got {weight}")
            field, k = field + ".kind", k["kind"]
        if k not in KINDS:
            raise ConfigError(src, field, f"must be one of {', '.join(KINDS)}, "
                              f"got {k!r}")
        kinds.append(k)
        classes.append(cls or k)
        weights.append(weight)
    cfg = ClutterConfig(int_range(d, "count", src, "scene.clutter.", cd.count, 0, 200),
                        tuple(kinds), tuple(classes), tuple(weights),
                        number_range(d, "fill", src, "scene.clutter.", cd.fill, lo=0.0, hi=1.0),
                        number(d, "variants", src, "scene.clutter.", lo=0, hi=100000,
                             integer=True, default=cd.variants))
    # window glass gives no return: its class must be the glass's alone
    others = [(f"scene.clutter.kinds[{i}]", c)
              for i, (k, c) in enumerate(zip(kinds, classes, strict=True))
              if KINDS[k].returns]
    others.append(("the things on surfaces", cfg.objects_class))
    if props is not None:
        others += [("scene.props", c) for c in props.kind_classes + props.mesh_classes]
    for i, (k, c) in enumerate(zip(kinds, classes, strict=True)):
        if not KINDS[k].returns:
            clash = next((who for who, o in others if o == c), None)
            if clash is not None or c == "prop":
                raise ConfigError(src, f"scene.clutter.kinds[{i}].class", f"{k} items give "
                                  f"no return (their surface has no measurement), so "
                                  f"their class {c!r} cannot also be that of "
                                  f"{clash or 'props'}: give {k} items a class of their own")
    return cfg


def _check_clutter_fits(cfg: ClutterConfig, room: RoomConfig, people: tuple[int, int],
                        props: PropsConfig | None, src) -> None:
    """Clutter that can never fit is a load-time error: a kind larger than the largest
    room (along a wall, or higher than its walls), or more items at the least than the
    floor the camera sees can hold."""
    from vhgen.scene.clutter.items import smallest

    side = max(room.width_m[1], room.depth_m[1])
    need = 0.0
    weights = np.array(cfg.weights) / sum(cfg.weights)
    for i, (k, w) in enumerate(zip(cfg.kinds, weights, strict=True)):
        shape = smallest(k)
        x0, x1 = shape.x_extent
        if x1 - x0 > side - 0.05:
            raise ConfigError(src, f"scene.clutter.kinds[{i}]", f"{k} needs a wall of at "
                              f"least {x1 - x0 + 0.05:.2f} m; scene.room allows at most "
                              f"{side} m")
        if not KINDS[k].pierces_ceiling and shape.top > room.height_m[1]:
            raise ConfigError(src, f"scene.clutter.kinds[{i}]", f"{k} is at least "
                              f"{shape.top:.2f} m high; scene.room.height_m allows at most "
                              f"{room.height_m[1]} m")
        # floor taken by what stands on it (things on the walls take none)
        need += w * sum(float(np.prod(q.max(0) - q.min(0))) for q, y0, _, inside
                        in shape.solids if inside and y0 < 0.5)
    # items stand where the camera sees them, about a third of the largest room's floor,
    # shared with the people and props; each item with as much again around it. The
    # fewest items asked for must fit there (more may be left out and counted)
    area = room.width_m[1] * room.depth_m[1] / 3
    n_props = props.count[0] if props is not None else 0
    taken = np.pi * (people[0] * PERSON_CLEARANCE_M ** 2 + n_props * 0.6 ** 2)
    if 2 * cfg.count[0] * need > area - taken:
        raise ConfigError(src, "scene.clutter.count", f"at least {cfg.count[0]} items of "
                          f"these kinds need about {2 * cfg.count[0] * need:.1f} m^2 of floor; "
                          f"the largest room's floor in view offers about "
                          f"{max(area - taken, 0):.1f} m^2 besides the people and props: "
                          f"lower the count or enlarge scene.room")


def _lineup(d: Any, src) -> LineupConfig:
    """``scene.lineup``: true (the defaults) or a mapping of :class:`LineupConfig`'s
    fields."""
    if d is True:
        d = {}
    if not isinstance(d, dict):
        raise ConfigError(src, "scene.lineup", f"must be a mapping (or true/false), got {d!r}")
    check_keys(d, {"share", "gap_m", "depth_m", "facing_deg", "tilt_deg"}, set(), src,
               "scene.lineup.")
    df = LineupConfig()
    p = "scene.lineup."
    return LineupConfig(
        share=number(d, "share", src, p, lo=0.0, hi=1.0, default=df.share),
        gap_m=number_range(d, "gap_m", src, p, df.gap_m, lo=0.0, hi=2.0),
        depth_m=number(d, "depth_m", src, p, lo=0.0, hi=2.0, default=df.depth_m),
        facing_deg=number(d, "facing_deg", src, p, lo=0.0, hi=180.0, default=df.facing_deg),
        tilt_deg=number(d, "tilt_deg", src, p, lo=0.0, hi=60.0, default=df.tilt_deg))


def parse_scene(d: dict, src, camera: CameraConfig) -> SceneConfig:
    """The ``scene:`` section; checks at load time that a room can hold the people, the
    props and the camera at its farthest distance."""
    check_keys(d, {"floor", "room", "people", "props", "min_visible_fraction",
                   "backgrounds", "clutter", "layout_frames", "lineup"}, set(), src,
               "scene.")
    floor = d.get("floor", False)
    if not isinstance(floor, bool):
        raise ConfigError(src, "scene.floor", f"must be true or false, got {floor!r}")
    backgrounds: tuple[BackgroundSource, ...] = ()
    if d.get("backgrounds") is not None:
        backgrounds = _backgrounds(d["backgrounds"], src)
        # the real frame is the room: its floor holds the people, nothing synthetic is
        # drawn around them
        for key in ("room", "props", "clutter"):
            if d.get(key) not in (None, False):
                raise ConfigError(src, "scene.backgrounds", f"a real background is the "
                                  f"room: it cannot be combined with scene.{key}")
        if d.get("floor") is False:
            raise ConfigError(src, "scene.floor", "people stand on the floor of the real "
                              "backgrounds (scene.backgrounds): it cannot be false")
        floor = True
    people = int_range(d, "people", src, "scene.", (1, 1), 1, 32)
    props = None
    if d.get("props") not in (None, False):
        props = _props(d["props"], src)
    room = None
    r = d.get("room")
    if r is not None and r is not False:
        if r is True:
            r = {}
        if not isinstance(r, dict):
            raise ConfigError(src, "scene.room", f"must be a mapping (or false), got {r!r}")
        rd = RoomConfig()
        check_keys(r, {"width_m", "depth_m", "height_m", "yaw_deg"}, set(), src, "scene.room.")
        room = RoomConfig(
            number_range(r, "width_m", src, "scene.room.", rd.width_m, lo=0.5, hi=100),
            number_range(r, "depth_m", src, "scene.room.", rd.depth_m, lo=0.5, hi=100),
            number_range(r, "height_m", src, "scene.room.", rd.height_m, lo=1.0, hi=20),
            number_range(r, "yaw_deg", src, "scene.room.", rd.yaw_deg, lo=-90, hi=90))
        need_w = 2 * PERSON_CLEARANCE_M
        need_d = (camera.distance_m[1] + PERSON_CLEARANCE_M + CAMERA_CLEARANCE_M
                  + (BEHIND_M if people[1] > 1 else 0.0))
        if room.width_m[1] < need_w:
            raise ConfigError(src, "scene.room.width_m", f"room too small: at most "
                              f"{room.width_m[1]} m wide, a person needs {need_w:.1f} m")
        if room.depth_m[1] < need_d:
            raise ConfigError(src, "scene.room.depth_m", f"room too small: at most "
                              f"{room.depth_m[1]} m deep, but camera.distance_m reaches "
                              f"{camera.distance_m[1]} m (needs {need_d:.1f} m with clearances)")
        # footprints asked for must fit in half the largest room's floor, or most frames
        # would drop people or props
        n_props = props.count[1] if props is not None else 0
        need_area = np.pi * (people[1] * PERSON_CLEARANCE_M ** 2 + n_props * 0.6 ** 2)
        area = room.width_m[1] * room.depth_m[1]
        if area < 2 * need_area:
            raise ConfigError(src, "scene.room", f"room too small for {people[1]} people and "
                              f"{n_props} props: at most {area:.1f} m^2 of floor, they need "
                              f"about {2 * need_area:.1f} m^2")
    clutter = None
    if d.get("clutter") not in (None, False):
        clutter = _clutter(d["clutter"], src, props)
        if room is None or not floor:
            raise ConfigError(src, "scene.clutter", "clutter stands on the floor and against "
                              "walls: it needs scene.floor: true and a scene.room")
        _check_clutter_fits(clutter, room, people, props, src)
    layout_frames = number(d, "layout_frames", src, "scene.", lo=1, hi=1_000_000,
                           integer=True, default=1)
    if layout_frames > 1 and (backgrounds or (room is None and props is None)):
        raise ConfigError(src, "scene.layout_frames", "frames share a room, props and "
                          "clutter: it needs scene.room or scene.props, and no "
                          "scene.backgrounds (a real background is already shared)")
    lineup = None
    if d.get("lineup") not in (None, False):
        lineup = _lineup(d["lineup"], src)
        why = ("scene.people must allow more than one person" if people[1] < 2 else
               "real backgrounds place their people themselves" if backgrounds else
               "frames that share a layout keep places, not lines (layout_frames: 1)"
               if layout_frames > 1 else "")
        if why:
            raise ConfigError(src, "scene.lineup", f"people side by side: {why}")
    scene = SceneConfig(floor=floor, room=room, people=people, props=props,
                        min_visible_fraction=number(d, "min_visible_fraction", src, "scene.",
                                                  lo=0.0, hi=1.0, default=0.5),
                        backgrounds=backgrounds, clutter=clutter,
                        layout_frames=int(layout_frames), lineup=lineup)
    room_for = MAX_SCENE_CLASSES - len(SCENE_CLASSES)
    if len(scene.class_names) - len(SCENE_CLASSES) > room_for:
        raise ConfigError(src, "scene.backgrounds" if backgrounds else "scene.clutter",
                          f"{len(scene.class_names) - len(SCENE_CLASSES)} user classes; the "
                          f"uint8 classes array holds {room_for} besides the built-in "
                          f"{len(SCENE_CLASSES)}")
    return scene
