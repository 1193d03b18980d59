"""A frame's scene around its first person (pure): the room, further people and props
placed on the floor, and the static geometry to draw.

Everything here is drawn from the frame's *scene stream* (see
:class:`~vhgen.scene.description.FrameDescription`), in a fixed order: the room, the
number of people, each further person (avatar, pose, heading, then its spot), the number
of props and each prop, then the clutter (:mod:`vhgen.scene.clutter.place`). A frame
whose people do not all fit is laid out again from streams of its own (see
:func:`layout_scene`). Posing a person needs a body, which this layer does not build:
the caller passes a :class:`People`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from vhgen.camera import CameraPose, Intrinsics
from vhgen.scene.clutter.place import Obstacle, place_clutter
from vhgen.scene.description import Person, PlacedClutter, PlacedProp
from vhgen.scene.geometry import StaticMesh
from vhgen.scene.placement import (
    GAP_M,
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
from vhgen.scene.solids import disc_solid
from vhgen.scene.walls import walls_with_openings


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
    clutter: tuple[PlacedClutter, ...] = ()


# A frame whose people do not all fit is laid out again (room, headings, spots) from
# fresh streams, up to this many layouts in all; the one with the most people is kept.
MAX_LAYOUTS = 8
SAME_PEOPLE_LAYOUTS = 4  # layouts 1-3 keep the people's avatars and poses


@dataclass
class _People:
    """One layout's room and people: the generator it drew them from (props and clutter
    continue it), what was drawn for each further person (avatar, pose) and what fit."""

    rng: np.random.Generator
    room: Room | None
    people: list[Person]
    discs: list[Disc]
    drawn: list[tuple[int, int]]
    dropped: int


def layout_scene(rng: np.random.Generator, scene: SceneConfig, camera: CameraPose,
                 intr: Intrinsics, reach: tuple[float, float], first: Person,
                 people_from: People,
                 redraw: Callable[[int], np.random.Generator] | None = None,
                 library_seed: int = 0) -> SceneLayout:
    """Lay out the scene of one frame around ``first`` (the plan's person, at the
    origin, with its footprint), seen by ``camera`` of intrinsics ``intr``.

    reach : (nearest, farthest) floor distance from the camera at which further people
        are placed; they are drawn and posed by ``people_from``.
    redraw : the generator of layout k >= 1 (a stream of its own). When a person of the
        first layout (drawn from ``rng``) finds no place, the room, the people's headings
        and spots are drawn again from ``redraw(1)``, ``redraw(2)``, ..., always for the
        same number of people (so the count asked for is what the frames show): layouts
        below :data:`SAME_PEOPLE_LAYOUTS` keep the people's avatars and poses, later ones
        draw them anew (a wide pose may fit nowhere beside the others). At most
        :data:`MAX_LAYOUTS` layouts; the first that fits everyone, else the first with the
        most people, is kept, and props and clutter follow it. A frame whose first layout
        fits is exactly what it always was.
    library_seed : the seed of the job's clutter library (the job's seed).
    """
    sc = scene
    eye = camera.eye[[0, 2]]
    forward = camera.world_to_camera[2, :3][[0, 2]]
    forward = forward / np.linalg.norm(forward)
    half_fov = float(np.arctan2(intr.width / 2, intr.fx))
    assert first.footprint is not None
    posed: dict[int, Person] = {}
    lay = _layout_people(rng, sc, eye, forward, half_fov, camera.yaw_deg, reach, first,
                         people_from, posed, None)
    best = lay
    for k in range(1, MAX_LAYOUTS if redraw is not None else 0):
        if best.dropped == 0:
            break
        assert redraw is not None
        # the first redraws keep who the people are; later ones draw them anew too (a
        # person in a wide pose may fit nowhere beside the others)
        keep = k < SAME_PEOPLE_LAYOUTS
        again = _layout_people(redraw(k), sc, eye, forward, half_fov, camera.yaw_deg, reach,
                               first, people_from, posed if keep else {},
                               lay.drawn if keep else None, len(lay.drawn) + 1)
        if len(again.people) > len(best.people):
            best = again
    rng, room, people, discs = best.rng, best.room, best.people, best.discs
    dropped = {"people": best.dropped, "props": 0}
    people_discs = [p.footprint for p in people if p.footprint is not None]
    walls: list[Disc] = []  # tall props: they hide people like people do

    def keeps_people_visible(d: Disc) -> bool:
        """No person is hidden beyond min_visible_fraction by the tall prop ``d``."""
        blockers = people_discs + walls + [d]
        return all(visible_fraction(eye, t, [o for o in blockers if o is not t])
                   >= sc.min_visible_fraction for t in people_discs)

    props: list[PlacedProp] = []
    prop_tops: list[float] = []
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
            top = float(shape.vertices[:, 1].max())
            tall = top >= TALL_PROP_M

            def ok(d: Disc, tall: bool = tall) -> bool:
                return not tall or keeps_people_visible(d)

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
            prop_tops.append(top)
            static.append(StaticMesh(f"prop:{shape.kind}",
                                     shape.vertices @ t[:3, :3].T + t[:3, 3], shape.faces,
                                     np.full(len(shape.faces), sc.class_id(cls), np.uint8)))
            discs.append(spot)
            if tall:
                walls.append(spot)
    clutter: tuple[PlacedClutter, ...] = ()
    if sc.clutter is not None and room is not None:
        obstacles = ([Obstacle(disc_solid(d.x, d.z, d.r), GAP_M) for d in people_discs]
                     + [Obstacle(disc_solid(float(eye[0]), float(eye[1]),
                                            CAMERA_CLEARANCE_M), GAP_M)]
                     + [Obstacle(disc_solid(p.footprint.x, p.footprint.z, p.footprint.r, top),
                                 GAP_M) for p, top in zip(props, prop_tops, strict=True)])
        cl = place_clutter(rng, sc, room, eye, forward, half_fov, obstacles, people_discs,
                           walls, library_seed)
        clutter = cl.items
        dropped["clutter"] = cl.dropped
        static += cl.meshes
        if cl.openings:
            static = [walls_with_openings(room.corners_xz, room.height_m, cl.openings)
                      if m.name == "walls" else m for m in static]
    return SceneLayout(tuple(people), tuple(static), room, tuple(props), dropped, clutter)


def _layout_people(rng: np.random.Generator, sc: SceneConfig, eye: np.ndarray,
                   forward: np.ndarray, half_fov: float, camera_yaw_deg: float,
                   reach: tuple[float, float], first: Person, people_from: People,
                   posed: dict[int, Person], forced: list[tuple[int, int]] | None,
                   count: int | None = None) -> _People:
    """The room and the further people of one layout. ``count``: the number of people
    (None: drawn); ``forced``: the avatars and poses of an earlier layout (who the people
    are stays; headings and spots are drawn anew); ``posed``: people posed so far, by draw
    index (posing is the costly part, and a redrawn layout may pose the same people)."""
    assert first.footprint is not None
    behind = BEHIND_M if sc.people[1] > 1 else 0.0
    room = (sample_room(rng, sc.room, eye, camera_yaw_deg, behind) if sc.room is not None
            else None)
    people = [first]
    discs = [first.footprint, Disc(float(eye[0]), float(eye[1]), CAMERA_CLEARANCE_M)]
    people_discs = [first.footprint]
    dropped = 0

    def keeps_people_visible(d: Disc) -> bool:
        """No person (the new one included) is hidden beyond min_visible_fraction."""
        everyone = people_discs + [d]
        return all(visible_fraction(eye, t, [o for o in everyone if o is not t])
                   >= sc.min_visible_fraction for t in everyone)

    n_people = (count if count is not None
                else int(rng.integers(sc.people[0], sc.people[1] + 1)))
    drawn = []
    for k in range(2, n_people + 1):
        if forced is None:
            a = int(rng.integers(people_from.num_avatars))
            pose = int(rng.integers(people_from.num_poses))
        else:
            a, pose = forced[k - 2]
        drawn.append((a, pose))
        heading = float(rng.uniform(-np.pi, np.pi))
        local = posed.get(k)
        if local is None:
            local = posed[k] = people_from.pose(k, a, pose)
        assert local.footprint is not None
        r = local.footprint.r
        spot = place_in_view(rng, eye, forward, half_fov, reach, r, discs, room,
                             accept=keeps_people_visible)
        if spot is None:
            dropped += 1
            continue
        # rotate about the footprint's centre, then move that centre onto the spot
        c = np.array([local.footprint.x, 0.0, local.footprint.z])
        t = yaw_transform(heading, spot.x, spot.z) @ yaw_transform(0.0, -c[0], -c[2])
        people.append(Person(len(people) + 1, a, pose, t @ local.bones,
                             local.joints @ t[:3, :3].T + t[:3, 3], local.offset, t, spot))
        discs.append(spot)
        people_discs.append(spot)
    return _People(rng, room, people, discs, drawn, dropped)
