"""From the plan to a frame's pure description (no GL): bodies, poses, camera, room."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vhgen.body.kernels import footprint as floor_footprint
from vhgen.body.kernels import skin_points
from vhgen.body.labels import LabelScheme
from vhgen.body.model import Body, build_avatar, build_body
from vhgen.body.skinning import matrices_from_heads, posed_heads
from vhgen.camera import look_at
from vhgen.config import CameraConfig, JobConfig
from vhgen.scene.config import BEHIND_M, CAMERA_CLEARANCE_M
from vhgen.scene.description import CameraPose, FrameDescription, Person, PlacedProp
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
from vhgen.scene.room import sample_room, static_geometry

# the scene stream: room and placements, spawned from the frame seed (see FrameDescription)
_SCENE_STREAM = 0x5CE4E
FLOOR_SNAP_M = 0.10  # a lowest point closer than this to the floor is put on it


def sample_camera(rng: np.random.Generator, cfg: CameraConfig) -> CameraPose:
    """Camera placement around the subject's root (the first draws of the frame's
    stream, in this order: yaw, distance, height, then look-at height; or, for a mounted
    camera (``pitch_deg`` set), pitch and roll)."""
    yaw = rng.uniform(*cfg.yaw_deg)
    dist = rng.uniform(*cfg.distance_m)
    height = rng.uniform(*cfg.height_m)
    a = np.deg2rad(yaw)
    eye = np.array([dist * np.sin(a), height, dist * np.cos(a)])
    if cfg.pitch_deg is None:
        target_h = rng.uniform(*cfg.look_at_height_m)
        w2c = look_at(eye, np.array([0.0, target_h, 0.0]))
        return CameraPose(w2c, float(yaw), float(dist), float(height))
    pitch = float(rng.uniform(*cfg.pitch_deg))
    roll = float(rng.uniform(*cfg.roll_deg))
    w2c = mounted_camera(eye, pitch, roll)
    return CameraPose(w2c, float(yaw), float(dist), float(height), pitch, roll)


def mounted_camera(eye: np.ndarray, pitch_deg: float, roll_deg: float) -> np.ndarray:
    """world_to_camera (4, 4) of a camera at ``eye`` turned towards the world's y axis,
    tilted down by ``pitch_deg`` and rolled by ``roll_deg`` about its optical axis."""
    level = np.array([-eye[0], 0.0, -eye[2]])
    level /= np.linalg.norm(level)
    p = np.deg2rad(pitch_deg)
    forward = np.cos(p) * level + np.array([0.0, -np.sin(p), 0.0])
    w2c = look_at(eye, eye + forward)
    c, s = np.cos(np.deg2rad(roll_deg)), np.sin(np.deg2rad(roll_deg))
    rz = np.eye(4)
    rz[:2, :2] = [[c, -s], [s, c]]
    return rz @ w2c


MAX_BODIES = 32  # CPU bodies a describer keeps (~0.4 MB each: the topology is shared)


class FrameDescriber:
    """Builds :class:`FrameDescription` s of one job. Holds the pose table, the plan and a
    cache of CPU bodies (one per avatar, built on first use)."""

    def __init__(self, cfg: JobConfig, asset_dir: str | Path, pose_rotations: np.ndarray,
                 pose_roots: np.ndarray, plan_arrays: dict, avatars: list[dict],
                 bodies: dict[int, Body] | None = None, base_hip_drop: float | None = None):
        """bodies : avatar id -> body already built (by the driver, while this worker set
        up: :func:`build_avatar`, so the same body); base_hip_drop : the unshaped base
        body's :attr:`~vhgen.body.model.Body.hip_drop` if known. Both only save work."""
        self.cfg = cfg
        self.asset_dir = Path(asset_dir)
        self.rotations = pose_rotations
        self.roots = pose_roots
        self.plan = plan_arrays
        self.avatars = avatars
        self.scheme = LabelScheme.load(cfg.labels)
        self._bodies: dict[int, Body] = dict(list((bodies or {}).items())[:MAX_BODIES])
        # poses were retargeted onto the unshaped base body; an avatar's root height
        # scales with its hip height so its feet stay on the floor
        self._base_hip_drop = base_hip_drop if base_hip_drop is not None else \
            build_body(self.asset_dir, self.scheme).hip_drop

    def body(self, avatar_id: int) -> Body:
        """The avatar's shaped body (CPU), built on first use and kept in a least recently
        used cache of :data:`MAX_BODIES`."""
        body = self._bodies.pop(avatar_id, None)
        if body is None:
            if len(self._bodies) >= MAX_BODIES:  # the least recently used goes
                self._bodies.pop(next(iter(self._bodies)))
            body = build_avatar(self.asset_dir, self.scheme, self.avatars[avatar_id])
        self._bodies[avatar_id] = body  # most recently used at the end
        return body

    def person(self, instance: int, avatar_id: int, pose: int, ground: bool = False,
               footprint: bool = False) -> Person:
        """A person with its root above the world origin (height and heading kept).

        ``ground`` (scenes with a floor): a lowest skinned vertex less than
        :data:`FLOOR_SNAP_M` above the floor, or below it, is moved onto y = 0, so feet
        touch the floor despite the few centimetres retargeting leaves; a higher one
        (a jump) stays in the air. The shift is part of ``offset``. ``footprint``: also
        bound the skinned body's floor footprint by a circle (for placement)."""
        body = self.body(avatar_id)
        rot = self.rotations[pose]
        root = self.roots[pose] * (body.hip_drop / self._base_hip_drop)
        offset = np.array([-root[0], 0.0, -root[2]])
        disc = None
        heads = posed_heads(body.rig, rot, root + offset)
        mats = matrices_from_heads(body.rig, rot, heads)
        if ground or footprint:
            verts = skin_points(body.vertices, body.joints, body.weights, mats)
            lowest, cx, cz, radius = floor_footprint(verts)
            if ground and lowest < FLOOR_SNAP_M:
                # moved up by -lowest: the same rotations, so every head and every bone's
                # translation moves by the same vector (not posed again: 0.1 ms a person)
                offset[1] = -lowest
                heads = heads + np.array([0.0, -lowest, 0.0])
                mats = mats.copy()
                mats[:, 1, 3] -= lowest
            disc = Disc(cx, cz, radius)
        return Person(instance, avatar_id, pose, mats, heads, offset, footprint=disc)

    def describe(self, frame: int) -> FrameDescription:
        """The frame's description. The first person and the camera come from the frame
        stream exactly as vhgen always drew them; room, further people and props from the
        scene stream (see :class:`FrameDescription`)."""
        seed = int(self.plan["seeds"][frame])
        rng = np.random.default_rng(seed)
        sc = self.cfg.scene
        person = self.person(1, int(self.plan["avatar_id"][frame]),
                             int(self.plan["pose_index"][frame]), ground=sc.floor,
                             footprint=not sc.is_person_only)
        cam = sample_camera(rng, self.cfg.camera)
        noise_state = rng.bit_generator.state
        if sc.is_person_only:
            return FrameDescription(frame, seed, cam, (person,), (), None, noise_state)
        srng = np.random.default_rng(np.random.SeedSequence([seed, _SCENE_STREAM]))
        w2c = cam.world_to_camera
        eye = (-w2c[:3, :3].T @ w2c[:3, 3])[[0, 2]]
        forward = w2c[2, :3][[0, 2]]
        forward = forward / np.linalg.norm(forward)
        behind = BEHIND_M if sc.people[1] > 1 else 0.0
        room = (sample_room(srng, sc.room, eye, cam.yaw_deg, behind) if sc.room is not None
                else None)
        people = [person]
        assert person.footprint is not None
        discs = [person.footprint, Disc(float(eye[0]), float(eye[1]), CAMERA_CLEARANCE_M)]
        dropped = {"people": 0, "props": 0}
        intr = self.cfg.sensor.intrinsics
        half_fov = float(np.arctan2(intr.width / 2, intr.fx))
        reach = (self.cfg.camera.distance_m[0], self.cfg.camera.distance_m[1] + 1.5)
        people_discs = [person.footprint]
        walls: list[Disc] = []  # tall props: they hide people like people do

        def keeps_people_visible(d: Disc, is_person: bool) -> bool:
            """No person (the new one included) is hidden beyond min_visible_fraction."""
            everyone = people_discs + ([d] if is_person else [])
            blockers = everyone + walls + ([] if is_person else [d])
            return all(visible_fraction(eye, t, [o for o in blockers if o is not t])
                       >= sc.min_visible_fraction for t in everyone)

        n_people = int(srng.integers(sc.people[0], sc.people[1] + 1))
        for k in range(2, n_people + 1):
            a = int(srng.integers(len(self.avatars)))
            pose = int(srng.integers(len(self.rotations)))
            heading = float(srng.uniform(-np.pi, np.pi))
            local = self.person(k, a, pose, ground=sc.floor, footprint=True)
            assert local.footprint is not None
            r = local.footprint.r
            spot = place_in_view(srng, eye, forward, half_fov, reach, r, discs, room,
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
            n_props = int(srng.integers(pc.count[0], pc.count[1] + 1))
            p_occ = float(srng.uniform(*pc.occlusion))
            choices = len(pc.kinds) + len(pc.meshes)
            for _ in range(n_props):
                pick = int(srng.integers(choices))
                shape = (parametric(pc.kinds[pick], srng) if pick < len(pc.kinds)
                         else pc.meshes[pick - len(pc.kinds)])
                cls = (pc.kind_classes + pc.mesh_classes)[pick]
                heading = float(srng.uniform(-np.pi, np.pi))
                occluder = bool(srng.uniform() < p_occ)
                target = people[int(srng.integers(len(people)))].footprint
                assert target is not None
                tall = float(shape.vertices[:, 1].max()) >= TALL_PROP_M

                def ok(d: Disc, tall: bool = tall) -> bool:
                    return not tall or keeps_people_visible(d, False)

                spot = (place_between(srng, eye, target, shape.radius, discs, room,
                                      accept=ok) if occluder else None)
                if spot is None:  # not asked to occlude, or no room on the line of sight
                    spot = place_anywhere(srng, eye, shape.radius, discs, room, accept=ok)
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
        return FrameDescription(frame, seed, cam, tuple(people), tuple(static), room,
                                noise_state, tuple(props), dropped)
