"""Frame generation inside one process: describe, render, sensor, record, shard write.

Per frame: :class:`~vhgen.pipeline.describe.FrameDescriber` builds the pure description
from the job's plan, :class:`~vhgen.render.scene_renderer.SceneRenderer` draws its views, the sensor
model runs on the whole scene, and a :class:`~vhgen.store.record.FrameRecord` (the
manifest row) is made from the description and the outputs. With the GL sensor the
frames go to the GPU in batches (``render.batch_frames``), two in flight: the CPU
describes the next batch and reads the last one back while the GPU draws and senses
(:meth:`FrameGenerator.frames`).

:class:`FrameGenerator` owns one GL context (created once, in ``__init__``) and is what a
Ray actor wraps; it is also used directly by tests and benchmarks without Ray.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from vhgen.body.avatar import Body
from vhgen.camera import pitch_roll_deg, project
from vhgen.pipeline.describe import FrameDescriber
from vhgen.pipeline.job import Job
from vhgen.scene.description import FrameDescription, Person
from vhgen.scene.geometry import unpack_ids
from vhgen.scene.truth import joint_visibility
from vhgen.sensor.composite import simulate_over_real
from vhgen.sensor.simulator import FrameSensor, SensorModel, SensorOutput
from vhgen.store.manifest import write_part
from vhgen.store.record import FrameRecord, PersonRecord
from vhgen.store.zarr_store import write_shard

if TYPE_CHECKING:  # the render step is imported lazily (GL); only its types here
    from vhgen.render.renderer import View
    from vhgen.render.sensor_gl import GLSensorModel

log = logging.getLogger(__name__)

__all__ = ["FrameGenerator", "FrameOutput", "ShardResult"]


@dataclass(frozen=True)
class ShardResult:
    """What a worker reports of a shard it wrote: its frames, the GL renderer, the valid
    pixels over its frames, the people and props that found no place (by kind), and the
    seconds it took (render, sensor and write)."""

    shard: int
    frames: int
    renderer: str
    valid_pixels: int
    dropped: dict[str, int]
    seconds: float = 0.0


@dataclass(frozen=True, eq=False)
class FrameOutput:
    """One frame's arrays, (H, W) each: depth uint16 mm, labels / instances / classes
    uint8, raw11 uint16 (or None when the sensor's encoding does not keep it), and the
    manifest record."""

    depth_mm: np.ndarray
    labels: np.ndarray
    instances: np.ndarray
    classes: np.ndarray
    raw11: np.ndarray | None
    record: FrameRecord


class FrameGenerator:
    """Renders frames of one :class:`~vhgen.pipeline.job.Job`. Heavy set-up once (a GL
    context, unless one is given; the sensor model); ``run_task`` per shard.

    bodies : avatar id -> body already built (it only saves work)."""

    def __init__(self, job: Job, context=None, bodies: dict[int, Body] | None = None):
        from vhgen.render.context import create_context
        from vhgen.render.renderer import DepthLabelRenderer
        from vhgen.render.scene_renderer import SceneRenderer

        cfg = job.cfg
        self.job = job
        self.cfg = cfg
        self.describer = FrameDescriber(job, bodies)
        self.ctx = context if context is not None else create_context(cfg.backend)
        self.renderer_info = self.ctx.info.get("GL_RENDERER", "?")
        self.sensor: FrameSensor
        # with sensor.backend gl, the effects as compute passes on this context; they read
        # a frame where it was drawn when nothing was drawn or changed after it
        self.gl_sensor: GLSensorModel | None = None
        if cfg.sensor.backend == "gl":
            from vhgen.render.sensor_gl import GLSensorModel

            self.sensor = self.gl_sensor = GLSensorModel(self.ctx, cfg.sensor)
        else:
            self.sensor = SensorModel(cfg.sensor)
        self.renderer = DepthLabelRenderer(self.ctx, cfg.sensor.intrinsics,
                                           near=cfg.camera.near_m, far=cfg.camera.far_m,
                                           skinning=cfg.skinning,
                                           incidence="incidence" in cfg.sensor.needs,
                                           background=bool(cfg.scene.backgrounds))
        self.scene = SceneRenderer(self.renderer, self.describer.body, cfg.scene.class_id)
        self._sensor_json = json.dumps(cfg.sensor.to_dict(), sort_keys=True)
        # with the GL sensor, frames go to the GPU in batches, two in flight, each read
        # back while the CPU describes the next (not over real backgrounds, composited on
        # the CPU, nor with a projector view, drawn into the same target)
        self.batch = cfg.batch_frames if (
            self.gl_sensor is not None and not cfg.scene.backgrounds
            and "projector_depth" not in cfg.sensor.needs) else 0
        self._staging: list[Any] = [None, None]  # the two batches in flight
        self._host: np.ndarray | None = None  # one frame's slot, read back

    def describe(self, frame: int) -> FrameDescription:
        return self.describer.describe(frame)

    def render(self, desc: FrameDescription) -> FrameOutput:
        """Render, sense and record one described frame."""
        s = self.cfg.sensor
        views = self.scene.render(desc, s.baseline_m if "projector_depth" in s.needs
                                  else None)
        cam = views.camera
        packed = cam.ids  # the sensor moves this one array with the pixels
        if self.gl_sensor is not None and views.in_target:  # no upload
            out = self.gl_sensor.simulate_target(self.renderer, desc.noise_rng(),
                                                 labels_dtype=packed.dtype)
        elif desc.background is None:
            out = self.sensor.simulate(cam.depth, desc.noise_rng(), labels=packed,
                                       incidence=cam.incidence,
                                       projector_depth=views.projector_depth)
        else:  # real pixels keep their measurement where the people change nothing
            bg = desc.background
            out = simulate_over_real(self.sensor, cam.depth, desc.noise_rng(),
                                     real_mm=bg.depth_mm, labels=packed,
                                     real_label=self.cfg.scene.class_id(bg.class_name) << 16,
                                     incidence=cam.incidence)
        return self._output(desc, cam, out)

    def render_frame(self, frame: int) -> FrameOutput:
        """Describe and render frame ``frame`` of the plan."""
        return self.render(self.describe(frame))

    def _person(self, desc: FrameDescription, person: Person, depth: np.ndarray,
                instances: np.ndarray) -> PersonRecord:
        """Per-person truth: provenance, placement, 3D/2D joints, visibility against the
        clean rendered view (before the sensor: its ``depth`` and ``instances``)."""
        w2c = desc.camera.world_to_camera
        joints_cam = person.joints @ w2c[:3, :3].T + w2c[:3, 3]
        intr = self.cfg.sensor.intrinsics
        visible = joint_visibility(intr, joints_cam, person.instance, depth, instances)
        motion_file, _, source_frame = self.job.poses.source(person.pose_index)
        return PersonRecord(
            instance=person.instance, avatar_id=person.avatar_id,
            motion_file=motion_file, source_frame=source_frame,
            pose_index=person.pose_index, placement=person.placement.reshape(-1).tolist(),
            body_offset=person.offset.tolist(),
            joints_cam=joints_cam.astype(np.float32).reshape(-1).tolist(),
            joints_px=np.nan_to_num(project(intr, joints_cam), nan=-1.0).astype(
                np.float32).reshape(-1).tolist(),
            joints_visible=visible.tolist(), visible_fraction=float(visible.mean()),
            footprint=None if person.footprint is None else
            [person.footprint.x, person.footprint.z, person.footprint.r])

    def _record(self, desc: FrameDescription, depth: np.ndarray, instances: np.ndarray,
                holes: dict, valid_pixels: int, labels: np.ndarray) -> FrameRecord:
        person = desc.people[0]
        body = self.describer.body(person.avatar_id)
        w2c = desc.camera.world_to_camera
        joints_cam = (person.joints @ w2c[:3, :3].T + w2c[:3, 3]).astype(np.float32)
        pose = person.pose_index
        motion_file, motion_sha1, source_frame = self.job.poses.source(pose)
        pitch, roll = pitch_roll_deg(w2c)
        intr = self.cfg.sensor.intrinsics
        sc = self.cfg.scene
        scene: dict[str, Any] | None = None if sc.is_person_only else {
            "floor": sc.floor, "room": desc.room.to_dict() if desc.room is not None else None,
            "props": [p.to_dict() for p in desc.props], "dropped": dict(desc.dropped)}
        if scene is not None and sc.clutter is not None:
            scene["clutter"] = [c.to_dict() for c in desc.clutter]
        if scene is not None and desc.layout is not None:
            scene["layout"] = desc.layout
        if scene is not None and desc.background is not None:
            scene["background"] = desc.background.to_dict()
            if desc.planned is not None:  # another person took the plan's place
                scene["planned"] = {"avatar_id": desc.planned[0],
                                    "pose_index": desc.planned[1]}
        return FrameRecord(
            frame=desc.frame, shard=-1,
            motion_file=motion_file, motion_sha1=motion_sha1, source_frame=source_frame,
            pose_index=pose, avatar_id=person.avatar_id,
            avatar_params=json.dumps({**body.params, "skinning": self.cfg.skinning},
                                     sort_keys=True),
            width=intr.width, height=intr.height, fx=intr.fx, fy=intr.fy, cx=intr.cx,
            cy=intr.cy, world_to_camera=w2c.reshape(-1).tolist(),
            camera_distance_m=desc.camera.distance_m, camera_yaw_deg=desc.camera.yaw_deg,
            camera_height_m=desc.camera.height_m, body_offset=person.offset.tolist(),
            joints_cam=joints_cam.reshape(-1).tolist(), seed=desc.seed,
            sensor=self._sensor_json, holes=json.dumps(holes, sort_keys=True),
            valid_pixels=valid_pixels, body_pixels=int((labels > 0).sum()),
            num_people=len(desc.people), scene=json.dumps(scene, sort_keys=True),
            people=[self._person(desc, p, depth, instances) for p in desc.people],
            camera_pitch_deg=pitch, camera_roll_deg=roll)

    def frames(self, start: int, stop: int) -> Iterator[tuple[FrameDescription, FrameOutput]]:
        """Describe and render frames [start, stop), in order: one by one, or with the GL
        sensor in batches (:attr:`batch`), the CPU describing batch k+1 and reading batch
        k-1 back while the GPU works on batch k. The same frames either way."""
        if self.batch <= 0:
            for f in range(start, stop):
                desc = self.describe(f)
                yield desc, self.render(desc)
            return
        from collections import deque

        from vhgen.render.context import gl_flush

        inflight: deque[tuple[int, list[FrameDescription]]] = deque()
        for i, first in enumerate(range(start, stop, self.batch)):
            descs = [self.describe(f) for f in range(first, min(first + self.batch, stop))]
            if len(inflight) == 2:
                yield from self._collect(*inflight.popleft())
            self._submit(i % 2, descs)
            gl_flush(self.ctx)
            inflight.append((i % 2, descs))
        while inflight:
            yield from self._collect(*inflight.popleft())

    def _slot_bytes(self) -> int:
        assert self.gl_sensor is not None
        return 4 * (self.renderer.view_floats + self.gl_sensor.output_words)

    def _submit(self, which: int, descs: list[FrameDescription]) -> None:
        """Draw and sense ``descs`` into staging buffer ``which``, one slot a frame: the
        targets' read-back, then the sensor's outputs. Nothing waits for the GPU."""
        gl = self.gl_sensor
        assert gl is not None
        slot = self._slot_bytes()
        buf = self._staging[which]
        if buf is None or buf.size < slot * len(descs):
            if buf is not None:
                buf.release()
            buf = self._staging[which] = self.ctx.buffer(
                reserve=slot * max(self.batch, len(descs)))
        view_bytes = 4 * self.renderer.view_floats
        for j, desc in enumerate(descs):
            self.scene.submit(desc)
            self.renderer.read_view_into(buf, j * slot)
            gl.queue_target(self.renderer, desc.noise_rng(), buf, j * slot + view_bytes,
                            glass=desc.no_return)

    def _collect(self, which: int, descs: list[FrameDescription]
                 ) -> Iterator[tuple[FrameDescription, FrameOutput]]:
        """Read the frames of staging buffer ``which`` back (waiting for the GPU where it
        is not done) and make their outputs as :meth:`render` does, decoded in one pass
        (:func:`vhgen.render.frame_words.decode`)."""
        from vhgen.render.frame_words import decode

        buf = self._staging[which]
        slot = self._slot_bytes()
        intr = self.cfg.sensor.intrinsics
        h, w, n = intr.height, intr.width, intr.width * intr.height
        if self._host is None or self._host.nbytes != slot:
            self._host = np.empty(slot // 4, np.uint32)
        host = self._host
        floats = host.view(np.float32)
        depth = floats[:n].reshape(h, w)  # the view's, before the sensor
        for j, desc in enumerate(descs):
            buf.read_into(host, size=slot, offset=j * slot)
            d = decode(host[2 * n:], floats[n:2 * n], h, w, self.cfg.sensor.encoding.raw11)
            # window glass has no depth in the view :meth:`render` records, but as no
            # person's pixel it hides their joints with or without it: the same record
            record = self._record(desc, depth, d.view_instances, d.holes, d.valid_pixels,
                                  d.labels)
            yield desc, FrameOutput(d.depth_mm, d.labels, d.instances, d.classes, d.raw11,
                                    record)

    def _output(self, desc: FrameDescription, view: View, out: SensorOutput) -> FrameOutput:
        labels, instances, classes = unpack_ids(out.labels if out.labels is not None
                                                else view.ids)
        return FrameOutput(out.depth_mm, labels, instances, classes, out.raw11,
                           self._record(desc, view.depth, view.instances, out.holes,
                                        int(out.valid.sum()), labels))

    def run_task(self, store: str, shard: int, start: int, stop: int) -> ShardResult:
        """Render frames [start, stop), write shard ``shard`` and its manifest part."""
        t = time.perf_counter()
        h, w = self.cfg.sensor.intrinsics.height, self.cfg.sensor.intrinsics.width
        n = stop - start
        depth = np.zeros((n, h, w), np.uint16)
        ids = {k: np.zeros((n, h, w), np.uint8) for k in ("labels", "instances", "classes")}
        keep_raw = "raw" in self.cfg.arrays  # the config checked that the sensor keeps it
        raw = np.zeros((n, h, w), np.uint16) if keep_raw else None
        records = []
        dropped = {"people": 0, "props": 0}
        for i, (desc, o) in enumerate(self.frames(start, stop)):
            for k, v in desc.dropped.items():
                dropped[k] = dropped.get(k, 0) + v
            depth[i] = o.depth_mm
            ids["labels"][i], ids["instances"][i], ids["classes"][i] = (o.labels, o.instances,
                                                                        o.classes)
            if raw is not None and o.raw11 is not None:
                raw[i] = o.raw11
            records.append(_with_shard(o.record, shard))
        write_shard(store, shard, self.cfg.frames_per_shard, depth, ids["labels"], raw,
                    extra={k: ids[k] for k in ("instances", "classes")
                           if k in self.cfg.arrays})
        num_joints = len(records[0].joints_cam) // 3
        write_part(store, shard, records, num_joints)
        return ShardResult(shard, n, str(self.renderer_info),
                           int(sum(r.valid_pixels for r in records)), dropped,
                           time.perf_counter() - t)

    def close(self) -> None:
        for buf in self._staging:
            if buf is not None:
                buf.release()
        self._staging = [None, None]
        self.scene.release()
        self.renderer.release()
        release = getattr(self.sensor, "release", None)
        if release is not None:  # the GL sensor's buffers and programs
            release()


def _with_shard(record: FrameRecord, shard: int) -> FrameRecord:
    from dataclasses import replace

    return replace(record, shard=shard)
