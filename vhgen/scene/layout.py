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
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from vhgen.camera import CameraPose, Intrinsics
from vhgen.scene.clutter.place import Obstacle, hides, place_clutter
from vhgen.scene.description import Person, PlacedClutter, PlacedProp
from vhgen.scene.geometry import StaticMesh
from vhgen.scene.placement import (
    GAP_M,
    TALL_PROP_M,
    Disc,
    all_visible,
    is_free,
    place_anywhere,
    place_beside,
    place_between,
    place_in_view,
    turned,
    yaw_transform,
)
from vhgen.scene.props import parametric
from vhgen.scene.room import Room, sample_room, static_geometry
from vhgen.scene.scene_config import (
    BEHIND_M,
    CAMERA_CLEARANCE_M,
    LineupConfig,
    SceneConfig,
)
from vhgen.scene.solids import (
    Solid,
    disc_polygon,
    disc_solid,
    separated,
    visible_fraction_compiled,
)
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
    clutter_solids: tuple[tuple[Solid, ...], ...] = ()  # per clutter item, its footprints


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
        return all_visible(eye, people_discs + walls + [d], len(people_discs),
                           sc.min_visible_fraction)

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
    clutter_solids: tuple[tuple[Solid, ...], ...] = ()
    if sc.clutter is not None and room is not None:
        obstacles = ([Obstacle(disc_solid(d.x, d.z, d.r), GAP_M) for d in people_discs]
                     + [Obstacle(disc_solid(float(eye[0]), float(eye[1]),
                                            CAMERA_CLEARANCE_M), GAP_M)]
                     + [Obstacle(disc_solid(p.footprint.x, p.footprint.z, p.footprint.r, top),
                                 GAP_M) for p, top in zip(props, prop_tops, strict=True)])
        cl = place_clutter(rng, sc, room, eye, forward, half_fov, obstacles, people_discs,
                           walls, library_seed)
        clutter, clutter_solids = cl.items, cl.item_solids
        dropped["clutter"] = cl.dropped
        static += cl.meshes
        if cl.openings:
            static = [walls_with_openings(room.corners_xz, room.height_m, cl.openings)
                      if m.name == "walls" else m for m in static]
    return SceneLayout(tuple(people), tuple(static), room, tuple(props), dropped, clutter,
                       clutter_solids)


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
    outlines = [first.outline] if first.outline is not None else []
    dropped = 0

    def keeps_people_visible(d: Disc) -> bool:
        """No person (the new one included) is hidden beyond min_visible_fraction."""
        return all_visible(eye, people_discs + [d], len(people_discs) + 1,
                           sc.min_visible_fraction)

    n_people = (count if count is not None
                else int(rng.integers(sc.people[0], sc.people[1] + 1)))
    line = _Line.draw(rng, sc, eye, first)
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
        spot, outline = None, None
        centre = np.array([local.footprint.x, local.footprint.z])
        if line is not None:
            assert local.outline is not None and first.outline is not None
            # facing the camera, turned by up to facing_deg (the heading's draw scaled:
            # one draw either way)
            turn = (heading / np.pi * np.deg2rad(line.cfg.facing_deg)
                    - _bearing(local.bones[0, [0, 2], 2]))

            def facing(xz: np.ndarray, turn: float = turn) -> float:
                return _bearing(eye - xz) + turn

            beside = place_beside(rng, eye, forward, half_fov, tuple(line.ends), line.across,
                                  local.outline - centre, r, facing, line.cfg.gap_m,
                                  line.cfg.depth_m, outlines, discs[1:2], room,
                                  accept=keeps_people_visible)
            if beside is not None:
                spot, heading, outline = beside.disc, beside.heading, beside.outline
                line.ends[beside.side] = (spot, outline)
        if spot is None:
            spot = place_in_view(rng, eye, forward, half_fov, reach, r, discs, room,
                                 accept=keeps_people_visible)
        if spot is None:
            dropped += 1
            continue
        # rotate about the footprint's centre, then move that centre onto the spot
        t = yaw_transform(heading, spot.x, spot.z) @ yaw_transform(0.0, -centre[0], -centre[1])
        if local.outline is not None:
            if outline is None:  # placed without the line: its outline follows
                outline = turned(local.outline - centre, heading) + np.array([spot.x, spot.z])
            outlines.append(outline)
        people.append(Person(len(people) + 1, a, pose, t @ local.bones,
                             local.joints @ t[:3, :3].T + t[:3, 3], local.offset, t, spot,
                             outline))
        discs.append(spot)
        people_discs.append(spot)
    return _People(rng, room, people, discs, drawn, dropped)


def _bearing(v: np.ndarray) -> float:
    """The yaw (radians about +y) that turns +z towards the floor direction ``v`` (x, z),
    as :func:`yaw_transform` turns."""
    return float(np.arctan2(v[0], v[1]))


@dataclass
class _Line:
    """The line of a frame whose people stand side by side (``scene.lineup``): its left
    and right end (a person's footprint and outline, the first person's to begin with)
    and its direction across the view."""

    cfg: LineupConfig
    ends: list[tuple[Disc, np.ndarray]]
    across: np.ndarray

    @staticmethod
    def draw(rng: np.random.Generator, sc: SceneConfig, eye: np.ndarray,
             first: Person) -> _Line | None:
        """The frame's line, or None (no ``scene.lineup``, or a frame outside its share).
        Two draws when ``scene.lineup`` is set (in line or not, the tilt), none
        otherwise, so scenes without it keep their streams."""
        if sc.lineup is None:
            return None
        u = rng.uniform(size=2)
        if u[0] >= sc.lineup.share:
            return None
        assert first.footprint is not None and first.outline is not None
        end = (first.footprint, first.outline)
        sight = np.array([first.footprint.x, first.footprint.z]) - eye
        tilt = (2 * u[1] - 1) * np.deg2rad(sc.lineup.tilt_deg)
        a = _bearing(sight) + np.pi / 2 + tilt
        return _Line(sc.lineup, [end, end], np.array([np.sin(a), np.cos(a)]))


# -- a layout consecutive frames share (scene.layout_frames) ------------------------------
SLOT_M = 0.5  # the circle a shared layout keeps free for each person (most standing poses)
FIRST_SPOTS = 8  # spots drawn in its slot for the first person to stay in view
PERSON_DRAWS = 4  # draws of a further person (avatar, pose, heading) a slot may hold
_NO_BONES = np.zeros((0, 4, 4))
_NO_JOINTS = np.zeros((0, 3))
_NO_BONES.setflags(write=False)
_NO_JOINTS.setflags(write=False)


@dataclass(frozen=True, eq=False)
class SharedLayout:
    """What ``scene.layout_frames`` consecutive frames share, as a sensor standing in a
    furnished room sees people come and go: the camera, and a layout (room, props,
    clutter, their static meshes) made once around places kept for people (``slots``:
    circles of :data:`SLOT_M` for further people; the first person's at the origin).
    ``room_meshes``: how many of ``layout.static`` are the room's own (the props' meshes
    follow, one each, then the clutter's)."""

    camera: CameraPose
    layout: SceneLayout
    slots: tuple[Disc, ...]
    room_meshes: int
    # what hides people: tall props' circles (x, z, r) and the footprints of clutter
    # parts that hide a standing person (as placement counts them)
    tall_props: tuple[tuple[float, float, float], ...] = ()
    hiding: tuple[np.ndarray, ...] = ()


class _Slots:
    """The people :func:`layout_shared` lays out: each a circle of :data:`SLOT_M` at the
    origin, without a body."""

    def __init__(self, num_avatars: int, num_poses: int):
        self.num_avatars, self.num_poses = num_avatars, num_poses

    def pose(self, instance: int, avatar_id: int, pose: int) -> Person:
        return Person(instance, avatar_id, pose, _NO_BONES, _NO_JOINTS, np.zeros(3),
                      footprint=Disc(0.0, 0.0, SLOT_M))


def layout_shared(rng: np.random.Generator, scene: SceneConfig, camera: CameraPose,
                  intr: Intrinsics, reach: tuple[float, float], people_from: People,
                  redraw: Callable[[int], np.random.Generator] | None = None,
                  library_seed: int = 0) -> SharedLayout:
    """The layout frames share (see :class:`SharedLayout`): :func:`layout_scene` for the
    most people ``scene.people`` allows, each a circle of :data:`SLOT_M`, so the room,
    props and clutter leave that much floor free for every person and keep each of them
    ``min_visible_fraction`` in view. ``rng`` and ``redraw``: the shared layout's own
    streams; ``people_from`` only gives the numbers of avatars and poses drawn from."""
    most = scene.people[1]
    slots = _Slots(people_from.num_avatars, people_from.num_poses)
    lay = layout_scene(rng, replace(scene, people=(most, most)), camera, intr, reach,
                       slots.pose(1, -1, -1), slots, redraw, library_seed)
    places = tuple(p.footprint for p in lay.people[1:] if p.footprint is not None)
    n_room = len(lay.static) - len(lay.props) - len(lay.clutter)
    tall = tuple((p.footprint.x, p.footprint.z, p.footprint.r)
                 for p, m in zip(lay.props, lay.static[n_room:], strict=False)
                 if float(m.vertices[:, 1].max()) >= TALL_PROP_M)
    hiding = tuple(s.poly for item in lay.clutter_solids for s in item if hides(s))
    return SharedLayout(camera, lay, places, n_room, tall, hiding)


def fill_shared(rng: np.random.Generator, shared: SharedLayout, scene: SceneConfig,
                first: Person, people_from: People) -> SceneLayout:
    """One frame of a shared layout, drawn from ``rng`` (the frame's scene stream):
    ``first`` (the plan's person, posed at the origin with its footprint) moved so that its
    footprint lies at a random spot inside the slot at the origin; then how many people
    (``scene.people``), and for each further one its avatar, pose and heading, and a spot
    inside the first free slot, in a drawn order, that holds it: where it touches no
    other person, keeps everyone ``min_visible_fraction`` in view, and, if it is wider
    than the slot (it then stands at the slot's centre), touches no wall, the camera,
    prop or clutter. A person no free slot holds is drawn again (at most
    :data:`PERSON_DRAWS` draws), then left out (``dropped["people"]``). The first
    person, who is always there, instead leaves out the props and clutter its footprint
    touches (counted in ``dropped``; a door or window left out keeps its opening in the
    wall). A frame that leaves nothing out shares the layout's ``static`` tuple itself
    (the render step keeps it on the GPU)."""
    lay, room = shared.layout, shared.layout.room
    eye = shared.camera.eye[[0, 2]]
    f = first.footprint
    assert f is not None
    for _ in range(FIRST_SPOTS):  # a spot where it stays in view (else the last drawn)
        at = _in_slot(Disc(0.0, 0.0, SLOT_M), f.r, rng.uniform(size=2))
        if _in_view(shared, eye, [at], scene.min_visible_fraction):
            break
    t = yaw_transform(0.0, at.x - f.x, at.z - f.z)
    first = Person(first.instance, first.avatar_id, first.pose_index, t @ first.bones,
                   first.joints + t[:3, 3], first.offset, t @ first.placement, at)
    n = int(rng.integers(scene.people[0], scene.people[1] + 1))
    order = rng.permutation(len(shared.slots))
    people, discs = [first], [at]
    dropped = {**lay.dropped, "people": 0}  # props and clutter: those of the layout
    free = [int(k) for k in order]
    for _ in range(n - 1):
        spot = None
        for _ in range(PERSON_DRAWS):  # who, then the first free slot that holds them
            a = int(rng.integers(people_from.num_avatars))
            pose = int(rng.integers(people_from.num_poses))
            heading = float(rng.uniform(-np.pi, np.pi))
            local = people_from.pose(len(people) + 1, a, pose)
            fp = local.footprint
            assert fp is not None
            for k in free:
                slot = shared.slots[k]
                spot = _in_slot(slot, fp.r, rng.uniform(size=2))
                if (is_free(spot, discs, None)
                        and (fp.r <= slot.r or _clear(spot, shared, eye))
                        and _in_view(shared, eye, [*discs, spot], scene.min_visible_fraction)):
                    free.remove(k)
                    break
                spot = None
            if spot is not None:
                break
        if spot is None:
            dropped["people"] += 1
            continue
        assert fp is not None
        c = np.array([fp.x, 0.0, fp.z])
        t = yaw_transform(heading, spot.x, spot.z) @ yaw_transform(0.0, -c[0], -c[2])
        people.append(Person(len(people) + 1, a, pose, t @ local.bones,
                             local.joints @ t[:3, :3].T + t[:3, 3], local.offset, t, spot))
        discs.append(spot)
    props, clutter, solids = lay.props, lay.clutter, lay.clutter_solids
    static = lay.static
    f = at
    if f.r > SLOT_M:  # wider than its slot: what it touches goes
        keep_p = [is_free(f, [p.footprint], None) for p in props]
        keep_c = [_apart(f, s) for s in solids]
        if not all(keep_p) or not all(keep_c):
            dropped["props"] += keep_p.count(False)
            if keep_c:
                dropped["clutter"] += keep_c.count(False)
            n_room, n_props = shared.room_meshes, len(props)
            prop_meshes = static[n_room:n_room + n_props]
            clutter_meshes = static[n_room + n_props:]
            props = tuple(p for p, ok in zip(props, keep_p, strict=True) if ok)
            clutter = tuple(c for c, ok in zip(clutter, keep_c, strict=True) if ok)
            solids = tuple(s for s, ok in zip(solids, keep_c, strict=True) if ok)
            static = (static[:n_room]
                      + tuple(m for m, ok in zip(prop_meshes, keep_p, strict=True) if ok)
                      + tuple(m for m, ok in zip(clutter_meshes, keep_c, strict=True) if ok))
    return SceneLayout(tuple(people), static, room, props, dropped, clutter, solids)


def _in_slot(slot: Disc, r: float, u: np.ndarray) -> Disc:
    """A circle of radius ``r`` inside ``slot``, where the two uniform numbers ``u`` put
    it (uniform over the spots it can take); at the slot's centre if it is wider."""
    play = max(slot.r - r, 0.0) * float(np.sqrt(u[0]))
    return Disc(slot.x + play * float(np.cos(2 * np.pi * u[1])),
                slot.z + play * float(np.sin(2 * np.pi * u[1])), r)


def _in_view(shared: SharedLayout, eye: np.ndarray, people: list[Disc],
             least: float) -> bool:
    """Every person of ``people`` keeps ``least`` of its width in view past the others,
    the tall props and the clutter that hides people (the floor-plan measure of
    placement)."""
    for p in people:
        others = [(q.x, q.z, q.r) for q in people if q is not p] + list(shared.tall_props)
        if visible_fraction_compiled(eye, np.array([p.x, p.z]), p.r, others,
                                     list(shared.hiding)) < least:
            return False
    return True


def _apart(d: Disc, solids: tuple[Solid, ...]) -> bool:
    """A person's footprint ``d`` at least GAP_M from every footprint of a clutter item
    (people stand from the floor up: every height counts, as in placement)."""
    poly = disc_polygon(d.x, d.z, d.r)[None]
    return all(bool(separated(poly, s.poly, GAP_M, s.normals)[0]) for s in solids)


def _clear(d: Disc, shared: SharedLayout, eye: np.ndarray) -> bool:
    """A footprint ``d`` inside the room, clear of the camera, the props and the clutter
    of ``shared`` (other people are the caller's)."""
    lay = shared.layout
    camera = Disc(float(eye[0]), float(eye[1]), CAMERA_CLEARANCE_M)
    return (is_free(d, [camera, *(p.footprint for p in lay.props)], lay.room)
            and all(_apart(d, s) for s in lay.clutter_solids))
