"""Job configuration: frozen dataclasses built from YAML at the edge.

Every field is validated with a message naming the file and the field; unknown keys are
errors. The core never handles raw dicts.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.body.shape import ShapeSampler
from vhgen.body.wardrobe import CARRIED_CLASS, OutfitConfig, parse_outfit
from vhgen.camera import CameraConfig
from vhgen.errors import ConfigError
from vhgen.mocap.clips import BUILTIN_MOTION
from vhgen.scene.clutter import CLUTTER_KINDS, NO_RETURN_KINDS
from vhgen.scene.geometry import MAX_SCENE_CLASSES, SCENE_CLASSES
from vhgen.scene.props import PARAMETRIC, load_mesh
from vhgen.scene.scene_config import (
    BEHIND_M,
    CAMERA_CLEARANCE_M,
    PERSON_CLEARANCE_M,
    BackgroundSource,
    ClutterConfig,
    PropsConfig,
    RoomConfig,
    SceneConfig,
)
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.store.zarr_store import ARRAYS, DEFAULT_ARRAYS, REQUIRED_ARRAYS
from vhgen.yamlio import check_keys, find_config, load_yaml


def _num(d: dict, key: str, src, prefix: str, *, lo=None, hi=None, integer=False,
         default=None):
    if key not in d:
        if default is None:
            raise ConfigError(src, prefix + key, "required key is missing")
        return default
    v = d[key]
    ok = isinstance(v, int) if integer else isinstance(v, (int, float))
    if isinstance(v, bool) or not ok:
        kind = "an integer" if integer else "a number"
        raise ConfigError(src, prefix + key, f"must be {kind}, got {v!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ConfigError(src, prefix + key, f"{v!r} is outside [{lo}, {hi}]")
    return int(v) if integer else float(v)


def _range(d: dict, key: str, src, prefix: str, default: tuple[float, float], *, lo=None,
           hi=None) -> tuple[float, float]:
    if key not in d:
        return default
    v = d[key]
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v, v]
    if (not isinstance(v, list) or len(v) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise ConfigError(src, prefix + key, f"must be a number or [min, max], got {d[key]!r}")
    a, b = float(v[0]), float(v[1])
    if a > b:
        raise ConfigError(src, prefix + key, f"min {a} > max {b}")
    if (lo is not None and a < lo) or (hi is not None and b > hi):
        raise ConfigError(src, prefix + key, f"[{a}, {b}] is outside [{lo}, {hi}]")
    return (a, b)


# How users mount the camera: a Kinect on top of a TV, a robot's head camera.
CAMERA_PRESETS: dict[str, dict[str, Any]] = {
    "tv_top_kinect": {"height_m": [1.0, 1.6], "pitch_deg": [5, 20], "roll_deg": [-2, 2],
                      "distance_m": [2.0, 3.5], "yaw_deg": [-45, 45]},
    "robot_head": {"height_m": [1.1, 1.6], "pitch_deg": [5, 25], "roll_deg": [-5, 5],
                   "distance_m": [1.8, 3.2], "yaw_deg": [-90, 90]},
}


@dataclass(frozen=True)
class AvatarConfig:
    """How avatars are drawn (each from its own seeded stream, see pipeline.plan).

    MakeHuman macro values are uniform in their ranges ([0, 1], age in years), the ethnic
    mix is Dirichlet(ethnic_concentration); ``scale`` multiplies the shaped body; each
    clothing helper is worn with its probability.
    """

    count: int = 2
    scale: tuple[float, float] = (1.0, 1.0)
    shape: ShapeSampler = field(default_factory=ShapeSampler)
    tights_probability: float = 0.0
    skirt_probability: float = 0.0
    outfit: OutfitConfig = field(default_factory=OutfitConfig)  # avatars.outfit (wardrobe)


@dataclass(frozen=True)
class PosesConfig:
    """Which source frames become poses (the sparsifier replaces this later)."""

    frame_step: int = 10
    max_per_motion: int = 0  # 0 = no limit
    skip_first: int = 0  # e.g. 1 drops the converter's T-pose frame of cgspeed files


@dataclass(frozen=True)
class JobConfig:
    name: str
    seed: int
    motions: tuple[str, ...]
    retarget: str
    labels: str
    sensor: SensorConfig
    assets: str | None
    poses: PosesConfig
    avatars: AvatarConfig
    camera: CameraConfig
    frames_per_shard: int
    compression_level: int | None  # output.compression_level: every array's zstd level
    backend: str
    skinning: str
    num_workers: int
    scene: SceneConfig = field(default_factory=SceneConfig)
    source: str | None = None
    overrides: dict[str, Any] = field(default_factory=dict)
    gpus_per_worker: float = 0.0  # Ray GPUs per frame actor; > 0 renders on that GPU (EGL)
    codec: str = "zstd"  # output.codec: zstd (smallest) or lz4 (fastest to read)
    arrays: tuple[str, ...] = DEFAULT_ARRAYS  # output.arrays: the arrays the store holds

    @property
    def class_names(self) -> tuple[str, ...]:
        """The names of the ``classes`` array's ids: the scene's, then ``carried`` when the
        avatars carry things that are not the person (:mod:`vhgen.body.wardrobe`)."""
        names = self.scene.class_names
        own = self.avatars.outfit.has_own_class and CARRIED_CLASS not in names
        return names + ((CARRIED_CLASS,) if own else ())

    @classmethod
    def load(cls, path: str | Path, **overrides: Any) -> JobConfig:
        """A scene config by path, or by name from the shipped ``configs/scenes``
        (``default``); ``overrides`` (num_workers, backend) replace the file's values."""
        path = find_config("scenes", path)
        d = load_yaml(path)
        top = {"name", "seed", "motions", "retarget", "labels", "sensor", "assets", "poses",
               "avatars", "camera", "output", "render", "num_workers", "description", "scene"}
        check_keys(d, top, {"name", "motions"}, path, "")
        motions = d["motions"]
        if isinstance(motions, str):
            motions = [motions]
        if not isinstance(motions, list) or not motions or \
                not all(isinstance(m, str) for m in motions):
            raise ConfigError(path, "motions", "must be a BVH path, a folder, or a list of them")
        resolved = []
        for m in motions:
            if m == BUILTIN_MOTION:
                resolved.append(m)
            else:
                p = Path(m).expanduser()
                resolved.append(str(p if p.is_absolute() else (path.parent / p).resolve()))

        po = d.get("poses") or {}
        check_keys(po, {"frame_step", "max_per_motion", "skip_first"}, set(), path, "poses.")
        poses = PosesConfig(_num(po, "frame_step", path, "poses.", lo=1, integer=True, default=10),
                            _num(po, "max_per_motion", path, "poses.", lo=0, integer=True,
                                 default=0) if "max_per_motion" in po else 0,
                            _num(po, "skip_first", path, "poses.", lo=0, integer=True,
                                 default=0) if "skip_first" in po else 0)
        av = d.get("avatars") or {}
        ad = ShapeSampler()
        check_keys(av, {"count", "scale", "gender", "age_years", "muscle", "weight", "height",
                        "proportions", "ethnic_concentration", "tights_probability",
                        "skirt_probability", "outfit"}, set(), path, "avatars.")
        unit = {k: _range(av, k, path, "avatars.", getattr(ad, k), lo=0.0, hi=1.0)
                for k in ("gender", "muscle", "weight", "height", "proportions")}
        shape = ShapeSampler(
            age_years=_range(av, "age_years", path, "avatars.", ad.age_years, lo=1, hi=90),
            ethnic_concentration=_num(av, "ethnic_concentration", path, "avatars.", lo=1e-3,
                                      default=ad.ethnic_concentration), **unit)
        avatars = AvatarConfig(
            count=_num(av, "count", path, "avatars.", lo=1, hi=100000, integer=True, default=2),
            scale=_range(av, "scale", path, "avatars.", (1.0, 1.0), lo=0.3, hi=2.0),
            shape=shape,
            tights_probability=_num(av, "tights_probability", path, "avatars.", lo=0, hi=1,
                                    default=0.0),
            skirt_probability=_num(av, "skirt_probability", path, "avatars.", lo=0, hi=1,
                                   default=0.0),
            outfit=parse_outfit(av.get("outfit"), path))
        camera = _camera(d.get("camera") or {}, path)
        scene = _scene(d.get("scene") or {}, path, camera)
        if avatars.outfit.has_own_class:  # carried things: the class after the scene's
            names = scene.class_names  # (or the props' own class of that name)
            cid = names.index(CARRIED_CLASS) if CARRIED_CLASS in names else len(names)
            if cid >= MAX_SCENE_CLASSES:
                raise ConfigError(path, "avatars.outfit.carried", f"no class id left for "
                                  f"carried things: the scene has {len(names)} classes")
            avatars = replace(avatars, outfit=avatars.outfit.with_class(cid))
        out = d.get("output") or {}
        check_keys(out, {"frames_per_shard", "compression_level", "codec", "arrays"}, set(),
                   path, "output.")
        codec = out.get("codec", "zstd")
        if codec not in ("zstd", "lz4"):
            raise ConfigError(path, "output.codec", f"must be zstd or lz4, got {codec!r}")
        ren = d.get("render") or {}
        check_keys(ren, {"backend", "skinning", "gpus_per_worker"}, set(), path, "render.")
        skinning = ren.get("skinning", "lbs")
        if skinning not in ("lbs", "dqs"):
            raise ConfigError(path, "render.skinning", f"must be lbs or dqs, got {skinning!r}")
        backend = overrides.pop("backend", None) or ren.get("backend", "egl")
        if backend not in ("egl", "osmesa"):
            raise ConfigError(path, "render.backend", f"must be egl or osmesa, got {backend!r}")
        gpus = overrides.pop("gpus_per_worker", None)
        gpus = _num(ren, "gpus_per_worker", path, "render.", lo=0, hi=64, default=0.0) \
            if gpus is None else float(gpus)
        if gpus > 0 and backend != "egl":
            raise ConfigError(path, "render.gpus_per_worker", "GPU workers render through EGL; "
                              f"render.backend is {backend!r}")
        num_workers = overrides.pop("num_workers", None) or _num(
            d, "num_workers", path, "", lo=1, hi=4096, integer=True, default=2)
        if overrides:
            raise ConfigError(path, "overrides", f"unknown overrides {sorted(overrides)}")
        # named configs come from the package, YAML paths are relative to this file;
        # checked here, so a typo fails before any work starts
        refs: dict[str, str] = {}
        for key, kind, default in (("sensor", "sensors", "kinect_v1_full"),
                                   ("labels", "labels", "shotton31"),
                                   ("retarget", "retarget", "auto")):
            ref = d.get(key, default)
            if not isinstance(ref, str) or not ref:
                raise ConfigError(path, key, f"must be a config name or a YAML path, got {ref!r}")
            if ref.endswith((".yaml", ".yml")):
                ref = str((path.parent / Path(ref).expanduser()).resolve())
                if not Path(ref).is_file():
                    kind_name = {"retarget": "map", "labels": "label scheme"}.get(key, key)
                    raise ConfigError(path, key, f"{kind_name} file {ref} does not exist")
            refs[key] = ref
            if key != "sensor" and ref != "auto":  # the sensor is loaded (and checked) below
                try:
                    find_config(kind, ref)
                except ConfigError as e:
                    raise ConfigError(path, key, str(e)) from None
        try:
            sensor = SensorConfig.load(refs["sensor"])
        except ConfigError as e:
            raise ConfigError(path, "sensor", str(e)) from None
        arrays = _arrays(out.get("arrays", list(DEFAULT_ARRAYS)), sensor, path)
        if scene.backgrounds:
            _check_background_sensor(scene, sensor, path)
        else:
            _check_camera_sees(camera, sensor.intrinsics, path)
        assets = d.get("assets")
        if assets is not None:
            assets = str((path.parent / Path(assets).expanduser()).resolve())
        return cls(
            name=str(d["name"]),
            seed=_num(d, "seed", path, "", lo=0, hi=2**63 - 1, integer=True, default=0),
            motions=tuple(resolved), retarget=refs["retarget"],
            labels=refs["labels"], sensor=sensor, assets=assets,
            poses=poses, avatars=avatars, camera=camera,
            frames_per_shard=_num(out, "frames_per_shard", path, "output.", lo=1, hi=4096,
                                  integer=True, default=16),
            compression_level=_num(out, "compression_level", path, "output.", lo=1, hi=22,
                                   integer=True) if "compression_level" in out else None,
            backend=backend, skinning=skinning, num_workers=num_workers, scene=scene,
            source=str(path), gpus_per_worker=gpus, codec=codec, arrays=arrays)


def _arrays(value: Any, sensor: SensorConfig, src) -> tuple[str, ...]:
    """``output.arrays``: the store's arrays to write, in the store's order; depth and
    labels always, ``raw`` only from a sensor that keeps raw11."""
    field_name = "output.arrays"
    if not isinstance(value, list) or not all(isinstance(a, str) for a in value):
        raise ConfigError(src, field_name, f"must be a list of array names, got {value!r}")
    unknown = [a for a in value if a not in ARRAYS]
    if unknown:
        raise ConfigError(src, field_name, f"unknown array {unknown[0]!r} (known: "
                          f"{', '.join(ARRAYS)})")
    missing = [a for a in REQUIRED_ARRAYS if a not in value]
    if missing:
        raise ConfigError(src, field_name, f"must hold {' and '.join(REQUIRED_ARRAYS)} "
                          f"(every store has them), {missing[0]!r} is missing")
    if "raw" in value and not sensor.encoding.raw11:
        raise ConfigError(src, field_name, f"raw: the sensor {sensor.name!r} keeps no raw "
                          "disparity (its encode effect has no raw11: true)")
    return tuple(a for a in ARRAYS if a in value)


def _camera(ca: dict, src) -> CameraConfig:
    cd = CameraConfig()
    check_keys(ca, {"distance_m", "height_m", "yaw_deg", "look_at_height_m", "near_m", "far_m",
                    "pitch_deg", "roll_deg", "preset"}, set(), src, "camera.")
    preset = ca.get("preset")
    if preset is not None:
        if preset not in CAMERA_PRESETS:
            raise ConfigError(src, "camera.preset", f"unknown preset {preset!r}; choose one of "
                              f"{', '.join(CAMERA_PRESETS)}")
        ca = {**CAMERA_PRESETS[preset], **{k: v for k, v in ca.items() if k != "preset"}}
    camera = CameraConfig(
        _range(ca, "distance_m", src, "camera.", cd.distance_m, lo=0.1, hi=60),
        _range(ca, "height_m", src, "camera.", cd.height_m, lo=-10, hi=10),
        _range(ca, "yaw_deg", src, "camera.", cd.yaw_deg, lo=-360, hi=360),
        _range(ca, "look_at_height_m", src, "camera.", cd.look_at_height_m, lo=-10, hi=10),
        _num(ca, "near_m", src, "camera.", lo=1e-3, default=cd.near_m),
        _num(ca, "far_m", src, "camera.", lo=0.5, default=cd.far_m),
        _range(ca, "pitch_deg", src, "camera.", (0.0, 0.0), lo=-80, hi=80)
        if "pitch_deg" in ca else None,
        _range(ca, "roll_deg", src, "camera.", cd.roll_deg, lo=-45, hi=45))
    if camera.roll_deg != (0.0, 0.0) and camera.pitch_deg is None:
        raise ConfigError(src, "camera.roll_deg", "needs pitch_deg (a mounted camera)")
    return camera


# a standing person's body centre, metres above the floor, for the visibility check
_BODY_CENTRE_M = 0.9


def _check_camera_sees(camera: CameraConfig, intr, src) -> None:
    """Load-time: some camera in the configured ranges sees the subject's body centre."""
    if camera.distance_m[0] >= camera.far_m:
        raise ConfigError(src, "camera.distance_m", f"the camera is never nearer than "
                          f"{camera.distance_m[0]} m, beyond far_m {camera.far_m} m: it can "
                          "never see a person")
    if camera.pitch_deg is None:
        return  # it looks at the subject
    half_v = np.degrees(np.arctan2(intr.height / 2, intr.fy))
    h = np.linspace(*camera.height_m, 9)[:, None, None]
    dist = np.linspace(*camera.distance_m, 9)[None, :, None]
    pitch = np.linspace(*camera.pitch_deg, 9)[None, None, :]
    below = np.degrees(np.arctan2(h - _BODY_CENTRE_M, dist))  # angle under the horizon
    if (np.abs(below - pitch) > half_v).all():
        raise ConfigError(src, "camera.pitch_deg", f"with height_m {list(camera.height_m)} "
                          f"and distance_m {list(camera.distance_m)}, no pitch in "
                          f"{list(camera.pitch_deg)} puts a person's body (0.9 m above the "
                          f"floor) in the {2 * half_v:.0f} deg vertical view: it can never "
                          "see a person")


def _int_range(d: dict, key: str, src, prefix: str, default: tuple[int, int], lo: int,
               hi: int) -> tuple[int, int]:
    a, b = _range(d, key, src, prefix, (float(default[0]), float(default[1])), lo=lo, hi=hi)
    if a != int(a) or b != int(b):
        raise ConfigError(src, prefix + key, f"must be integers, got {d[key]!r}")
    return int(a), int(b)


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
        scale = _num(m, "scale", src, field + ".", lo=1e-4, hi=1e4, default=1.0)
        mesh_classes.append(_prop_class(m, src, field + ".class"))
        path = Path(str(m["path"])).expanduser()
        if not path.is_absolute() and src is not None:
            path = Path(src).parent / path
        meshes.append(load_mesh(path, scale, src, field + ".path"))
    if not kinds and not meshes:
        raise ConfigError(src, "scene.props.kinds", "no kinds and no meshes: nothing to place")
    props = PropsConfig(_int_range(d, "count", src, "scene.props.", pd.count, 0, 64),
                        tuple(kinds), tuple(meshes),
                        _range(d, "occlusion", src, "scene.props.", pd.occlusion, lo=0, hi=1),
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
            intr = (_num(k, "fx", src, field + ".intrinsics.", lo=1.0),
                    _num(k, "fy", src, field + ".intrinsics.", lo=1.0),
                    _num(k, "cx", src, field + ".intrinsics."),
                    _num(k, "cy", src, field + ".intrinsics."))
        cls = _prop_class({"class": e.get("class", "real")}, src, field + ".class")
        out.append(BackgroundSource(str(p.resolve()), intr, cls))
    return tuple(out)


def _check_background_sensor(scene: SceneConfig, sensor: SensorConfig, src) -> None:
    """Load-time: a sensor that can run over real backgrounds, and intrinsics given for
    PNG backgrounds that are the sensor's (see ``vhgen.scene.background``)."""
    from vhgen.scene.background import intrinsics_mismatch

    if "projector_depth" in sensor.needs:
        raise ConfigError(src, "scene.backgrounds", f"sensor {sensor.name} needs a "
                          "projector-view depth image (projector_shadow: {method: exact} "
                          "or structured_light), which a real depth frame does not have: "
                          "use projector_shadow: {method: screen_space}")
    for i, b in enumerate(scene.backgrounds):
        if b.intrinsics is not None:
            bad = intrinsics_mismatch(b.intrinsics, sensor.intrinsics)
            if bad:
                raise ConfigError(src, f"scene.backgrounds[{i}].intrinsics", bad)


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
                          f"{', '.join(CLUTTER_KINDS)} (or {{kind, class, weight}} "
                          f"mappings), got {kinds_in!r}")
    kinds, classes, weights = [], [], []
    for i, k in enumerate(kinds_in):
        field = f"scene.clutter.kinds[{i}]"
        cls, weight = None, 1.0
        if isinstance(k, dict):
            check_keys(k, {"kind", "class", "weight"}, {"kind"}, src, field + ".")
            if "class" in k:
                cls = _prop_class(k, src, field + ".class")
            weight = _num(k, "weight", src, field + ".", lo=0.0, hi=1e6, default=1.0)
            if weight <= 0:
                raise ConfigError(src, field + ".weight", f"must be > 0, got {weight}")
            field, k = field + ".kind", k["kind"]
        if k not in CLUTTER_KINDS:
            raise ConfigError(src, field, f"must be one of {', '.join(CLUTTER_KINDS)}, "
                              f"got {k!r}")
        kinds.append(k)
        classes.append(cls or k)
        weights.append(weight)
    cfg = ClutterConfig(_int_range(d, "count", src, "scene.clutter.", cd.count, 0, 200),
                        tuple(kinds), tuple(classes), tuple(weights),
                        _range(d, "fill", src, "scene.clutter.", cd.fill, lo=0.0, hi=1.0),
                        _num(d, "variants", src, "scene.clutter.", lo=0, hi=100000,
                             integer=True, default=cd.variants))
    # window glass gives no return: its class must be the glass's alone
    others = [(f"scene.clutter.kinds[{i}]", c)
              for i, (k, c) in enumerate(zip(kinds, classes, strict=True))
              if k not in NO_RETURN_KINDS]
    others.append(("the things on surfaces", cfg.objects_class))
    if props is not None:
        others += [("scene.props", c) for c in props.kind_classes + props.mesh_classes]
    for i, (k, c) in enumerate(zip(kinds, classes, strict=True)):
        if k in NO_RETURN_KINDS:
            clash = next((who for who, o in others if o == c), None)
            if clash is not None or c == "prop":
                raise ConfigError(src, f"scene.clutter.kinds[{i}].class", f"windows give no "
                                  f"return (their glass has no measurement), so their class "
                                  f"{c!r} cannot also be that of {clash or 'props'}: give "
                                  f"windows a class of their own")
    return cfg


def _check_clutter_fits(cfg: ClutterConfig, room: RoomConfig, people: tuple[int, int],
                        props: PropsConfig | None, src) -> None:
    """Clutter that can never fit is a load-time error: a kind larger than the largest
    room (along a wall, or higher than its walls), or more items at the least than the
    floor the camera sees can hold."""
    from vhgen.scene.clutter import PIERCES_CEILING, smallest

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
        if k not in PIERCES_CEILING and shape.top > room.height_m[1]:
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


def _scene(d: dict, src, camera: CameraConfig) -> SceneConfig:
    """The ``scene:`` section; checks at load time that a room can hold the people, the
    props and the camera at its farthest distance."""
    check_keys(d, {"floor", "room", "people", "props", "min_visible_fraction",
                   "backgrounds", "clutter"}, set(), src, "scene.")
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
    people = _int_range(d, "people", src, "scene.", (1, 1), 1, 32)
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
            _range(r, "width_m", src, "scene.room.", rd.width_m, lo=0.5, hi=100),
            _range(r, "depth_m", src, "scene.room.", rd.depth_m, lo=0.5, hi=100),
            _range(r, "height_m", src, "scene.room.", rd.height_m, lo=1.0, hi=20),
            _range(r, "yaw_deg", src, "scene.room.", rd.yaw_deg, lo=-90, hi=90))
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
    scene = SceneConfig(floor=floor, room=room, people=people, props=props,
                        min_visible_fraction=_num(d, "min_visible_fraction", src, "scene.",
                                                  lo=0.0, hi=1.0, default=0.5),
                        backgrounds=backgrounds, clutter=clutter)
    room_for = MAX_SCENE_CLASSES - len(SCENE_CLASSES)
    if len(scene.class_names) - len(SCENE_CLASSES) > room_for:
        raise ConfigError(src, "scene.backgrounds" if backgrounds else "scene.clutter",
                          f"{len(scene.class_names) - len(SCENE_CLASSES)} user classes; the "
                          f"uint8 classes array holds {room_for} besides the built-in "
                          f"{len(SCENE_CLASSES)}")
    return scene
