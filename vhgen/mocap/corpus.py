"""Building a pose corpus: many BVH files in parallel -> retarget -> sparsify -> Parquet.

Files are read by :func:`vhgen.mocap.clips.load_clip`; one that fails (grammar, unknown
skeleton, NaN...) is reported (status ``skipped``, with its error text) and the rest of the
corpus goes on.
"""

from __future__ import annotations

import json
import logging
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.assets import resolve_asset_dir
from vhgen.body.mesh import Rig, load_base_mesh, load_rig
from vhgen.body.skinning import posed_heads
from vhgen.errors import VhgenError
from vhgen.mocap.clips import Clip, ClipFailure, expand_motion_paths, load_clip
from vhgen.mocap.posetable import PoseTable, write_pose_table
from vhgen.mocap.retarget import RetargetMap, load_all_maps, local_rotations, world_rotations
from vhgen.mocap.sparsify import remove_heading, sparsify

log = logging.getLogger(__name__)

# Finger and thumb bones: noisy in mocap (CMU thumbs), invisible at Kinect resolution.
DEFAULT_EXCLUDE = ("LeftFingerBase", "LeftHandFinger1", "LThumb", "RightFingerBase",
                   "RightHandFinger1", "RThumb")


@dataclass(frozen=True)
class SparsifySettings:
    metric: str = "angle"  # or "position" (Shotton et al.)
    min_angle_deg: float = 5.0
    min_distance_m: float = 0.05
    exclude: tuple[str, ...] = DEFAULT_EXCLUDE
    keep_heading: bool = False  # False: poses that differ only by facing direction merge
    frame_step: int = 1
    allow_truncated: bool = False  # keep the complete rows of files cut short

    def to_dict(self) -> dict:
        return {"metric": self.metric, "min_angle_deg": self.min_angle_deg,
                "min_distance_m": self.min_distance_m, "exclude": list(self.exclude),
                "keep_heading": self.keep_heading, "frame_step": self.frame_step,
                "allow_truncated": self.allow_truncated}


_WORKER: dict[str, Any] = {}


def _load_rig(asset_dir: str) -> Rig:
    base = load_base_mesh(Path(asset_dir))
    return load_rig(Path(asset_dir), base.vertices, base.vertex_groups)


def _init_worker(asset_dir: str, map_dir: str | None, units_m: float | None,
                 map_file: str | None = None) -> None:
    _WORKER["rig"] = _load_rig(asset_dir)
    # one map for every file (--map), or the shipped maps with automatic mapping
    _WORKER["maps"] = RetargetMap.load(map_file) if map_file else load_all_maps(map_dir)
    _WORKER["units_m"] = units_m


def _process_file(name: str, path: str, frame_step: int, allow_truncated: bool = False
                  ) -> tuple[Clip | ClipFailure, np.ndarray | None]:
    """One file through the clip loader, plus its local rotations (P, B, 3, 3) if usable;
    never raises for bad input."""
    rig = _WORKER["rig"]
    clip = load_clip(name, path, rig, _WORKER["maps"], frame_step=frame_step,
                     allow_truncated=allow_truncated, units_m=_WORKER["units_m"])
    if isinstance(clip, ClipFailure):
        return clip, None
    return clip, local_rotations(rig, clip.rotations)


def build_corpus(inputs: list[str], out: str | Path, *, settings: SparsifySettings,
                 asset_dir: str | Path | None = None, report: str | Path | None = None,
                 workers: int | None = None, units_m: float | None = None,
                 strict: bool = False, map_dir: str | Path | None = None,
                 map_file: str | Path | None = None) -> dict:
    """Read every BVH file under ``inputs``, sparsify all their poses, write the table.

    Returns a summary; raises VhgenError if no pose is usable (or, with ``strict``, if any
    file failed), after writing the report.
    """
    asset_dir = resolve_asset_dir(asset_dir)
    files = expand_motion_paths(list(inputs))
    workers = workers or os.cpu_count() or 1
    init = (str(asset_dir), None if map_dir is None else str(map_dir), units_m,
            None if map_file is None else str(map_file))
    if workers > 1 and len(files) > 1:
        with ProcessPoolExecutor(workers, initializer=_init_worker, initargs=init) as ex:
            results = list(ex.map(_process_file, [n for n, _ in files],
                                  [str(p) for _, p in files],
                                  [settings.frame_step] * len(files),
                                  [settings.allow_truncated] * len(files), chunksize=1))
    else:
        _init_worker(*init)
        results = [_process_file(n, str(p), settings.frame_step, settings.allow_truncated)
                   for n, p in files]
    rig = _WORKER.get("rig")
    if rig is None:  # the files were read in worker processes
        rig = _load_rig(str(asset_dir))
    entries = [c.report for c, _ in results]
    good = [(c, loc) for c, loc in results if isinstance(c, Clip) and loc is not None]
    summary: dict[str, Any] = {"files": len(entries), "ok": len(good),
                               "failed": [e.to_dict() for e in entries if e.status != "ok"]}
    if good:
        local = np.concatenate([loc for _, loc in good])
        root = np.concatenate([c.roots for c, _ in good])
        owner = np.concatenate([np.full(len(c.source_frames), k)
                                for k, (c, _) in enumerate(good)])
        frames = np.concatenate([c.source_frames for c, _ in good])
        keep_bones = [k for k, b in enumerate(rig.names) if b not in settings.exclude]
        if settings.metric == "angle":
            feats = local.copy()
            if not settings.keep_heading:
                root_idx = int(np.flatnonzero(rig.parents < 0)[0])
                feats[:, root_idx] = remove_heading(feats[:, root_idx])
            kept = sparsify(feats[:, keep_bones], np.deg2rad(settings.min_angle_deg), "angle")
        else:
            world = world_rotations(rig, local)
            if not settings.keep_heading:
                root_idx = int(np.flatnonzero(rig.parents < 0)[0])
                head_rm = remove_heading(world[:, root_idx]) @ np.swapaxes(
                    world[:, root_idx], -1, -2)
                world = head_rm[:, None] @ world
            pos = posed_heads(rig, world, np.zeros((len(world), 3)))
            kept = sparsify(pos[:, keep_bones], settings.min_distance_m, "position")
        counts = np.bincount(owner[kept], minlength=len(good))
        for (c, _), n in zip(good, counts, strict=True):
            c.report.poses_kept = int(n)
        table = PoseTable(
            source_file=[good[o][0].report.file for o in owner[kept]],
            source_frame=frames[kept], dialect=[good[o][0].report.dialect for o in owner[kept]],
            units_m=np.array([good[o][0].report.units_m for o in owner[kept]], np.float64),
            root_translation=root[kept], local_rotations=local[kept], rig="cmu_mb",
            bones=list(rig.names), settings=settings.to_dict())
        summary.update(poses_read=int(len(local)), poses_kept=int(len(kept)))
    if report is not None:
        Path(report).parent.mkdir(parents=True, exist_ok=True)
        with open(report, "w") as f:
            json.dump({"settings": settings.to_dict(), "files": [e.to_dict() for e in entries]},
                      f, indent=1)
    if not good:
        raise VhgenError(f"no usable motion among {len(entries)} file(s); see the report")
    if strict and summary["failed"]:
        raise VhgenError(f"{len(summary['failed'])} file(s) failed (--strict); first: "
                         f"{summary['failed'][0]['file']}: {summary['failed'][0]['error']}")
    write_pose_table(out, table)
    summary["table"] = str(out)
    return summary
