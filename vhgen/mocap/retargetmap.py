"""Retarget maps and bound retargeters: the data side of :mod:`vhgen.mocap.retarget`.

A :class:`RetargetMap` is a source dialect's joint map onto a target rig (YAML in
``configs/retarget``, or built by :mod:`vhgen.mocap.automap`); a :class:`Retargeter` is a
map bound to one source skeleton and one rig (built by
:func:`vhgen.mocap.retarget.build_retargeter`) and turns frames into target poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.errors import ConfigError
from vhgen.mocap.bvh import Motion
from vhgen.mocap.jointnames import ESSENTIAL
from vhgen.mocap.units import parse_units
from vhgen.yamlio import check_keys, configs_dir, find_config, load_yaml


@dataclass(frozen=True)
class RetargetMap:
    """A source dialect's joint map onto a target rig, as declared in ``configs/retarget``."""

    name: str
    target_rig: str
    units_m: float | None  # metres per file unit; None = detect from the skeleton size
    joints: dict[str, str | None]
    reference_directions: dict[str, tuple[float, float, float]]
    source: str | None = None
    # The file's world up axis (+y for the shipped maps); see :func:`up_rotation`.
    up: str = "+y"
    # None: the zero-rotation rest pose is the reference and only the bones listed in
    # reference_directions are straightened (the shipped maps). A frame number: that
    # frame's posture (world positions, so bone-local OFFSETs do not matter) is the
    # reference, every mapped bone is straightened (onto reference_directions, else onto
    # the target's rest direction) and the root is turned by its body frame (up, left).
    reference_frame: int | None = None
    confidence: float | None = None  # automatic maps: in [0, 1]
    notes: tuple[str, ...] = ()
    reasons: dict[str, str] = field(default_factory=dict)  # per source joint, why

    @classmethod
    def load(cls, name_or_path: str | Path) -> RetargetMap:
        path = find_config("retarget", name_or_path)
        d = load_yaml(path)
        check_keys(d, {"name", "target_rig", "units", "joints", "reference_directions",
                       "description", "up", "reference_frame"},
                   {"name", "target_rig", "joints"}, path, "")
        units = parse_units(d.get("units", "auto"), path, "units")
        joints = d["joints"]
        if not isinstance(joints, dict) or not joints:
            raise ConfigError(path, "joints", "must be a non-empty mapping source -> target")
        for k, v in joints.items():
            if v is not None and not isinstance(v, str):
                raise ConfigError(path, f"joints.{k}", f"target must be a bone name or null, "
                                                       f"got {v!r}")
        refs: dict[str, tuple[float, float, float]] = {}
        for k, v in (d.get("reference_directions") or {}).items():
            arr = np.asarray(v, dtype=np.float64) if isinstance(v, list) else None
            if arr is None or arr.shape != (3,) or not np.isfinite(arr).all() or \
                    np.linalg.norm(arr) == 0:
                raise ConfigError(path, f"reference_directions.{k}",
                                  f"must be a non-zero [x, y, z], got {v!r}")
            refs[k] = (float(arr[0]), float(arr[1]), float(arr[2]))
        up = str(d.get("up", "+y"))
        if up not in UP_ROTATIONS:
            raise ConfigError(path, "up", f"must be one of {', '.join(UP_ROTATIONS)}, "
                                          f"got {d.get('up')!r}")
        ref = d.get("reference_frame")
        if ref is not None and (isinstance(ref, bool) or not isinstance(ref, int) or ref < 0):
            raise ConfigError(path, "reference_frame",
                              f"must be a frame number >= 0 (or absent), got {ref!r}")
        return cls(name=str(d["name"]), target_rig=str(d["target_rig"]), units_m=units,
                   joints=dict(joints), reference_directions=refs, source=str(path), up=up,
                   reference_frame=ref)

    def check_target(self, rig: Rig) -> None:
        """Every bone the map names must exist in the rig."""
        named = {v for v in self.joints.values() if v} | set(self.reference_directions)
        missing = sorted(named - set(rig.names))
        if missing:
            raise ConfigError(self.source, "joints",
                              f"target bones not in rig {self.target_rig}: {', '.join(missing)}")


def load_all_maps(folder: str | Path | None = None) -> list[RetargetMap]:
    """Every map in ``configs/retarget`` (or ``folder``), sorted by name."""
    folder = Path(folder) if folder is not None else configs_dir() / "retarget"
    return [RetargetMap.load(p) for p in sorted(folder.glob("*.yaml"))]


def missing_essentials(rmap: RetargetMap, motion: Motion) -> list[str]:
    """Essential target parts (pelvis, head, legs, arms) that no joint of ``motion`` maps
    to under ``rmap``, in words."""
    mapped = {rmap.joints.get(n) for n in motion.names}
    return [w for b, w in ESSENTIAL.items() if b not in mapped]


UP_ROTATIONS = {
    "+y": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "-y": ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0)),  # 180 deg about X
    "+z": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)),  # -90 deg about X
    "-z": ((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),  # +90 deg about X
    "+x": ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),  # +90 deg about Z
    "-x": ((0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),  # -90 deg about Z
}


def up_rotation(up: str) -> np.ndarray:
    """(3, 3) float64 rotation taking the file's up axis (``+y``, ``-z``...) to +Y; a proper
    rotation, so the skeleton's handedness is kept."""
    return np.array(UP_ROTATIONS[up], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Retargeter:
    """A map bound to one source skeleton and one fitted target rig."""

    rig: Rig
    source_index: np.ndarray  # (B,) source joint per target bone, -1 = none
    source_ref: np.ndarray  # (B, 3, 3) S_b
    target_ref: np.ndarray  # (B, 3, 3) T_b
    scale: float  # metres per source unit, corrected for the skeletons' proportions
    source_root: int
    dialect: str
    units_m: float  # metres per file unit (declared by the map or detected)
    units_detected: bool
    world_fix: np.ndarray = field(default_factory=lambda: np.eye(3))  # file up -> +Y
    # worst angle between a mapped target bone and its source bone in the straightened
    # reference pose (degrees), and that bone
    ref_error_deg: float = 0.0
    ref_error_bone: str = ""

    def apply(self, motion: Motion, frames: np.ndarray | None = None) -> tuple[np.ndarray,
                                                                              np.ndarray]:
        """Target poses for ``frames`` (all by default).

        Returns rotations (F, B, 3, 3) world skinning rotations and root (F, 3) position of
        the root bone's head, float64 metres, in the mesh frame.
        """
        g, p = motion.world_transforms()
        if frames is not None:
            g, p = g[frames], p[frames]
        if not np.array_equal(self.world_fix, np.eye(3)):
            g = self.world_fix @ g
            p = p @ self.world_fix.T
        f = g.shape[0]
        b = len(self.rig.names)
        out = np.empty((f, b, 3, 3), dtype=np.float64)
        corr = np.swapaxes(self.source_ref, -1, -2) @ self.target_ref  # S^T T
        for k in range(b):
            j = self.source_index[k]
            if j >= 0:
                out[:, k] = g[:, j] @ corr[k]
            else:
                par = self.rig.parents[k]
                # no source: keep the rest orientation relative to the parent
                out[:, k] = out[:, par] if par >= 0 else np.eye(3)
        root = p[:, self.source_root] * self.scale
        return out, root


def mapping_report(rmap: RetargetMap, rt: Retargeter) -> dict:
    """Report fields of one file's mapping: how it was chosen, confidence (1.0 for a map
    that names every joint: shipped or given), the straightened reference pose's worst
    bone-direction error and notes (conflicts such as mirrored names)."""
    how = "auto" if rmap.confidence is not None else "map"
    return {"mapping": how, "confidence": 1.0 if rmap.confidence is None else rmap.confidence,
            "up": rmap.up, "reference_frame": rmap.reference_frame,
            "ref_error_deg": round(rt.ref_error_deg, 3), "ref_error_bone": rt.ref_error_bone,
            "notes": list(rmap.notes)}


def reference_error(rig: Rig, source_index: np.ndarray, src: np.ndarray,
                    tgt: np.ndarray) -> tuple[float, str]:
    """Worst angle (degrees) between mapped source and target bone directions (B, 3[, 1])
    in the reference pose, over bones whose source direction is known; and that bone."""
    src = src.reshape(len(rig.names), 3)
    tgt = tgt.reshape(len(rig.names), 3)
    ns, nt = np.linalg.norm(src, axis=1), np.linalg.norm(tgt, axis=1)
    ok = (source_index >= 0) & (ns > 1e-9) & (nt > 1e-12)
    if not ok.any():
        return 0.0, ""
    cos = np.sum(src[ok] * tgt[ok], axis=1) / (ns[ok] * nt[ok])
    ang = np.rad2deg(np.arccos(np.clip(cos, -1.0, 1.0)))
    k = int(np.argmax(ang))
    return float(ang[k]), rig.names[int(np.flatnonzero(ok)[k])]
