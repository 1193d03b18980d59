"""Stores and the scene arrays: an older store (no instances/classes) is refused clearly
when written to, and the manifest schema is the frame record's fields."""

from __future__ import annotations

import shutil
from dataclasses import fields

import numpy as np
import pytest

from vhgen.errors import StoreError
from vhgen.store.manifest import manifest_schema
from vhgen.store.record import FrameRecord, PersonRecord
from vhgen.store.zarr_store import create_store, open_store, write_shard


def test_old_store_without_scene_arrays(tmp_path):
    create_store(tmp_path / "s.zarr", num_frames=2, height=4, width=6, frames_per_shard=2,
                 compression_level=1, attrs={})
    root = open_store(tmp_path / "s.zarr")
    assert root.attrs["class_names"][:5] == ["background", "floor", "wall", "prop", "person"]
    shutil.rmtree(tmp_path / "s.zarr" / "instances")  # as an older vhgen made it
    z = np.zeros((2, 4, 6), np.uint16)
    u = np.zeros((2, 4, 6), np.uint8)
    with pytest.raises(StoreError, match="no 'instances' array.*older vhgen"):
        write_shard(tmp_path / "s.zarr", 0, 2, z, u, extra={"instances": u, "classes": u})
    with pytest.raises(StoreError, match="classes"):
        write_shard(tmp_path / "s.zarr", 0, 2, z, u, extra={"classes": u[:1]})


def test_manifest_schema_is_the_record():
    schema = manifest_schema(31)
    assert schema.names == [f.name for f in fields(FrameRecord)]
    person = schema.field("people").type.value_type
    assert [person.field(i).name for i in range(person.num_fields)] == [
        f.name for f in fields(PersonRecord)]
    assert schema.field("joints_cam").type.list_size == 93
    assert person.field("joints_px").type.list_size == 62
    assert person.field("joints_visible").type.list_size == 31
