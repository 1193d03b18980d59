"""The frame record: one manifest row per frame. Its fields ARE the manifest schema
(:func:`vhgen.store.manifest.manifest_schema` reads them), so a column is named once."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any


def _col(kind: str, doc: str = ""):
    """A manifest column of Arrow type ``kind`` (see ``manifest._ARROW``)."""
    return field(metadata={"arrow": kind, "doc": doc})


@dataclass(frozen=True)
class PersonRecord:
    """One person of a frame (the ``people`` column holds one per person, in instance
    order: person k has value k in ``instances``)."""

    instance: int = _col("int32")
    avatar_id: int = _col("int32")
    motion_file: str = _col("string")
    source_frame: int = _col("int32")
    pose_index: int = _col("int64")
    placement: list[float] = _col("float64x16", "row-major 4x4 world transform applied "
                                  "after body_offset (identity for person 1)")
    body_offset: list[float] = _col("float64x3")
    joints_cam: list[float] = _col("float32xJ3", "bone heads, camera frame, metres")
    joints_px: list[float] = _col("float32xJ2", "(u, v) pixels, pinhole projection of "
                                  "joints_cam with the frame's fx, fy, cx, cy")
    joints_visible: list[bool] = _col("boolxJ", "in the image and not occluded (see "
                                      "vhgen.scene.truth.joint_visibility)")
    visible_fraction: float = _col("float64", "visible joints / joints")
    footprint: list[float] | None = _col("float64[]", "(x, z, radius) metres: the circle "
                                         "on the floor that held the posed body when it "
                                         "was placed; placements keep these apart from "
                                         "each other, the props' and the camera's (null "
                                         "for a person-only frame; a variable-size list "
                                         "of 3, see manifest.MANIFEST_FORM)")


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
    scene: str = _col("string", "JSON: floor, room corners/height/yaw, props, dropped "
                      "(null = person only)")
    people: list[PersonRecord] = _col("people", "one struct per person")
    camera_pitch_deg: float = _col("float64", "optical axis below the horizon, degrees")
    camera_roll_deg: float = _col("float64", "about the optical axis, degrees")

    def to_row(self) -> dict[str, Any]:
        """The row as plain dicts and lists (the people as dicts), for Arrow. Shallow:
        ``dataclasses.asdict`` deep-copies every joint list, ~0.1 ms per person."""
        row = {f.name: getattr(self, f.name) for f in fields(self)}
        row["people"] = [{f.name: getattr(p, f.name) for f in fields(p)} for p in self.people]
        return row


def columns(record: type = FrameRecord) -> list[tuple[str, str]]:
    """(name, arrow kind) of every field of ``record`` (a manifest row, or a person)."""
    return [(f.name, f.metadata["arrow"]) for f in fields(record)]
