"""Frame generation inside one process: body, skinning, rendering, sensor, shard write.

:class:`FrameGenerator` owns one GL context (created once, in ``__init__``) and is what a
Ray actor wraps; it is also used directly by tests and benchmarks without Ray.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.body.labels import LabelScheme
from vhgen.body.model import Body, build_body
from vhgen.body.shape import Shape
from vhgen.body.skinning import bone_matrices, posed_heads
from vhgen.camera import look_at
from vhgen.config import JobConfig
from vhgen.sensor.model import SensorModel
from vhgen.store.manifest import write_part
from vhgen.store.zarr_store import write_shard

log = logging.getLogger(__name__)


def sample_camera(rng: np.random.Generator, cfg) -> dict:
    """Camera placement around the subject's root (first draws of the frame's stream)."""
    yaw = rng.uniform(*cfg.yaw_deg)
    dist = rng.uniform(*cfg.distance_m)
    height = rng.uniform(*cfg.height_m)
    target_h = rng.uniform(*cfg.look_at_height_m)
    a = np.deg2rad(yaw)
    eye = np.array([dist * np.sin(a), height, dist * np.cos(a)])
    w2c = look_at(eye, np.array([0.0, target_h, 0.0]))
    return {"yaw_deg": float(yaw), "distance_m": float(dist), "height_m": float(height),
            "world_to_camera": w2c}


class FrameGenerator:
    """Renders frames of one job. Heavy setup once; ``run_task`` per shard."""

    def __init__(self, cfg: JobConfig, asset_dir: str | Path, pose_rotations: np.ndarray,
                 pose_roots: np.ndarray, pose_meta: dict, plan_arrays: dict, avatars: list[dict],
                 context=None):
        from vhgen.render.context import create_context
        from vhgen.render.renderer import DepthLabelRenderer

        self.cfg = cfg
        self.asset_dir = Path(asset_dir)
        self.rotations = pose_rotations
        self.roots = pose_roots
        self.pose_meta = pose_meta
        self.plan = plan_arrays
        self.avatars = avatars
        self.scheme = LabelScheme.load(cfg.labels)
        self.ctx = context if context is not None else create_context(cfg.backend)
        self.renderer_info = self.ctx.info.get("GL_RENDERER", "?")
        self.sensor = SensorModel(cfg.sensor)
        self.renderer = DepthLabelRenderer(self.ctx, cfg.sensor.intrinsics,
                                           near=cfg.camera.near_m, far=cfg.camera.far_m,
                                           skinning=cfg.skinning,
                                           normals="normals" in cfg.sensor.needs)
        self._avatar: tuple[int, Body] | None = None
        # poses were retargeted onto the unshaped base body; an avatar's root height
        # scales with its hip height so its feet stay on the floor
        self._base_hip_drop = build_body(self.asset_dir, self.scheme).hip_drop
        self._sensor_json = json.dumps(cfg.sensor.to_dict(), sort_keys=True)

    def _body(self, avatar_id: int) -> Body:
        """The avatar's body, uploaded to the GPU (one avatar resident at a time)."""
        if self._avatar is None or self._avatar[0] != avatar_id:
            params = self.avatars[avatar_id]
            body = build_body(self.asset_dir, self.scheme, shape=Shape.from_dict(params["shape"]),
                              scale=params["scale"], clothing=tuple(params["clothing"]))
            self.renderer.set_mesh(body.vertices, body.faces, body.joints, body.weights,
                                   body.face_labels, body.num_bones)
            self._avatar = (avatar_id, body)
        return self._avatar[1]

    def render_frame(self, frame: int) -> tuple[np.ndarray, np.ndarray, dict[str, Any],
                                                np.ndarray | None]:
        """depth (H, W) uint16 mm, labels (H, W) uint8, the frame's manifest row, and the
        raw 11-bit image (H, W) uint16 when the sensor's encoding keeps it (else None)."""
        avatar_id = int(self.plan["avatar_id"][frame])
        pose = int(self.plan["pose_index"][frame])
        seed = int(self.plan["seeds"][frame])
        rng = np.random.default_rng(seed)
        body = self._body(avatar_id)
        rot = self.rotations[pose]
        root = self.roots[pose] * (body.hip_drop / self._base_hip_drop)
        # place the subject's root above the world origin; keep height and orientation
        offset = np.array([-root[0], 0.0, -root[2]])
        root = root + offset
        mats = bone_matrices(body.rig, rot, root)
        cam = sample_camera(rng, self.cfg.camera)
        w2c = cam["world_to_camera"]
        s = self.cfg.sensor
        depth_f, labels = self.renderer.render(w2c @ mats)
        normals = self.renderer.normals if self.renderer.want_normals else None
        proj = None
        if "projector_depth" in s.needs:
            # the projector sits at +baseline along the camera's x axis (rectified rig)
            w2p = w2c.copy()
            w2p[0, 3] -= s.baseline_m
            proj, _ = self.renderer.render(w2p @ mats)
        out = self.sensor.simulate(depth_f, rng, labels=labels, normals=normals,
                                   projector_depth=proj)
        depth_mm, valid = out.depth_mm, out.valid
        if out.labels is not None:  # moved with the pixels by geometric effects
            labels = out.labels
        heads = posed_heads(body.rig, rot, root)
        joints_cam = (heads @ w2c[:3, :3].T + w2c[:3, 3]).astype(np.float32)
        mid = int(self.pose_meta["motion_id"][pose])
        intr = s.intrinsics
        row = {
            "frame": frame, "shard": -1,
            "motion_file": self.pose_meta["motion_files"][mid],
            "motion_sha1": self.pose_meta["motion_sha1"][mid],
            "source_frame": int(self.pose_meta["source_frame"][pose]),
            "pose_index": pose, "avatar_id": avatar_id,
            "avatar_params": json.dumps({**body.params, "skinning": self.cfg.skinning},
                                        sort_keys=True),
            "width": intr.width, "height": intr.height, "fx": intr.fx, "fy": intr.fy,
            "cx": intr.cx, "cy": intr.cy,
            "world_to_camera": w2c.reshape(-1).tolist(),
            "camera_distance_m": cam["distance_m"], "camera_yaw_deg": cam["yaw_deg"],
            "camera_height_m": cam["height_m"],
            "body_offset": offset.tolist(),
            "joints_cam": joints_cam.reshape(-1).tolist(),
            "seed": seed,
            "sensor": self._sensor_json,
            "holes": json.dumps(out.holes, sort_keys=True),
            "valid_pixels": int(valid.sum()), "body_pixels": int((labels > 0).sum()),
        }
        return depth_mm, labels, row, out.raw11

    def run_task(self, store: str, shard: int, start: int, stop: int) -> dict:
        """Render frames [start, stop), write shard ``shard`` and its manifest part."""
        h, w = self.cfg.sensor.intrinsics.height, self.cfg.sensor.intrinsics.width
        depth = np.zeros((stop - start, h, w), np.uint16)
        labels = np.zeros((stop - start, h, w), np.uint8)
        raw = None  # allocated if the sensor's encoding keeps raw11 (the model decides)
        rows = []
        for i, f in enumerate(range(start, stop)):
            depth[i], labels[i], row, r11 = self.render_frame(f)
            if r11 is not None:
                if raw is None:
                    raw = np.zeros((stop - start, h, w), np.uint16)
                raw[i] = r11
            row["shard"] = shard
            rows.append(row)
        write_shard(store, shard, self.cfg.frames_per_shard, depth, labels, raw)
        num_joints = len(rows[0]["joints_cam"]) // 3
        write_part(store, shard, rows, num_joints)
        return {"shard": shard, "frames": stop - start, "renderer": self.renderer_info,
                "valid_pixels": int(sum(r["valid_pixels"] for r in rows))}

    def close(self) -> None:
        self.renderer.release()
