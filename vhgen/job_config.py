"""Job configuration: frozen dataclasses built from YAML at the edge.

Every field is validated with a message naming the file and the field; unknown keys are
errors. The core never handles raw dicts. Each section is parsed by the package that owns
it (``scene:`` by :func:`vhgen.scene.scene_config.parse_scene`, ``avatars.outfit`` by
:func:`vhgen.body.wardrobe.parse_outfit`, the sensor by
:meth:`vhgen.sensor.sensor_config.SensorConfig.load`), with the checks they share in
:mod:`vhgen.yamlio`; this module composes them and checks what spans sections (a camera
that sees a person, a sensor that can run over real backgrounds).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.body.shape import ShapeSampler
from vhgen.body.wardrobe import CARRIED_CLASS, OutfitConfig, parse_outfit
from vhgen.camera import CameraConfig
from vhgen.errors import ConfigError
from vhgen.mocap.clips import BUILTIN_MOTION
from vhgen.scene.geometry import MAX_SCENE_CLASSES
from vhgen.scene.scene_config import SceneConfig, parse_scene
from vhgen.sensor.sensor_config import SensorConfig, sensor_section
from vhgen.store.zarr_store import ARRAYS, DEFAULT_ARRAYS, REQUIRED_ARRAYS
from vhgen.yamlio import check_keys, find_config, load_yaml, probability
from vhgen.yamlio import number as _num
from vhgen.yamlio import number_range as _range

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
    bend_share: float = 0.0  # poses.bend.share: the share of poses bent forward at the hips
    bend_degrees: tuple[float, float] = (30.0, 100.0)  # poses.bend.degrees: how far


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
    palette: bool = True  # output.palette: uint16 arrays through vhgen.palette (default: with zstd)
    arrays: tuple[str, ...] = DEFAULT_ARRAYS  # output.arrays: the arrays the store holds
    # render.batch_frames: with sensor.backend gl, the frames a worker draws and senses
    # before it reads any back (two batches in flight); 0: each frame read back before
    # the next is drawn. The frames are the same either way
    batch_frames: int = 4

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
        check_keys(po, {"frame_step", "max_per_motion", "skip_first", "bend"}, set(), path,
                   "poses.")
        bend = po.get("bend") or {}
        if not isinstance(bend, dict):
            raise ConfigError(path, "poses.bend", f"must be a mapping (share, degrees), got "
                              f"{bend!r}")
        check_keys(bend, {"share", "degrees"}, set(), path, "poses.bend.")
        poses = PosesConfig(_num(po, "frame_step", path, "poses.", lo=1, integer=True, default=10),
                            _num(po, "max_per_motion", path, "poses.", lo=0, integer=True,
                                 default=0) if "max_per_motion" in po else 0,
                            _num(po, "skip_first", path, "poses.", lo=0, integer=True,
                                 default=0) if "skip_first" in po else 0,
                            probability(bend.get("share", 0.0), path, "poses.bend.share"),
                            _range(bend, "degrees", path, "poses.bend.",
                                   PosesConfig.bend_degrees, lo=0, hi=120))
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
        scene = parse_scene(d.get("scene") or {}, path, camera)
        if avatars.outfit.has_own_class:  # carried things: the class after the scene's
            names = scene.class_names  # (or the props' own class of that name)
            cid = names.index(CARRIED_CLASS) if CARRIED_CLASS in names else len(names)
            if cid >= MAX_SCENE_CLASSES:
                raise ConfigError(path, "avatars.outfit.carried", f"no class id left for "
                                  f"carried things: the scene has {len(names)} classes")
            avatars = replace(avatars, outfit=avatars.outfit.with_class(cid))
        out = d.get("output") or {}
        check_keys(out, {"frames_per_shard", "compression_level", "codec", "arrays",
                         "palette"}, set(), path, "output.")
        codec = out.get("codec", "zstd")
        if codec not in ("zstd", "lz4"):
            raise ConfigError(path, "output.codec", f"must be zstd or lz4, got {codec!r}")
        palette = out.get("palette", codec == "zstd")
        if not isinstance(palette, bool):
            raise ConfigError(path, "output.palette", f"must be true or false, got {palette!r}")
        ren = d.get("render") or {}
        check_keys(ren, {"backend", "skinning", "gpus_per_worker", "batch_frames"}, set(),
                   path, "render.")
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
        sensor_ref, sensor_backend = sensor_section(d.get("sensor", "kinect_v1_full"), path)
        for key, kind, default in (("sensor", "sensors", "kinect_v1_full"),
                                   ("labels", "labels", "shotton31"),
                                   ("retarget", "retarget", "auto")):
            ref = sensor_ref if key == "sensor" else d.get(key, default)
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
            if sensor_backend is not None:
                sensor = sensor.with_backend(sensor_backend)
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
            source=str(path), gpus_per_worker=gpus, codec=codec, arrays=arrays,
            palette=palette,
            batch_frames=_num(ren, "batch_frames", path, "render.", lo=0, hi=64, integer=True,
                              default=4))


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


def _check_background_sensor(scene: SceneConfig, sensor: SensorConfig, src) -> None:
    """Load-time: a sensor that can run over real backgrounds, and intrinsics given for
    PNG backgrounds that are the sensor's (see ``vhgen.scene.background``)."""
    from vhgen.scene.background.load import intrinsics_mismatch

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


