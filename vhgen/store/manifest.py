"""The per-frame manifest: one Parquet row per frame, written as one part per shard."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from vhgen.errors import StoreError
from vhgen.store.zarr_store import MANIFEST_FILE, MANIFEST_PARTS


def manifest_schema(num_joints: int):
    import pyarrow as pa

    return pa.schema([
        ("frame", pa.int64()),
        ("shard", pa.int32()),
        ("motion_file", pa.string()),
        ("motion_sha1", pa.string()),
        ("source_frame", pa.int32()),
        ("pose_index", pa.int64()),
        ("avatar_id", pa.int32()),
        ("avatar_params", pa.string()),  # JSON
        ("width", pa.int32()),
        ("height", pa.int32()),
        ("fx", pa.float64()),
        ("fy", pa.float64()),
        ("cx", pa.float64()),
        ("cy", pa.float64()),
        ("world_to_camera", pa.list_(pa.float64(), 16)),  # row-major 4x4, OpenCV camera
        ("camera_distance_m", pa.float64()),
        ("camera_yaw_deg", pa.float64()),
        ("camera_height_m", pa.float64()),
        ("body_offset", pa.list_(pa.float64(), 3)),  # added to the retargeted pose
        ("joints_cam", pa.list_(pa.float32(), 3 * num_joints)),  # bone heads, camera frame
        ("seed", pa.uint64()),
        ("sensor", pa.string()),  # JSON: sensor name, intrinsics, effects applied in order
        ("holes", pa.string()),  # JSON: pixels without measurement, by cause
        ("valid_pixels", pa.int32()),
        ("body_pixels", pa.int32()),
    ])


def write_part(store: str | Path, shard: int, rows: list[dict], num_joints: int) -> Path:
    """Write a shard's rows atomically (temp file + rename)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = manifest_schema(num_joints)
    cols = {f.name: [r[f.name] for r in rows] for f in schema}
    table = pa.table(cols, schema=schema)
    out = Path(store) / MANIFEST_PARTS / f"part-{shard:06d}.parquet"
    tmp = out.with_suffix(".tmp")
    pq.write_table(table, tmp, compression="zstd")
    os.replace(tmp, out)
    return out


def merge_parts(store: str | Path, num_frames: int) -> Path:
    """Concatenate the parts into ``manifest.parquet``; check every frame appears once."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    parts = sorted((Path(store) / MANIFEST_PARTS).glob("part-*.parquet"))
    if not parts:
        raise StoreError(f"{store}: no manifest parts")
    table = pa.concat_tables([pq.read_table(p) for p in parts]).sort_by("frame")
    frames = table.column("frame").to_numpy()
    if len(frames) != num_frames or not np.array_equal(frames, np.arange(num_frames)):
        dup = len(frames) - len(np.unique(frames))
        missing = num_frames - len(np.unique(frames))
        raise StoreError(f"{store}: manifest has {len(frames)} rows for {num_frames} frames "
                         f"({dup} duplicated, {missing} missing)")
    out = Path(store) / MANIFEST_FILE
    tmp = out.with_suffix(".tmp")
    pq.write_table(table, tmp, compression="zstd")
    os.replace(tmp, out)
    return out


def read_manifest(store: str | Path):
    import pyarrow.parquet as pq

    path = Path(store) / MANIFEST_FILE
    if not path.is_file():
        raise StoreError(f"{store}: no {MANIFEST_FILE} (job not finished?)")
    return pq.read_table(path)
