"""The frozen description of one frame: everything the render step and the sensor need,
built from the plan before any GL call (see :mod:`vhgen.pipeline.describe`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vhgen.camera import CameraPose
from vhgen.scene.background.background_frame import PlacedBackground
from vhgen.scene.geometry import StaticMesh
from vhgen.scene.placement import Disc
from vhgen.scene.room import Room


@dataclass(frozen=True, eq=False)
class Person:
    """One person in a frame: ``instance`` (1..255, the value in ``instances``), the avatar
    and pose, ``bones`` (B, 4, 4) float64 world transforms of the posed rig, ``joints``
    (B, 3) float64 world bone heads, and ``offset`` (3,) added to the retargeted root."""

    instance: int
    avatar_id: int
    pose_index: int
    bones: np.ndarray
    joints: np.ndarray
    offset: np.ndarray
    placement: np.ndarray = field(default_factory=lambda: np.eye(4))  # (4, 4), after offset
    footprint: Disc | None = None  # bounding circle on the floor at placement time
    # the body's convex outline on the floor, (K, 2) x, z in the world (only where
    # placement needs it: scene.lineup stands people closer than their circles allow)
    outline: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class PlacedProp:
    """A prop in a frame: its kind (or mesh file name), the (4, 4) world transform of its
    own frame, its footprint, whether it was put on a line of sight to a person, and its
    scene class name."""

    kind: str
    transform: np.ndarray
    footprint: Disc
    occluder: bool
    class_name: str = "prop"

    def to_dict(self) -> dict:
        """The manifest's record of the prop; ``class`` only for a user class (absent =
        the built-in "prop", so stores of configs without user classes keep their bytes)."""
        d = {"kind": self.kind, "x": self.footprint.x, "z": self.footprint.z,
             "radius": self.footprint.r,
             "yaw_deg": float(np.rad2deg(np.arctan2(self.transform[0, 2],
                                                    self.transform[0, 0]))),
             "occluder": self.occluder}
        if self.class_name != "prop":
            d["class"] = self.class_name
        return d


@dataclass(frozen=True, eq=False)
class PlacedClutter:
    """A clutter item in a frame (see :mod:`vhgen.scene.clutter`): its kind and scene
    class, the (4, 4) world transform of its own frame, the parameters that rebuild it
    (:func:`vhgen.scene.clutter.build`), how it stands (``wall``, ``corner``, ``floor``)
    and the wall it stands against (corner k to k + 1 of the room; -1 on the floor)."""

    kind: str
    class_name: str
    transform: np.ndarray
    params: Mapping[str, float]
    mode: str
    wall: int

    def to_dict(self) -> dict:
        """The manifest's record: enough to rebuild the item exactly."""
        return {"kind": self.kind, "class": self.class_name, "mode": self.mode,
                "wall": self.wall, "transform": self.transform.reshape(-1).tolist(),
                "params": dict(self.params)}


@dataclass(frozen=True, eq=False)
class FrameDescription:
    """One frame, pure: people, static geometry, camera, and the seeds.

    ``noise_state`` is the bit-generator state the sensor's noise starts from. It is the
    frame stream right after the camera's draws, the order vhgen has always used, so
    person-only frames are byte-identical to earlier versions; everything new a scene
    samples (room, placements) comes from a second stream spawned from ``seed``, so scene
    options never shift the sensor noise of a frame."""

    frame: int
    seed: int
    camera: CameraPose
    people: tuple[Person, ...]
    static: tuple[StaticMesh, ...]
    room: Room | None
    noise_state: Mapping[str, Any]
    props: tuple[PlacedProp, ...] = ()
    dropped: Mapping[str, int] = field(default_factory=dict)  # people/props that did not fit
    # a real depth frame the people are composited into (vhgen.scene.background), and the
    # plan's (avatar, pose) when another person took its place there
    background: PlacedBackground | None = None
    planned: tuple[int, int] | None = None
    clutter: tuple[PlacedClutter, ...] = ()
    # scene classes whose pixels get no measurement (window glass): the render step
    # removes their depth before the sensor
    no_return: tuple[int, ...] = ()
    # the layout this frame shares with its neighbours (scene.layout_frames > 1): frame //
    # layout_frames; None when the frame laid out its own
    layout: int | None = None

    def noise_rng(self) -> np.random.Generator:
        """A fresh generator at :attr:`noise_state` (the same numbers every call)."""
        bg = np.random.PCG64()
        # numpy types the state as a TypedDict; ours is the same mapping, copied
        bg.state = dict(self.noise_state)  # type: ignore[assignment]
        return np.random.Generator(bg)
