"""From the job's plan to a frame's pure description (no GL): bodies, poses, camera, and
the scene around the people (:mod:`vhgen.scene.layout`)."""

from __future__ import annotations

import numpy as np

from vhgen.body.avatar import Body, build_avatar
from vhgen.body.skin_kernels import footprint as floor_footprint
from vhgen.body.skin_kernels import skin_points
from vhgen.body.skinning import matrices_from_heads, posed_heads
from vhgen.camera import sample_camera, skip_camera
from vhgen.pipeline.job import Job
from vhgen.scene.background.people import layout_background
from vhgen.scene.description import FrameDescription, Person
from vhgen.scene.layout import SharedLayout, fill_shared, layout_scene, layout_shared
from vhgen.scene.placement import Disc, floor_outline

# the scene stream: room and placements, spawned from the frame seed (see FrameDescription)
_SCENE_STREAM = 0x5CE4E
# the stream of a layout frames share (scene.layout_frames), spawned from the seed of its
# first frame
_SHARED_STREAM = 0x5A4ED
FLOOR_SNAP_M = 0.10  # a lowest point closer than this to the floor is put on it
# further people stand up to this much farther from the camera than its farthest distance
_REACH_BEYOND_M = 1.5


MAX_BODIES = 32  # CPU bodies a describer keeps (~0.4 MB each: the topology is shared)


class FrameDescriber:
    """Builds the :class:`FrameDescription` s of one :class:`~vhgen.pipeline.job.Job`;
    keeps a cache of CPU bodies (one per avatar, built on first use)."""

    def __init__(self, job: Job, bodies: dict[int, Body] | None = None):
        """bodies : avatar id -> body already built (by the driver, while this worker set
        up: :func:`build_avatar`, so the same body); it only saves work."""
        self.job = job
        self._bodies: dict[int, Body] = dict(list((bodies or {}).items())[:MAX_BODIES])
        # poses were retargeted onto the unshaped base body; an avatar's root height
        # scales with its hip height so its feet stay on the floor
        self._base_hip_drop = job.base.hip_drop
        self._shared: tuple[int, SharedLayout] | None = None  # the last shared layout

    def body(self, avatar_id: int) -> Body:
        """The avatar's shaped body (CPU), built on first use and kept in a least recently
        used cache of :data:`MAX_BODIES`."""
        body = self._bodies.pop(avatar_id, None)
        if body is None:
            if len(self._bodies) >= MAX_BODIES:  # the least recently used goes
                self._bodies.pop(next(iter(self._bodies)))
            body = build_avatar(self.job.asset_dir, self.job.scheme,
                                self.job.plan.avatars[avatar_id])
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
        rot = self.job.poses.rotations[pose]
        root = self.job.poses.roots[pose] * (body.hip_drop / self._base_hip_drop)
        offset = np.array([-root[0], 0.0, -root[2]])
        disc = None
        heads = posed_heads(body.rig, rot, root + offset)
        mats = matrices_from_heads(body.rig, rot, heads)
        outline = None
        if ground or footprint:
            verts = skin_points(body.vertices, body.joints, body.weights, mats)
            lowest, cx, cz, radius = floor_footprint(verts)
            if footprint and self.job.cfg.scene.lineup is not None:
                outline = floor_outline(verts[:, [0, 2]])
            if ground and lowest < FLOOR_SNAP_M:
                # moved up by -lowest: the same rotations, so every head and every bone's
                # translation moves by the same vector (not posed again: 0.1 ms a person)
                offset[1] = -lowest
                heads = heads + np.array([0.0, -lowest, 0.0])
                mats = mats.copy()
                mats[:, 1, 3] -= lowest
            disc = Disc(cx, cz, radius)
        return Person(instance, avatar_id, pose, mats, heads, offset, footprint=disc,
                      outline=outline)

    # -- vhgen.scene.layout.People: further people of a scene --------------------------
    @property
    def num_avatars(self) -> int:
        return len(self.job.plan.avatars)

    @property
    def num_poses(self) -> int:
        return self.job.poses.num_poses

    def pose(self, instance: int, avatar_id: int, pose: int) -> Person:
        """A further person of a scene: grounded if the scene has a floor, with its
        footprint."""
        return self.person(instance, avatar_id, pose, ground=self.job.cfg.scene.floor,
                           footprint=True)

    def describe(self, frame: int) -> FrameDescription:
        """The frame's description. The first person and the camera come from the frame
        stream exactly as vhgen always drew them; room, further people and props from the
        scene stream (see :class:`FrameDescription`)."""
        job, plan = self.job, self.job.plan
        seed = int(plan.seeds[frame])
        rng = np.random.default_rng(seed)
        sc = job.cfg.scene
        person = self.person(1, int(plan.avatar_id[frame]), int(plan.pose_index[frame]),
                             ground=sc.floor, footprint=not sc.is_person_only)
        if job.backgrounds is not None:
            return self._on_background(frame, seed, rng, person)
        if sc.layout_frames > 1 and not sc.is_person_only:  # the layout's camera
            skip_camera(rng, job.cfg.camera)
        else:
            cam = sample_camera(rng, job.cfg.camera)
        noise_state = rng.bit_generator.state
        if sc.is_person_only:
            return FrameDescription(frame, seed, cam, (person,), (), None, noise_state)
        srng = np.random.default_rng(np.random.SeedSequence([seed, _SCENE_STREAM]))
        if sc.layout_frames > 1:
            index = frame // sc.layout_frames
            shared = self.shared_layout(index)
            lay = fill_shared(srng, shared, sc, person, self)
            return FrameDescription(frame, seed, shared.camera, lay.people, lay.static,
                                    lay.room, noise_state, lay.props, lay.dropped,
                                    clutter=lay.clutter, no_return=sc.no_return_ids,
                                    layout=index)
        reach = self._reach
        lay = layout_scene(srng, sc, cam, job.cfg.sensor.intrinsics, reach, person, self,
                           redraw=lambda k: np.random.default_rng(
                               np.random.SeedSequence([seed, _SCENE_STREAM, k])),
                           library_seed=job.cfg.seed)
        return FrameDescription(frame, seed, cam, lay.people, lay.static, lay.room,
                                noise_state, lay.props, lay.dropped, clutter=lay.clutter,
                                no_return=sc.no_return_ids)

    @property
    def _reach(self) -> tuple[float, float]:
        """The floor distances from the camera further people stand at."""
        d = self.job.cfg.camera.distance_m
        return (d[0], d[1] + _REACH_BEYOND_M)

    def shared_layout(self, index: int) -> SharedLayout:
        """Layout ``index`` of a job with ``scene.layout_frames`` N > 1, which frames
        index * N .. index * N + N - 1 share: drawn from the seed of its first frame, so
        any frame can be made again alone (the last one is kept: a shard's frames are
        consecutive)."""
        if self._shared is not None and self._shared[0] == index:
            return self._shared[1]
        job = self.job
        first_seed = int(job.plan.seeds[index * job.cfg.scene.layout_frames])

        def stream(*k: int) -> np.random.Generator:
            return np.random.default_rng(np.random.SeedSequence([first_seed,
                                                                 _SHARED_STREAM, *k]))

        rng = stream()
        cam = sample_camera(rng, job.cfg.camera)
        shared = layout_shared(rng, job.cfg.scene, cam, job.cfg.sensor.intrinsics,
                               self._reach, self, redraw=stream,
                               library_seed=job.cfg.seed)
        self._shared = (index, shared)
        return shared

    def _on_background(self, frame: int, seed: int, rng: np.random.Generator,
                       person: Person) -> FrameDescription:
        """A frame composited into one of the job's real backgrounds: the camera is the
        background's (none is drawn; the sensor noise starts from the frame stream as
        it is), the background and the people's places come from the scene stream
        (:func:`vhgen.scene.background.people.layout_background`), the people stand
        ``camera.distance_m`` from the camera."""
        job = self.job
        assert job.backgrounds is not None
        srng = np.random.default_rng(np.random.SeedSequence([seed, _SCENE_STREAM]))
        bg = layout_background(srng, job.cfg.scene, job.backgrounds,
                               job.cfg.sensor.intrinsics, job.cfg.camera.distance_m, person,
                               self)
        return FrameDescription(frame, seed, bg.camera, bg.people, (), None,
                                rng.bit_generator.state, (), bg.dropped, bg.background,
                                bg.planned)
