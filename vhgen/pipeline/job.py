"""A job, prepared once: everything any worker needs to make any frame of it.

:func:`prepare_job` is the one set-up path from a config to frames: the driver, the
tests, the benchmarks and the forest study all call it, then hand the :class:`Job` whole
to :class:`~vhgen.pipeline.frames.FrameGenerator` (directly, or through a worker).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path

from vhgen.assets import resolve_asset_dir
from vhgen.body.avatar import Body, build_avatar, build_body
from vhgen.body.labels import LabelScheme
from vhgen.job_config import JobConfig
from vhgen.mocap.retarget import RetargetMap, load_all_maps
from vhgen.pipeline.plan import Plan, make_plan
from vhgen.pipeline.poses import PoseSet, load_poses
from vhgen.scene.background.load import Backgrounds, load_backgrounds

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Job:
    """A prepared job (frozen, picklable: it travels to every worker once).

    cfg : the job's config (scene, camera, sensor and output specs).
    asset_dir : the MakeHuman assets the bodies are built from.
    scheme : the body-part label scheme.
    base : the unshaped base body (its rig is the one the poses were retargeted onto).
    poses : every pose, retargeted, with its motion file and source frame.
    plan : every frame's avatar, pose and seed, and the shards.
    backgrounds : the real backgrounds (``scene.backgrounds``: read, floors found, free
        floor mapped), or None.
    """

    cfg: JobConfig
    asset_dir: Path
    scheme: LabelScheme
    base: Body
    poses: PoseSet
    plan: Plan
    backgrounds: Backgrounds | None = None

    @property
    def rig_bones(self) -> list[str]:
        """The rig's bone names (the order of ``joints_cam`` in the manifest)."""
        return list(self.base.rig.names)

    def avatar_body(self, avatar_id: int) -> Body:
        """The shaped body of avatar ``avatar_id`` of the plan (built on every call)."""
        return build_avatar(self.asset_dir, self.scheme, self.plan.avatars[avatar_id])


def prepare_job(cfg: JobConfig, *, max_frames: int | None = None,
                asset_dir: str | Path | None = None) -> Job:
    """Read the real backgrounds (``scene.backgrounds``: floor and free floor of each,
    see :func:`vhgen.scene.background.load.load_backgrounds`; a bad file is one warning line),
    read, retarget and select the poses, build the base body and plan the frames.

    max_frames : only the plan's first N frames (the same frames, seeds and shards as the
        full job). asset_dir : the MakeHuman assets (default: the config's, else the
        fetched ones).
    """
    assets = Path(resolve_asset_dir(cfg.assets) if asset_dir is None else asset_dir)
    backgrounds = None
    if cfg.scene.backgrounds:  # read first (no usable one fails the job at once)
        backgrounds = load_backgrounds(cfg.scene.backgrounds, cfg.sensor.intrinsics,
                                       cfg.camera.distance_m, log.warning, cfg.source)
    scheme = LabelScheme.load(cfg.labels)
    rmap = load_all_maps() if cfg.retarget == "auto" else RetargetMap.load(cfg.retarget)
    base = build_body(assets, scheme)
    poses = load_poses(cfg.motions, base.rig, rmap, cfg.poses, cfg.seed)
    plan = make_plan(cfg.seed, poses.num_poses, cfg.avatars, cfg.frames_per_shard)
    if max_frames is not None and max_frames < plan.num_frames:
        plan = _truncate(plan, max_frames)
    return Job(cfg, assets, scheme, base, poses, plan, backgrounds)


def _truncate(plan: Plan, n: int) -> Plan:
    """The first ``n`` frames of a plan (the same frames, seeds and shards as the full job)."""
    tasks = [replace(t, stop=min(t.stop, n)) for t in plan.tasks if t.start < n]
    return replace(plan, num_frames=n, avatar_id=plan.avatar_id[:n],
                   pose_index=plan.pose_index[:n], seeds=plan.seeds[:n], tasks=tasks)
