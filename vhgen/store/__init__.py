"""Dataset stores: Zarr v3 arrays and the Parquet manifest (no GL, no Ray)."""

from vhgen.store.manifest import merge_parts, read_manifest, write_part
from vhgen.store.zarr_store import (
    CONTRACT_VERSION,
    completed_shards,
    create_store,
    open_store,
    write_shard,
)

__all__ = ["CONTRACT_VERSION", "completed_shards", "create_store", "merge_parts", "open_store",
           "read_manifest", "write_part", "write_shard"]
