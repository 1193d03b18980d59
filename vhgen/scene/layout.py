"""A frame's scene around its first person (pure): the room, further people and props
placed on the floor, and the static geometry to draw.

Everything here is drawn from the frame's *scene stream* (see
:class:`~vhgen.scene.description.FrameDescription`), in a fixed order: the room, the
number of people, each further person (avatar, pose, heading, then its spot), the number
of props and each prop. Posing a person needs a body, which this layer does not build:
the caller passes a :class:`People`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from vhgen.camera import CameraPose, Intrinsics
from vhgen.scene.description import Person, PlacedProp
from vhgen.scene.geometry import StaticMesh
from vhgen.scene.placement import (
    TALL_PROP_M,
    Disc,
    place_anywhere,
    place_between,
    place_in_view,
    visible_fraction,
    yaw_transform,
)
from vhgen.scene.props import parametric
from vhgen.scene.room import Room, sample_room, static_geometry
from vhgen.scene.scene_config import BEHIND_M, CAMERA_CLEARANCE_M, SceneConfig


class People(Protocol):
    """Where further people come from: how many avatars and poses there are to draw
    from, and a person of a given avatar and pose, posed with its root above the world
    origin and its footprint (see :meth:`vhgen.pipeline.describe.FrameDescriber.pose`)."""

    @property
    def num_avatars(self) -> int: ...

    @property
    def num_poses(self) -> int: ...

    def pose(self, instance: int, avatar_id: int, pose: int) -> Person: ...


@dataclass(frozen=True, eq=False)
class SceneLayout:
    """What a frame holds besides its first person's pose: every person (the first
    included), the static meshes, the room, the props, and what did not fit."""

    people: tuple[Person, ...]
    static: tuple[StaticMesh, ...]
    room: Room | None
    props: tuple[PlacedProp, ...] = ()
    dropped: Mapping[str, int] = field(default_factory=dict)


def layout_scene(rng: np.random.Generator, scene: SceneConfig, camera: CameraPose,
                 intr: Intrinsics, reach: tuple[float, float], first: Person,
                 people_from: People) -> SceneLayout:
    """Lay out the scene of one frame around ``first`` (the plan's person, at the
    origin, with its footprint), seen by ``camera`` of intrinsics ``intr``.

    reach : (nearest, farthest) floor distance from the camera at which further people
        are placed; they are drawn and posed by ``people_from``.
    """
    sc = scene
    eye = camera.eye[[0, 2]]
    forward = camera.world_to_camera[2, :3][[0, 2]]
    forward = forward / np.linalg.norm(forward)
    behind = BEHIND_M if sc.people[1] > 1 else 0.0
    room = (sample_room(rng, sc.room, eye, camera.yaw_deg, behind) if sc.room is not None
            else None)
    people = [first]
    assert first.footprint is not None
    discs = [first.footprint, Disc(float(eye[0]), float(eye[1]), CAMERA_CLEARANCE_M)]
    dropped = {"people": 0, "props": 0}
    half_fov = float(np.arctan2(intr.width / 2, intr.fx))
    people_discs = [first.footprint]
    walls: list[Disc] = []  # tall props: they hide people like people do

    def keeps_people_visible(d: Disc, is_person: bool) -> bool:
        """No person (the new one included) is hidden beyond min_visible_fraction."""
        everyone = people_discs + ([d] if is_person else [])
        blockers = everyone + walls + ([] if is_person else [d])
        return all(visible_fraction(eye, t, [o for o in blockers if o is not t])
                   >= sc.min_visible_fraction for t in everyone)

    n_people = int(rng.integers(sc.people[0], sc.people[1] + 1))
    for k in range(2, n_people + 1):
        a = int(rng.integers(people_from.num_avatars))
        pose = int(rng.integers(people_from.num_poses))
        heading = float(rng.uniform(-np.pi, np.pi))
        local = people_from.pose(k, a, pose)
        assert local.footprint is not None
        r = local.footprint.r
        spot = place_in_view(rng, eye, forward, half_fov, reach, r, discs, room,
                             accept=lambda d: keeps_people_visible(d, True))
        if spot is None:
            dropped["people"] += 1
            continue
        # rotate about the footprint's centre, then move that centre onto the spot
        c = np.array([local.footprint.x, 0.0, local.footprint.z])
        t = yaw_transform(heading, spot.x, spot.z) @ yaw_transform(0.0, -c[0], -c[2])
        people.append(Person(len(people) + 1, a, pose, t @ local.bones,
                             local.joints @ t[:3, :3].T + t[:3, 3], local.offset, t, spot))
        discs.append(spot)
        people_discs.append(spot)
    props: list[PlacedProp] = []
    static = list(static_geometry(sc, room))
    if sc.props is not None:
        pc = sc.props
        n_props = int(rng.integers(pc.count[0], pc.count[1] + 1))
        p_occ = float(rng.uniform(*pc.occlusion))
        choices = len(pc.kinds) + len(pc.meshes)
        for _ in range(n_props):
            pick = int(rng.integers(choices))
            shape = (parametric(pc.kinds[pick], rng) if pick < len(pc.kinds)
                     else pc.meshes[pick - len(pc.kinds)])
            cls = (pc.kind_classes + pc.mesh_classes)[pick]
            heading = float(rng.uniform(-np.pi, np.pi))
            occluder = bool(rng.uniform() < p_occ)
            target = people[int(rng.integers(len(people)))].footprint
            assert target is not None
            tall = float(shape.vertices[:, 1].max()) >= TALL_PROP_M

            def ok(d: Disc, tall: bool = tall) -> bool:
                return not tall or keeps_people_visible(d, False)

            spot = (place_between(rng, eye, target, shape.radius, discs, room,
                                  accept=ok) if occluder else None)
            if spot is None:  # not asked to occlude, or no room on the line of sight
                spot = place_anywhere(rng, eye, shape.radius, discs, room, accept=ok)
                occluder = False
            if spot is None:
                dropped["props"] += 1
                continue
            t = yaw_transform(heading, spot.x, spot.z)
            props.append(PlacedProp(shape.kind, t, spot, occluder, cls))
            static.append(StaticMesh(f"prop:{shape.kind}",
                                     shape.vertices @ t[:3, :3].T + t[:3, 3], shape.faces,
                                     np.full(len(shape.faces), sc.class_id(cls), np.uint8)))
            discs.append(spot)
            if tall:
                walls.append(spot)
    return SceneLayout(tuple(people), tuple(static), room, tuple(props), dropped)
