"""From the plan to a frame's pure description (no GL): bodies, poses, camera, room."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vhgen.body.labels import LabelScheme
from vhgen.body.model import Body, build_body
from vhgen.body.shape import Shape
from vhgen.body.skinning import bone_matrices, posed_heads, skin_vertices
from vhgen.camera import look_at
from vhgen.config import CameraConfig, JobConfig
from vhgen.scene.description import CameraPose, FrameDescription, Person
from vhgen.scene.room import sample_room, static_geometry

# the scene stream: room and placements, spawned from the frame seed (see FrameDescription)
_SCENE_STREAM = 0x5CE4E
FLOOR_SNAP_M = 0.10  # a lowest point closer than this to the floor is put on it


def sample_camera(rng: np.random.Generator, cfg: CameraConfig) -> CameraPose:
    """Camera placement around the subject's root (the first 4 draws of the frame's
    stream, in this order: yaw, distance, height, look-at height)."""
    yaw = rng.uniform(*cfg.yaw_deg)
    dist = rng.uniform(*cfg.distance_m)
    height = rng.uniform(*cfg.height_m)
    target_h = rng.uniform(*cfg.look_at_height_m)
    a = np.deg2rad(yaw)
    eye = np.array([dist * np.sin(a), height, dist * np.cos(a)])
    w2c = look_at(eye, np.array([0.0, target_h, 0.0]))
    return CameraPose(w2c, float(yaw), float(dist), float(height))


class FrameDescriber:
    """Builds :class:`FrameDescription` s of one job. Holds the pose table, the plan and a
    cache of CPU bodies (one per avatar, built on first use)."""

    def __init__(self, cfg: JobConfig, asset_dir: str | Path, pose_rotations: np.ndarray,
                 pose_roots: np.ndarray, plan_arrays: dict, avatars: list[dict]):
        self.cfg = cfg
        self.asset_dir = Path(asset_dir)
        self.rotations = pose_rotations
        self.roots = pose_roots
        self.plan = plan_arrays
        self.avatars = avatars
        self.scheme = LabelScheme.load(cfg.labels)
        self._bodies: dict[int, Body] = {}
        # poses were retargeted onto the unshaped base body; an avatar's root height
        # scales with its hip height so its feet stay on the floor
        self._base_hip_drop = build_body(self.asset_dir, self.scheme).hip_drop

    def body(self, avatar_id: int) -> Body:
        """The avatar's shaped body (CPU), built once per describer."""
        if avatar_id not in self._bodies:
            if len(self._bodies) >= 4:  # avatars come in runs (avatar-major plan)
                self._bodies.pop(next(iter(self._bodies)))
            p = self.avatars[avatar_id]
            self._bodies[avatar_id] = build_body(
                self.asset_dir, self.scheme, shape=Shape.from_dict(p["shape"]),
                scale=p["scale"], clothing=tuple(p["clothing"]))
        return self._bodies[avatar_id]

    def person(self, instance: int, avatar_id: int, pose: int, ground: bool = False) -> Person:
        """A person with its root above the world origin (height and heading kept).

        ``ground`` (scenes with a floor): a lowest skinned vertex less than
        :data:`FLOOR_SNAP_M` above the floor, or below it, is moved onto y = 0, so feet
        touch the floor despite the few centimetres retargeting leaves; a higher one
        (a jump) stays in the air. The shift is part of ``offset``."""
        body = self.body(avatar_id)
        rot = self.rotations[pose]
        root = self.roots[pose] * (body.hip_drop / self._base_hip_drop)
        offset = np.array([-root[0], 0.0, -root[2]])
        if ground:
            lowest = skin_vertices(body.vertices, body.joints, body.weights,
                                   bone_matrices(body.rig, rot, root + offset))[:, 1].min()
            if lowest < FLOOR_SNAP_M:
                offset[1] = -lowest
        root = root + offset
        return Person(instance, avatar_id, pose, bone_matrices(body.rig, rot, root),
                      posed_heads(body.rig, rot, root), offset)

    def describe(self, frame: int) -> FrameDescription:
        """The frame's description: its person, camera (first draws of the frame stream),
        static geometry (scene stream) and the sensor noise state."""
        seed = int(self.plan["seeds"][frame])
        rng = np.random.default_rng(seed)
        person = self.person(1, int(self.plan["avatar_id"][frame]),
                             int(self.plan["pose_index"][frame]), ground=self.cfg.scene.floor)
        cam = sample_camera(rng, self.cfg.camera)
        room = None
        sc = self.cfg.scene
        if sc.room is not None:
            scene_rng = np.random.default_rng(np.random.SeedSequence([seed, _SCENE_STREAM]))
            eye = -cam.world_to_camera[:3, :3].T @ cam.world_to_camera[:3, 3]
            room = sample_room(scene_rng, sc.room, eye[[0, 2]], cam.yaw_deg)
        return FrameDescription(frame, seed, cam, (person,), static_geometry(sc, room), room,
                                rng.bit_generator.state)
