"""One clip loader: a motion file -> retargeted, grounded poses, or a typed failure.

``vhgen corpus build`` and ``vhgen generate`` both read clips through :func:`load_clip`
and report every file with the same :class:`ClipReport` fields (in ``report.json``, the
corpus report and the dataset's ``motions`` attribute)::

    file        the motion file (``builtin:demo`` for the packaged demo clip)
    status      "ok" or "skipped" (the file was not used; ``error`` says why)
    frames      frames in the file
    poses_read  poses taken from it (after frame selection)
    poses_kept  poses used (corpus: after sparsification; generate: = poses_read)
    dialect     the retarget map that matched (``pose-table`` for a pose table), ``auto``
                for an automatic mapping (:mod:`vhgen.mocap.automap`)
    units_m     metres per file unit (declared, detected or overridden), null if unknown
    error       the error text, empty when ok
    mapping     "map" (a shipped or given map names every joint) or "auto"
    confidence  of the mapping, in [0, 1] (1 for a map)
    up          the file's world up axis (+y, +z...)
    reference_frame   the frame straightened into the reference pose (null: the rest)
    ref_error_deg, ref_error_bone   worst angle between a mapped target bone and its
                source bone in the straightened reference pose, and that bone
    notes       conflicts settled by geometry (e.g. mirrored left/right names)

A bad file never raises: it comes back as a :class:`ClipFailure` and the caller goes on.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.body.skinning import posed_heads
from vhgen.errors import ConfigError, VhgenError
from vhgen.mocap.bvh import read_bvh
from vhgen.mocap.retarget import RetargetMap, build_retargeter, detect_dialect, mapping_report

BUILTIN_MOTION = "builtin:demo"


def builtin_motion_path() -> Path:
    """The packaged demo clip (CMU motion-builder BVH)."""
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
class ClipReport:
    """One motion file's line in every report (fields in the module docstring)."""

    file: str
    status: Literal["ok", "skipped"] = "ok"
    frames: int = 0
    poses_read: int = 0
    poses_kept: int = 0
    dialect: str = ""
    units_m: float | None = None
    error: str = ""
    mapping: str = ""
    confidence: float | None = None
    up: str = ""
    reference_frame: int | None = None
    ref_error_deg: float | None = None
    ref_error_bone: str = ""
    notes: list[str] = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Clip:
    """Retargeted poses of one file on the target rig (float64).

    rotations (P, B, 3, 3) world skinning rotations; roots (P, 3) root head positions with
    the clip grounded (feet on y = 0); source_frames (P,) int32 frame indices in the file.
    """

    report: ClipReport
    rotations: np.ndarray
    roots: np.ndarray
    source_frames: np.ndarray


@dataclass(frozen=True)
class ClipFailure:
    """A file that could not be used; ``report.error`` says why."""

    report: ClipReport


def ground_offset(rig: Rig, rotations: np.ndarray, roots: np.ndarray) -> float:
    """Vertical shift (m) putting the clip's feet on the floor.

    The lowest bone end of each frame is compared with the rest pose's lowest bone end
    (the toe tip, just above the floor); the clip's 5th percentile of that gap is removed,
    so standing frames touch the floor while jumps stay in the air.
    """
    heads = posed_heads(rig, rotations, roots)
    tails = heads + np.einsum("...bij,bj->...bi", rotations, rig.tails - rig.heads)
    low = np.minimum(heads[..., 1].min(-1), tails[..., 1].min(-1))
    rest_low = min(rig.heads[:, 1].min(), rig.tails[:, 1].min())
    return float(rest_low - np.percentile(low, 5))


def select_frames(num_frames: int, frame_step: int = 1, skip_first: int = 0,
                  max_poses: int = 0) -> np.ndarray:
    """Frame indices: every ``frame_step``-th from ``skip_first``; with ``max_poses`` > 0,
    that many spread evenly over them. (K,) int64."""
    idx = np.arange(skip_first, num_frames, frame_step)
    if max_poses and len(idx) > max_poses:
        idx = idx[np.linspace(0, len(idx) - 1, max_poses).round().astype(int)]
    return idx


def load_clip(name: str, path: str | Path, rig: Rig, maps: RetargetMap | list[RetargetMap], *,
              frame_step: int = 1, skip_first: int = 0, max_poses: int = 0,
              allow_truncated: bool = False, units_m: float | None = None
              ) -> Clip | ClipFailure:
    """Read a BVH file, pick its retarget map, retarget onto ``rig``, ground it, select
    frames (:func:`select_frames`). Never raises for a bad file: returns ClipFailure.

    ``maps``: one map, or a list to detect the dialect from. ``units_m`` overrides the
    units recorded for the file (metres per unit).
    """
    rep = ClipReport(file=name)
    try:
        motion = read_bvh(path, allow_truncated=allow_truncated)
        rep.frames = motion.num_frames
        rmap = detect_dialect(motion, maps) if isinstance(maps, list) else maps
        rep.dialect = rmap.name
        rt = build_retargeter(motion, rig, rmap)
        for k, v in mapping_report(rmap, rt).items():
            setattr(rep, k, v)
        # the root path is scaled from the skeletons' proportions; units are recorded
        rep.units_m = units_m if units_m is not None else rt.units_m
        rot, root = rt.apply(motion)
    except VhgenError as e:
        rep.status, rep.error = "skipped", str(e)
        return ClipFailure(rep)
    root = root.copy()
    root[:, 1] += ground_offset(rig, rot, root)
    sel = select_frames(motion.num_frames, frame_step, skip_first, max_poses)
    if len(sel) == 0:
        rep.status, rep.error = "skipped", "no frame selected"
        return ClipFailure(rep)
    rep.poses_read = rep.poses_kept = int(len(sel))
    return Clip(rep, rot[sel], root[sel], sel.astype(np.int32))
