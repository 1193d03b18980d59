"""The pose table: kept poses on the target rig, one Parquet row per pose.

Columns: ``source_file`` (string), ``source_frame`` (int32), ``dialect`` (string),
``units_m`` (float64, metres per source unit), ``root_translation`` (3 x float64, metres,
the root bone's head with the clip grounded) and ``local_rotations`` (a fixed-shape tensor
(B, 3, 3) float64: rotation of each bone relative to its parent and to the rest pose,
expressed in world-aligned axes, ``A_parent^T A_b``; the root's is its world rotation).
Schema metadata: ``vhgen.rig`` (name), ``vhgen.bones`` (JSON list, the B axis),
``vhgen.sparsify`` (JSON settings).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.errors import StoreError

FORMAT = "vhgen-pose-table/1"


@dataclass(frozen=True, eq=False)
class PoseTable:
    source_file: list[str]
    source_frame: np.ndarray  # (P,) int32
    dialect: list[str]
    units_m: np.ndarray  # (P,) float64
    root_translation: np.ndarray  # (P, 3) float64
    local_rotations: np.ndarray  # (P, B, 3, 3) float64
    rig: str
    bones: list[str]
    settings: dict

    @property
    def num_poses(self) -> int:
        return int(self.source_frame.shape[0])


def write_pose_table(path: str | Path, table: PoseTable) -> Path:
    import pyarrow as pa
    import pyarrow.parquet as pq

    b = len(table.bones)
    rot_type = pa.fixed_shape_tensor(pa.float64(), (b, 3, 3))
    rot = np.ascontiguousarray(table.local_rotations, dtype=np.float64)
    storage = pa.FixedSizeListArray.from_arrays(pa.array(rot.reshape(-1)), b * 9)
    root = pa.FixedSizeListArray.from_arrays(
        pa.array(np.ascontiguousarray(table.root_translation, np.float64).reshape(-1)), 3)
    meta = {"vhgen.format": FORMAT, "vhgen.rig": table.rig,
            "vhgen.bones": json.dumps(table.bones), "vhgen.sparsify": json.dumps(table.settings)}
    t = pa.table({
        "source_file": pa.array(table.source_file, pa.string()),
        "source_frame": pa.array(table.source_frame, pa.int32()),
        "dialect": pa.array(table.dialect, pa.string()),
        "units_m": pa.array(table.units_m, pa.float64()),
        "root_translation": root,
        "local_rotations": pa.ExtensionArray.from_storage(rot_type, storage),
    }).replace_schema_metadata(meta)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    pq.write_table(t, tmp, compression="zstd", use_dictionary=["source_file", "dialect"],
                   use_byte_stream_split=["units_m", "root_translation", "local_rotations"])
    tmp.replace(path)
    return path


def read_pose_table(path: str | Path) -> PoseTable:
    import pyarrow.parquet as pq

    path = Path(path)
    try:
        t = pq.read_table(path)
    except (OSError, ValueError) as e:
        raise StoreError(f"{path}: not a readable Parquet file ({e})") from None
    meta = {k.decode(): v.decode() for k, v in (t.schema.metadata or {}).items()}
    if meta.get("vhgen.format") != FORMAT:
        raise StoreError(f"{path}: not a vhgen pose table (format "
                         f"{meta.get('vhgen.format')!r}, expected {FORMAT!r})")
    bones = json.loads(meta["vhgen.bones"])
    rot = t.column("local_rotations").combine_chunks()
    rot = np.asarray(rot.storage.flatten(), dtype=np.float64).reshape(-1, len(bones), 3, 3)
    root = np.asarray(t.column("root_translation").combine_chunks().flatten(),
                      dtype=np.float64).reshape(-1, 3)
    return PoseTable(
        source_file=t.column("source_file").to_pylist(),
        source_frame=t.column("source_frame").to_numpy().astype(np.int32),
        dialect=t.column("dialect").to_pylist(),
        units_m=t.column("units_m").to_numpy().astype(np.float64),
        root_translation=root, local_rotations=rot, rig=meta["vhgen.rig"], bones=bones,
        settings=json.loads(meta.get("vhgen.sparsify", "{}")))
