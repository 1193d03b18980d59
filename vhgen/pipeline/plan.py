"""Task planning, pure: the frame list, each frame's seed, and the shards.

Frames are ordered avatar-major (all poses for avatar 0, then avatar 1, ...). Task k
writes shard k: frames [k*S, (k+1)*S). Everything here is a function of the config and
the pose set, so it is identical whatever the number of workers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vhgen.body.avatar import AvatarParams
from vhgen.job_config import AvatarConfig

_AVATAR_STREAM = 0xA7A7
_FRAME_STREAM = 0xF7A3


def frame_seed(job_seed: int, avatar_id: int, pose_index: int, camera: int = 0) -> int:
    """The 64-bit seed of one frame, from (job seed, avatar, pose, camera)."""
    ss = np.random.SeedSequence([job_seed, _FRAME_STREAM, avatar_id, pose_index, camera])
    return int(ss.generate_state(1, dtype=np.uint64)[0])


def avatar_params(job_seed: int, avatar_id: int, cfg: AvatarConfig) -> AvatarParams:
    """Parameters of one avatar (shape, scale, clothing, and its outfit when the config
    has ``avatars.outfit``), drawn from its own seeded stream; the body is rebuilt from
    them exactly (:func:`vhgen.body.avatar.build_avatar`)."""
    rng = np.random.default_rng(np.random.SeedSequence([job_seed, _AVATAR_STREAM, avatar_id]))
    shape = cfg.shape.sample(rng)
    scale = float(rng.uniform(*cfg.scale))
    clothing = [c for c, p in (("tights", cfg.tights_probability),
                               ("skirt", cfg.skirt_probability)) if rng.uniform() < p]
    # drawn after the rest: configs without an outfit keep their avatars
    outfit = cfg.outfit.sample(rng) if cfg.outfit.enabled else None
    return AvatarParams(shape, scale, tuple(clothing), outfit)


@dataclass(frozen=True)
class Task:
    """One shard: frames [start, stop)."""

    shard: int
    start: int
    stop: int


@dataclass(frozen=True, eq=False)
class Plan:
    num_frames: int
    frames_per_shard: int
    avatar_id: np.ndarray  # (N,)
    pose_index: np.ndarray  # (N,)
    seeds: np.ndarray  # (N,) uint64
    avatars: list[AvatarParams]
    tasks: list[Task]


def make_plan(job_seed: int, num_poses: int, avatars: AvatarConfig,
              frames_per_shard: int) -> Plan:
    n = avatars.count * num_poses
    avatar_id = np.repeat(np.arange(avatars.count, dtype=np.int32), num_poses)
    pose_index = np.tile(np.arange(num_poses, dtype=np.int64), avatars.count)
    seeds = np.array([frame_seed(job_seed, int(a), int(p)) for a, p in
                      zip(avatar_id, pose_index, strict=True)], dtype=np.uint64)
    params = [avatar_params(job_seed, a, avatars) for a in range(avatars.count)]
    tasks = [Task(k, s, min(s + frames_per_shard, n))
             for k, s in enumerate(range(0, n, frames_per_shard))]
    return Plan(n, frames_per_shard, avatar_id, pose_index, seeds, params, tasks)
