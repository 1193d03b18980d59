"""vhgen.store.manifest: the merge leaves one copy of the manifest (the parts are removed
after ``manifest.parquet`` is written), and every state a stopped run can leave merges
and counts its shards as done."""

from __future__ import annotations

import shutil

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from tests.conftest import unmerge_manifest, write_synthetic_store
from vhgen.errors import StoreError
from vhgen.store.manifest import ManifestMerger, read_manifest, write_parquet
from vhgen.store.zarr_store import completed_shards

FRAMES, PER_SHARD = 22, 4
SHARDS = set(range(6))


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    return write_synthetic_store(tmp_path_factory.mktemp("manifest") / "s.zarr",
                                 frames=FRAMES, frames_per_shard=PER_SHARD)


@pytest.fixture
def store(synthetic, tmp_path):
    out = tmp_path / "s.zarr"
    shutil.copytree(synthetic, out)
    return out


def redo_shard(store, table, shard: int, avatar_id: int):
    """A redone shard's part, as a resumed run leaves it: ``shard``'s rows of ``table``
    with another ``avatar_id``. Returns the part's rows."""
    changed = table.filter(pc.equal(table.column("shard"), shard)).set_column(
        table.column_names.index("avatar_id"), "avatar_id",
        pa.array([avatar_id] * PER_SHARD, pa.int32()))
    (store / "manifest").mkdir(exist_ok=True)
    write_parquet(changed, store / "manifest" / f"part-{shard:06d}.parquet")
    return changed


def test_merge_removes_the_parts(store, synthetic):
    unmerge_manifest(store)  # a run stopped before its merge: parts only
    assert completed_shards(store) == SHARDS and not (store / "manifest.parquet").exists()
    ManifestMerger(store).finish(FRAMES)
    assert not (store / "manifest").exists()  # one copy: the parts and their folder gone
    assert read_manifest(store).equals(read_manifest(synthetic).sort_by("frame"))
    assert completed_shards(store) == SHARDS  # the merged file says so now


def test_stopped_between_merge_and_removal(store, synthetic):
    """Parts and manifest.parquet both there (the synthetic store is written so): the
    merge gives the same rows once each, then removes the parts."""
    assert (store / "manifest").is_dir() and (store / "manifest.parquet").is_file()
    assert completed_shards(store) == SHARDS
    ManifestMerger(store).finish(FRAMES)
    assert read_manifest(store).equals(read_manifest(synthetic).sort_by("frame"))
    assert not (store / "manifest").exists()


def test_merging_a_finished_store_again(store):
    """--resume of a finished job: nothing to render, and the merge keeps the rows."""
    ManifestMerger(store).finish(FRAMES)
    before = read_manifest(store)
    ManifestMerger(store).finish(FRAMES)
    assert read_manifest(store).equals(before)


def test_a_redone_shard_replaces_its_rows(store):
    ManifestMerger(store).finish(FRAMES)
    table = read_manifest(store)
    mine = pc.equal(table.column("shard"), 2)
    redo_shard(store, table, 2, 99)
    ManifestMerger(store).finish(FRAMES)
    got = read_manifest(store)
    assert got.num_rows == FRAMES
    assert got.filter(pc.equal(got.column("shard"), 2)).column("avatar_id").to_pylist() == \
        [99] * PER_SHARD
    others = pc.invert(pc.equal(got.column("shard"), 2))
    assert got.filter(others).equals(table.filter(pc.invert(mine)))


def test_written_with_zstd_and_dictionaries_for_strings_only(store):
    ManifestMerger(store).finish(FRAMES)
    meta = pq.ParquetFile(store / "manifest.parquet").metadata.row_group(0)
    cols = {meta.column(k).path_in_schema: meta.column(k) for k in range(meta.num_columns)}
    assert {c.compression for c in cols.values()} == {"ZSTD"}
    dict_cols = {p for p, c in cols.items() if "RLE_DICTIONARY" in c.encodings}
    strings = {p for p, c in cols.items() if c.physical_type == "BYTE_ARRAY"}
    assert dict_cols and dict_cols <= strings
    assert cols["frame"].is_stats_set


def test_rows_stream_in_frame_order_as_shards_finish(store, synthetic, monkeypatch):
    """The driver's merge: a shard's rows are written once every earlier shard is, in row
    groups of MANIFEST_ROW_GROUP frames (the merge holds no more), and the file is the
    same rows as a merge at the end."""
    import vhgen.store.manifest as manifest

    monkeypatch.setattr(manifest, "MANIFEST_ROW_GROUP", 4)
    unmerge_manifest(store)
    merger = ManifestMerger(store, sorted(SHARDS), SHARDS)
    merger.add(1)  # shard 0 still rendering: nothing can be written
    assert merger.writer is None and merger.count == 0
    merger.add(0)  # shards 0 and 1 now: two row groups
    assert merger.pos == 2 and merger.count == 0
    for shard in (5, 3, 4, 2):
        merger.add(shard)
        assert merger.count < 4  # at most one row group held
    merger.finish(FRAMES)
    meta = pq.ParquetFile(store / "manifest.parquet").metadata
    assert meta.num_row_groups == 6  # one per shard here (4 frames each, 2 in the last)
    assert read_manifest(store).equals(read_manifest(synthetic).sort_by("frame"))
    assert not (store / "manifest").exists() and not (store / "manifest.parquet.tmp").exists()


def test_resume_takes_rows_from_an_earlier_manifest_row_group_by_row_group(
        store, synthetic, monkeypatch):
    """A resumed run: the earlier manifest (several row groups) gives the rows of the
    shards not redone, a redone shard's part replaces its rows."""
    import vhgen.store.manifest as manifest

    monkeypatch.setattr(manifest, "MANIFEST_ROW_GROUP", 8)
    ManifestMerger(store).finish(FRAMES)
    table = read_manifest(store)
    assert pq.ParquetFile(store / "manifest.parquet").metadata.num_row_groups == 3
    changed = redo_shard(store, table, 3, 7)
    merger = ManifestMerger(store, sorted(SHARDS), {3})
    merger.add(3)
    merger.finish(FRAMES)
    got = read_manifest(store)
    expect = pa.concat_tables([table.filter(pc.less(table.column("shard"), 3)), changed,
                               table.filter(pc.greater(table.column("shard"), 3))])
    assert got.equals(expect)


def test_a_missing_shard_fails_the_merge_and_keeps_the_parts(store):
    unmerge_manifest(store)
    (store / "manifest" / "part-000004.parquet").unlink()
    with pytest.raises(StoreError, match=r"manifest has 18 rows for 22 frames \(0 duplicated, "
                       r"4 missing\)"):
        ManifestMerger(store, sorted(SHARDS), SHARDS - {4}).finish(FRAMES)
    assert not (store / "manifest.parquet").exists()
    assert not (store / "manifest.parquet.tmp").exists()
    assert len(list((store / "manifest").glob("part-*.parquet"))) == 5


def test_an_unreadable_part_is_named_and_the_job_goes_on(store):
    unmerge_manifest(store)
    (store / "manifest" / "part-000002.parquet").write_bytes(b"PAR1 not parquet")
    merger = ManifestMerger(store, sorted(SHARDS), SHARDS)
    for shard in sorted(SHARDS):
        merger.add(shard)  # no exception while the job runs
    with pytest.raises(StoreError, match=r"1 part\(s\) unreadable: part-000002.parquet"):
        merger.finish(FRAMES)
    assert len(list((store / "manifest").glob("part-*.parquet"))) == 6


def test_a_merge_the_driver_did_not_finish_is_cleaned_on_resume(store):
    from vhgen.store.zarr_store import clean_partials

    unmerge_manifest(store)
    merger = ManifestMerger(store, sorted(SHARDS), SHARDS)
    merger.add(0)
    merger._flush()  # rows on disk in manifest.parquet.tmp, then the driver is killed
    assert (store / "manifest.parquet.tmp").is_file()
    assert clean_partials(store) == 1 and not (store / "manifest.parquet.tmp").exists()
    assert completed_shards(store) == SHARDS  # the parts still say what is done
