"""Which frames a forest trains or is evaluated on: store checks and frame selection.

Stores are read through :mod:`vhgen.store` (the one reader of vhgen stores). Frames are
addressed globally: the stores in the order given, frames in store order, ``global id``
counting across stores. Everything seeded derives from global ids, so the same stores
and seed select and sample the same pixels on any number of workers.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.camera import Intrinsics
from vhgen.errors import ForestError, StoreError
from vhgen.scene.geometry import PERSON
from vhgen.store.zarr_store import open_store, read_attrs
from vhgen.store.zarr_store import read_frames as read_store_frames


@dataclass(frozen=True)
class StoreInfo:
    """One dataset store as the forest sees it."""

    path: str
    num_frames: int
    label_scheme: str
    label_names: tuple[str, ...]
    fx: float
    fy: float
    sensor: str
    frames_per_shard: int
    label_colors: tuple[tuple[int, int, int], ...] | None = None
    width: int = 0
    height: int = 0
    cx: float | None = None  # None: the image centre
    cy: float | None = None
    has_instances: bool = False  # an ``instances`` array (person k = value k)
    has_classes: bool = False  # a ``classes`` array (vhgen.scene.geometry.SCENE_CLASSES)

    @property
    def intrinsics(self) -> Intrinsics:
        """The frames' pinhole camera (the principal point at the centre if not recorded)."""
        return Intrinsics(self.width, self.height, self.fx, self.fy,
                          (self.width - 1) / 2 if self.cx is None else self.cx,
                          (self.height - 1) / 2 if self.cy is None else self.cy)


def store_info(path: str | Path) -> StoreInfo:
    """Check that ``path`` is a vhgen store with depth and labels; one-line ForestError if not."""
    p = Path(path)
    if not p.exists():
        raise ForestError(f"{p}: no such store")
    if not (p / "zarr.json").is_file():
        raise ForestError(f"{p}: not a Zarr v3 group (no zarr.json); expected a store written "
                          "by `vhgen generate`")
    for name in ("depth", "labels"):
        if not (p / name / "zarr.json").is_file():
            raise ForestError(f"{p}: store has no `{name}` array; the forest needs depth and "
                              "per-pixel labels")
    try:
        g = open_store(p)
        attrs = read_attrs(p)
    except StoreError as e:
        raise ForestError(str(e)) from None
    names = attrs.get("label_names")
    if not names:
        raise ForestError(f"{p}: store has no `label_names` attribute")
    sensor = attrs.get("sensor") or {}
    intr = sensor.get("intrinsics") or {}
    if "fx" not in intr:
        raise ForestError(f"{p}: store attribute sensor.intrinsics has no fx")
    depth: Any = g["depth"]
    labels: Any = g["labels"]
    if depth.shape != labels.shape or depth.ndim != 3:
        raise ForestError(f"{p}: depth {depth.shape} and labels {labels.shape} differ")
    colors = attrs.get("label_colors")
    has_instances = (p / "instances" / "zarr.json").is_file()
    if has_instances and g["instances"].shape != depth.shape:
        raise ForestError(f"{p}: instances {g['instances'].shape} and depth {depth.shape} "
                          "differ")
    has_classes = (p / "classes" / "zarr.json").is_file() and \
        g["classes"].shape == depth.shape
    return StoreInfo(str(p), int(depth.shape[0]), str(attrs.get("label_scheme", "")),
                     tuple(names), float(intr["fx"]), float(intr.get("fy", intr["fx"])),
                     str(sensor.get("name", "")),
                     int(depth.shards[0] if depth.shards else depth.chunks[0]),
                     tuple(tuple(c) for c in colors) if colors else None,
                     int(depth.shape[2]), int(depth.shape[1]),
                     float(intr["cx"]) if "cx" in intr else None,
                     float(intr["cy"]) if "cy" in intr else None, has_instances, has_classes)


def check_compatible(infos: list[StoreInfo], what: str = "training") -> StoreInfo:
    """All stores share label scheme, names and focal length; returns the first."""
    if not infos:
        raise ForestError(f"no {what} store given")
    ref = infos[0]
    for s in infos[1:]:
        if s.label_names != ref.label_names or s.label_scheme != ref.label_scheme:
            raise ForestError(f"{s.path}: label scheme {s.label_scheme!r} "
                              f"({len(s.label_names)} parts) differs from {ref.path}'s "
                              f"{ref.label_scheme!r} ({len(ref.label_names)} parts)")
        if abs(s.fx - ref.fx) > 1e-6 or abs(s.fy - ref.fy) > 1e-6:
            raise ForestError(f"{s.path}: focal length fx={s.fx} differs from {ref.path}'s "
                              f"fx={ref.fx}; pixel offsets only transfer at one focal length")
    return ref


def select_frames(infos: list[StoreInfo], max_frames: int | None,
                  seed: int) -> list[tuple[str, int, int]]:
    """(store path, frame, global id) of the frames used, in global-id order.

    ``max_frames``: a seeded random subset of that size (nested: a smaller size with the same
    seed is a subset of a larger one), else every frame.
    """
    table = [(s.path, f) for s in infos for f in range(s.num_frames)]
    ids = np.arange(len(table))
    if max_frames is not None and max_frames < len(table):
        perm = np.random.default_rng(np.random.SeedSequence([seed, 0x5E1EC7])).permutation(
            len(table))
        ids = np.sort(perm[:max_frames])
    return [(table[i][0], table[i][1], int(i)) for i in ids]


def read_frames(frames: list[tuple[str, int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Depth (N, H, W) uint16 mm and labels (N, H, W) uint8 of the selected frames, in
    the order given (one contiguous read per shard touched)."""
    by_store: dict[str, list[int]] = {}
    for path, f, _ in frames:
        by_store.setdefault(path, []).append(f)
    depth_parts, label_parts = [], []
    for path, fs in by_store.items():
        root = open_store(path)
        fps = store_info(path).frames_per_shard
        got = read_store_frames(root, ("depth", "labels"), np.asarray(fs, np.int64), fps)
        depth_parts.append(got["depth"])
        label_parts.append(got["labels"])
    if not depth_parts:
        return np.zeros((0, 0, 0), np.uint16), np.zeros((0, 0, 0), np.uint8)
    return (np.concatenate(depth_parts).astype(np.uint16, copy=False),
            np.concatenate(label_parts).astype(np.uint8, copy=False))


def read_classes(frames: list[tuple[str, int, int]], shape: tuple[int, ...]) -> np.ndarray:
    """Scene classes (N, H, W) uint8 of the selected frames (ids of
    :data:`vhgen.scene.geometry.SCENE_CLASSES`); 0 (background) for the frames of a store
    without a ``classes`` array. ``shape``: (N, H, W)."""
    out = np.zeros(shape, np.uint8)
    _read_optional(frames, "classes", out)
    return out


def _read_optional(frames: list[tuple[str, int, int]], name: str, out: np.ndarray
                   ) -> np.ndarray:
    """Fill ``out`` (N, H, W) with the optional array ``name`` (``instances`` or
    ``classes``) of the selected frames whose store has it; returns (N,) bool: which."""
    has = np.zeros(len(frames), bool)
    by_store: dict[str, list[int]] = {}
    for i, (path, _, _) in enumerate(frames):
        by_store.setdefault(path, []).append(i)
    for path, idx in by_store.items():
        info = store_info(path)
        if not (info.has_instances if name == "instances" else info.has_classes):
            continue
        fs = np.asarray([frames[i][1] for i in idx], np.int64)
        out[idx] = read_store_frames(open_store(path), (name,), fs,
                                     info.frames_per_shard)[name]
        has[idx] = True
    return has


def cut_out_view(depth_mm: np.ndarray, truth: np.ndarray, classes: np.ndarray
                 ) -> np.ndarray:
    """A frame as a pipeline that removed its background leaves it: only its people
    (``truth`` > 0, or scene class person: clothes, hair) measured, everything else read
    as no measurement. Returns the depth of the view (the truth is the frame's)."""
    keep = (truth > 0) | (classes == PERSON)
    return np.where(keep, depth_mm, 0).astype(depth_mm.dtype)


def zoom_view(depth_mm: np.ndarray, labels: np.ndarray, zoom: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) depth and labels as a pinhole camera of ``zoom`` times the focal length (the
    same centre and size) sees the scene, or the same camera a scene ``zoom`` times the
    size at the same depths: the nearest pixel of the frame; what falls outside it has
    no measurement (depth 0, label 0). The depths do not change."""
    if zoom == 1.0:
        return depth_mm, labels
    h, w = depth_mm.shape
    ys = np.floor((np.arange(h) + 0.5 - h / 2) / zoom + h / 2).astype(np.int64)
    xs = np.floor((np.arange(w) + 0.5 - w / 2) / zoom + w / 2).astype(np.int64)
    inside = ((ys >= 0) & (ys < h))[:, None] & ((xs >= 0) & (xs < w))[None]
    yi, xi = np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)
    return (np.where(inside, depth_mm[yi][:, xi], 0).astype(depth_mm.dtype),
            np.where(inside, labels[yi][:, xi], 0).astype(labels.dtype))


# scene classes that are not free-standing things: the room's surfaces and what hangs on
# them, and people with what they wear and carry (vhgen.scene.geometry's class names)
NOT_THINGS = ("background", "floor", "wall", "person", "window", "curtain", "door",
              "picture", "radiator", "stairs", "carried")


def class_names(path: str) -> tuple[str, ...]:
    """The scene class names of a store (its attrs ``class_names``; () when it has none)."""
    return tuple(read_attrs(path).get("class_names") or ())


def lone_things_view(depth_mm: np.ndarray, truth: np.ndarray, classes: np.ndarray,
                     class_names: tuple[str, ...] | list[str]) -> np.ndarray:
    """A frame with only its free-standing things measured (furniture, props, clutter:
    every scene class not in :data:`NOT_THINGS`), no person: what a pipeline that
    removed the background leaves of the objects it missed, each with nothing around it.
    Every candidate of it is no person. Returns the depth of the view."""
    things = np.array([n not in NOT_THINGS for n in class_names] + [False] * 256)[:256]
    keep = things[np.asarray(classes, np.uint8)] & (truth == 0)
    return np.where(keep, depth_mm, 0).astype(depth_mm.dtype)


def read_instances(frames: list[tuple[str, int, int]], labels: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Person instances (N, H, W) uint8 of the selected frames (0 = no person, k = the
    k-th person of the frame's manifest row) and (N,) bool: whether they came from the
    store's ``instances`` array. A store without one (written before it existed) gives
    ``labels > 0`` (the frames' ``labels``, (N, H, W)) as one person."""
    out = (np.asarray(labels) > 0).astype(np.uint8)
    return out, _read_optional(frames, "instances", out)
