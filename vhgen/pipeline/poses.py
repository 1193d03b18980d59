"""Driver side, once per job: read the motions, retarget, select poses.

Clips come through :func:`vhgen.mocap.clips.load_clip` (one report format with
``vhgen corpus build``); a bad file is reported and skipped; it never stops the corpus.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.errors import VhgenError
from vhgen.job_config import PosesConfig
from vhgen.mocap.bend import bend_forward, choose_bends
from vhgen.mocap.clips import ClipFailure, ClipReport, expand_motion_paths, load_clip
from vhgen.mocap.posetable import read_pose_table
from vhgen.mocap.retarget import RetargetMap, world_rotations

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class PoseSet:
    """Poses on the target rig, all clips concatenated (float64).

    rotations (P, B, 3, 3) world skinning rotations; roots (P, 3) root head positions with
    the clip grounded (its feet on y = 0); motion_id (P,) index into ``motion_files`` and
    ``motion_sha1``; source_frame (P,) the frame of the motion file each pose came from;
    bend_deg (P,) how far each pose was turned forward at the hips (:mod:`vhgen.mocap.bend`;
    0: as captured), None without ``poses.bend``.
    """

    rotations: np.ndarray
    roots: np.ndarray
    motion_id: np.ndarray
    source_frame: np.ndarray
    motion_files: list[str]
    motion_sha1: list[str]
    report: list[dict[str, Any]] = field(default_factory=list)  # ClipReport.to_dict()
    bend_deg: np.ndarray | None = None  # (P,) degrees each pose was turned (poses.bend)

    @property
    def num_poses(self) -> int:
        return int(self.rotations.shape[0])

    def source(self, pose: int) -> tuple[str, str, int]:
        """(motion file, its sha1, source frame) of pose ``pose``."""
        mid = int(self.motion_id[pose])
        return self.motion_files[mid], self.motion_sha1[mid], int(self.source_frame[pose])


def load_poses(specs, rig: Rig, rmap: RetargetMap | list[RetargetMap],
               cfg: PosesConfig, seed: int = 0) -> PoseSet:
    """Read every motion, retarget onto ``rig`` and keep the selected frames; with
    ``poses.bend``, bend a share of them forward (drawn from the job's ``seed``).

    ``rmap`` is one map, or a list of maps to pick from per file (dialect detection).
    """
    rots, roots, mids, frames, files, shas = [], [], [], [], [], []
    report: list[ClipReport] = []
    for name, path in expand_motion_paths(specs):
        if path.suffix.lower() == ".parquet":
            # a pose table from `vhgen corpus build`: already retargeted and sparsified
            entry = ClipReport(file=name, dialect="pose-table")
            report.append(entry)
            try:
                table = read_pose_table(path)
            except VhgenError as e:
                entry.status, entry.error = "skipped", str(e)
                log.warning("skipping %s: %s", path, e)
                continue
            if table.bones != list(rig.names):
                entry.status = "skipped"
                entry.error = f"pose table rig {table.rig} has other bones than the job's rig"
                continue
            sha = hashlib.sha1(path.read_bytes()).hexdigest()
            for src in dict.fromkeys(table.source_file):
                rows = np.flatnonzero(np.asarray(table.source_file) == src)
                files.append(src)
                shas.append(sha)
                rots.append(world_rotations(rig, table.local_rotations[rows]))
                roots.append(table.root_translation[rows])
                mids.append(np.full(len(rows), len(files) - 1, dtype=np.int32))
                frames.append(table.source_frame[rows])
            entry.frames = entry.poses_read = entry.poses_kept = table.num_poses
            continue
        clip = load_clip(name, path, rig, rmap, frame_step=cfg.frame_step,
                         skip_first=cfg.skip_first, max_poses=cfg.max_per_motion)
        report.append(clip.report)
        if isinstance(clip, ClipFailure):
            log.warning("skipping %s: %s", path, clip.report.error)
            continue
        files.append(name)
        shas.append(hashlib.sha1(path.read_bytes()).hexdigest())
        rots.append(clip.rotations)
        roots.append(clip.roots)
        mids.append(np.full(len(clip.source_frames), len(files) - 1, dtype=np.int32))
        frames.append(clip.source_frames)
    if not files:
        errors = "; ".join(f"{e.file}: {e.error}" for e in report)
        raise VhgenError(f"no usable motion among {len(report)} file(s): {errors}")
    rot, root = np.concatenate(rots), np.concatenate(roots)
    bend = None
    if cfg.bend_share > 0:
        bend = choose_bends(len(rot), cfg.bend_share, cfg.bend_degrees, seed)
        bent = np.flatnonzero(bend)
        rot[bent], root[bent], bend[bent] = bend_forward(rig, rot[bent], root[bent],
                                                         bend[bent])
    return PoseSet(rot, root, np.concatenate(mids), np.concatenate(frames), files, shas,
                   [e.to_dict() for e in report], bend)
