"""Driver side, once per job: read the motions, retarget, select poses.

A bad file is reported and skipped; it never stops the corpus.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.body.skinning import posed_heads
from vhgen.config import BUILTIN_MOTION, PosesConfig
from vhgen.errors import ConfigError, VhgenError
from vhgen.mocap.bvh import read_bvh
from vhgen.mocap.posetable import read_pose_table
from vhgen.mocap.retarget import (
    RetargetMap,
    build_retargeter,
    detect_dialect,
    mapping_report,
    world_rotations,
)

log = logging.getLogger(__name__)


def builtin_motion_path() -> Path:
    return Path(str(resources.files("vhgen").joinpath("data", "demo_cmu_mb.bvh")))


def expand_motion_paths(specs: tuple[str, ...] | list[str]) -> list[tuple[str, Path]]:
    """(name, path) of every motion file: folders are searched recursively for *.bvh
    (case-insensitive) and sorted. The name is the path, or ``builtin:demo`` for the
    package's demo clip (so manifests do not depend on where vhgen is installed)."""
    out: list[tuple[str, Path]] = []
    for s in specs:
        if s == BUILTIN_MOTION:
            out.append((BUILTIN_MOTION, builtin_motion_path()))
            continue
        p = Path(s)
        if p.is_dir():
            found = sorted(q for q in p.rglob("*") if q.suffix.lower() == ".bvh" and q.is_file())
            if not found:
                raise ConfigError(None, "motions", f"folder {p} holds no .bvh files")
            out.extend((str(q), q) for q in found)
        elif p.is_file():
            out.append((str(p), p))
        else:
            raise ConfigError(None, "motions", f"{p} does not exist")
    return out


@dataclass
class PoseSet:
    """Poses on the target rig, all clips concatenated (float64).

    rotations (P, B, 3, 3) world skinning rotations; roots (P, 3) root head positions with
    the clip grounded (its feet on y = 0); motion_id (P,), source_frame (P,).
    """

    rotations: np.ndarray
    roots: np.ndarray
    motion_id: np.ndarray
    source_frame: np.ndarray
    motion_files: list[str]
    motion_sha1: list[str]
    report: list[dict] = field(default_factory=list)

    @property
    def num_poses(self) -> int:
        return int(self.rotations.shape[0])


def select_frames(num_frames: int, cfg: PosesConfig) -> np.ndarray:
    idx = np.arange(cfg.skip_first, num_frames, cfg.frame_step)
    if cfg.max_per_motion and len(idx) > cfg.max_per_motion:
        idx = idx[np.linspace(0, len(idx) - 1, cfg.max_per_motion).round().astype(int)]
    return idx


def ground_offset(rig: Rig, rotations: np.ndarray, roots: np.ndarray) -> float:
    """Vertical shift putting the clip's feet on the floor.

    The lowest bone end of each frame is compared with the rest pose's lowest bone end
    (the toe tip, just above the floor); the clip's 5th percentile of that gap is removed,
    so standing frames touch the floor while jumps stay in the air.
    """
    heads = posed_heads(rig, rotations, roots)
    tails = heads + np.einsum("...bij,bj->...bi", rotations, rig.tails - rig.heads)
    low = np.minimum(heads[..., 1].min(-1), tails[..., 1].min(-1))
    rest_low = min(rig.heads[:, 1].min(), rig.tails[:, 1].min())
    return float(rest_low - np.percentile(low, 5))


def load_poses(specs, rig: Rig, rmap: RetargetMap | list[RetargetMap],
               cfg: PosesConfig) -> PoseSet:
    """Read every motion, retarget onto ``rig`` and keep the selected frames.

    ``rmap`` is one map, or a list of maps to pick from per file (dialect detection).
    """
    rots, roots, mids, frames, files, shas, report = [], [], [], [], [], [], []
    for name, path in expand_motion_paths(specs):
        entry = {"file": name, "status": "ok", "frames": 0, "poses": 0, "dialect": "",
                 "error": ""}
        report.append(entry)
        if path.suffix.lower() == ".parquet":
            # a pose table from `vhgen corpus build`: already retargeted and sparsified
            try:
                table = read_pose_table(path)
            except VhgenError as e:
                entry.update(status="skipped", error=str(e))
                log.warning("skipping %s: %s", path, e)
                continue
            if table.bones != list(rig.names):
                entry.update(status="skipped", error=f"pose table rig {table.rig} has other "
                                                     "bones than the job's rig")
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
            entry.update(frames=table.num_poses, poses=table.num_poses, dialect="pose-table")
            continue
        try:
            motion = read_bvh(path)
            entry["frames"] = motion.num_frames
            m = detect_dialect(motion, rmap) if isinstance(rmap, list) else rmap
            entry["dialect"] = m.name
            rt = build_retargeter(motion, rig, m)
            entry.update(mapping_report(m, rt))
            r_all, p_all = rt.apply(motion)
        except VhgenError as e:
            entry.update(status="skipped", error=str(e))
            log.warning("skipping %s: %s", path, e)
            continue
        p_all = p_all.copy()
        p_all[:, 1] += ground_offset(rig, r_all, p_all)
        sel = select_frames(motion.num_frames, cfg)
        if len(sel) == 0:
            entry.update(status="skipped", error="no frame selected")
            continue
        mid = len(files)
        files.append(name)
        shas.append(hashlib.sha1(path.read_bytes()).hexdigest())
        rots.append(r_all[sel])
        roots.append(p_all[sel])
        mids.append(np.full(len(sel), mid, dtype=np.int32))
        frames.append(sel.astype(np.int32))
        entry["poses"] = int(len(sel))
    if not files:
        errors = "; ".join(f"{e['file']}: {e['error']}" for e in report)
        raise VhgenError(f"no usable motion among {len(report)} file(s): {errors}")
    return PoseSet(np.concatenate(rots), np.concatenate(roots), np.concatenate(mids),
                   np.concatenate(frames), files, shas, report)
