"""Stores any reader opens (issue 29): the manifest in form 2 (no null inside a fixed-size
list), stores of form 1 still read, and a store read without vhgen: pandas and DuckDB for
the manifest, plain zarr for the arrays.

The floors of the declared dependencies, and pyarrow 18, 21 and 25 reading what the newest
wrote, are checked by ``scripts/check_floors.sh`` (a stage of ``.ci/run``)."""

from __future__ import annotations

import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import vhgen.dataset as vd
from vhgen.store.inspect import inspect_store
from vhgen.store.manifest import manifest_form, read_manifest_table

pytestmark = pytest.mark.slow


def _as_form1(table: pa.Table) -> pa.Table:
    """``table`` (form 2) written as vhgen wrote it before: the footprint a fixed-size list
    of 3, null where there was none."""
    people = table.column("people").combine_chunks()
    inner = people.values
    names = [inner.type.field(k).name for k in range(inner.type.num_fields)]
    arrays = [inner.field(k) for k in range(inner.type.num_fields)]
    k = names.index("footprint")
    fp = arrays[k]
    values = pa.array([v for x in fp.to_pylist() for v in (x or [0.0, 0.0, 0.0])], pa.float64())
    arrays[k] = pa.FixedSizeListArray.from_arrays(values, 3, mask=fp.is_null())
    structs = pa.StructArray.from_arrays(arrays, names=names)
    old = pa.ListArray.from_arrays(people.offsets, structs)
    return table.set_column(table.column_names.index("people"), "people", old)


@pytest.fixture(scope="module")
def room_store(tmp_path_factory, shared_mocap, asset_dir):
    """Four frames of the shipped living_room: people with floor footprints."""
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    out = tmp_path_factory.mktemp("room") / "room.zarr"
    run_job(JobConfig.load("living_room", num_workers=1, backend="osmesa"), out,
            max_frames=4, executor="local")
    return out


def test_person_only_manifest_is_form_2(small_store):
    schema = pq.read_schema(small_store / "manifest.parquet")
    fp = schema.field("people").type.value_type.field("footprint")
    assert pa.types.is_list(fp.type) and not pa.types.is_fixed_size_list(fp.type)
    assert manifest_form(schema) == 2
    people = pq.read_table(small_store / "manifest.parquet").column("people").to_pylist()
    assert all(p["footprint"] is None for row in people for p in row)
    rep = inspect_store(small_store)
    assert rep.ok and rep.manifest_form == 2 and "manifest form 2: portable" in rep.format()


@pytest.mark.parametrize("which", ["person_only", "room"])
def test_form_1_still_reads(which, small_store, room_store, tmp_path, monkeypatch):
    """A store of form 1 reads to the same rows, with pyarrow 26 and (forced here, real in
    check_floors.sh) with a pyarrow that cannot read a null inside a fixed-size list."""
    src = small_store if which == "person_only" else room_store
    store = tmp_path / "old.zarr"
    shutil.copytree(src, store)
    new = pq.read_table(src / "manifest.parquet")
    pq.write_table(_as_form1(new), store / "manifest.parquet", compression="zstd")
    assert manifest_form(pq.read_schema(store / "manifest.parquet")) == 1
    rows = new.to_pylist()
    footprints = [p["footprint"] for r in rows for p in r["people"]]
    assert (which == "room") == all(f is not None and len(f) == 3 for f in footprints)
    assert read_manifest_table(store / "manifest.parquet").to_pylist() == rows
    ds = vd.open(store)
    assert ds[1]["manifest"]["people"] == vd.open(src)[1]["manifest"]["people"]
    rep = inspect_store(store)
    assert rep.ok and rep.manifest_form == 1 and "the old form" in rep.format()

    if which == "person_only":  # what pyarrow < 26 does with it
        real = pq.read_table

        def old_pyarrow(path, columns=None, **kw):
            table = real(path, columns=columns, **kw)
            if "people" in table.column_names and manifest_form(table.schema) == 1:
                raise pa.ArrowInvalid("Expected all lists to be of size=3 but index 1 had "
                                      "size=0")
            return table

        monkeypatch.setattr(pq, "read_table", old_pyarrow)
        with pytest.raises(pa.ArrowInvalid):
            pq.read_table(store / "manifest.parquet")
        assert read_manifest_table(store / "manifest.parquet").to_pylist() == rows


def test_readers_outside_vhgen(room_store, small_store):
    """The README's reading section: pandas and DuckDB open the manifest, plain zarr the
    arrays, and they agree with vhgen.dataset."""
    import duckdb
    import pandas as pd
    import zarr

    for store in (room_store, small_store):
        ds = vd.open(store)
        man = pd.read_parquet(store / "manifest.parquet")
        assert man["frame"].tolist() == list(range(len(ds)))
        assert np.allclose(np.stack(man["world_to_camera"].to_numpy()).reshape(-1, 4, 4)[1],
                           ds[1]["manifest"]["world_to_camera"])
        con = duckdb.connect()
        n, people, feet = con.execute(
            "SELECT count(*), sum(len(people)), "
            "sum((SELECT count(*) FROM unnest(people) AS t(p) WHERE p.footprint IS NOT NULL))"
            f" FROM read_parquet('{store / 'manifest.parquet'}')").fetchone()
        assert n == len(ds) and people == int(man["num_people"].sum())
        assert feet == (people if store == room_store else 0)
        g = zarr.open_group(str(store), mode="r")
        for name in ("depth", "labels"):
            assert np.array_equal(g[name][2], ds[2][name])
