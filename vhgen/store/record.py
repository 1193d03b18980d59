"""The frame record: one manifest row per frame. Its fields ARE the manifest schema
(:func:`vhgen.store.manifest.manifest_schema` reads them), so a column is named once."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from typing import Any


def _col(kind: str, doc: str = ""):
    """A manifest column of Arrow type ``kind`` (see ``manifest._ARROW``)."""
    return field(metadata={"arrow": kind, "doc": doc})


@dataclass(frozen=True)
class FrameRecord:
    """One frame's ground truth and provenance (the columns' meaning is the contract)."""

    frame: int = _col("int64")
    shard: int = _col("int32")
    motion_file: str = _col("string")
    motion_sha1: str = _col("string")
    source_frame: int = _col("int32")
    pose_index: int = _col("int64")
    avatar_id: int = _col("int32")
    avatar_params: str = _col("string", "JSON")
    width: int = _col("int32")
    height: int = _col("int32")
    fx: float = _col("float64")
    fy: float = _col("float64")
    cx: float = _col("float64")
    cy: float = _col("float64")
    world_to_camera: list[float] = _col("float64x16", "row-major 4x4, OpenCV camera")
    camera_distance_m: float = _col("float64")
    camera_yaw_deg: float = _col("float64")
    camera_height_m: float = _col("float64")
    body_offset: list[float] = _col("float64x3", "added to the retargeted pose")
    joints_cam: list[float] = _col("float32xJ3", "bone heads, camera frame, metres")
    seed: int = _col("uint64")
    sensor: str = _col("string", "JSON: sensor name, intrinsics, effects applied in order")
    holes: str = _col("string", "JSON: pixels without measurement, by cause")
    valid_pixels: int = _col("int32")
    body_pixels: int = _col("int32", "pixels with label > 0")
    num_people: int = _col("int32", "people in the frame; instance k = k-th person")
    scene: str = _col("string", "JSON: floor, room corners/height/yaw (null = none)")

    def to_row(self) -> dict[str, Any]:
        return asdict(self)


def columns() -> list[tuple[str, str]]:
    """(name, arrow kind) of every manifest column, in order."""
    return [(f.name, f.metadata["arrow"]) for f in fields(FrameRecord)]
