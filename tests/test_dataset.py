"""vhgen.dataset on a real store: random access, shard-local sampling, filtering, pickling
into spawned worker processes, a DataLoader-style loop (no torch), and Ray Data; batched
reads and streams against the reader as it was before them, bit for bit; streams split
between ranks and workers; the memory bound; damaged and unfinished stores (the last on
synthetic stores, which need no rendering)."""

from __future__ import annotations

import multiprocessing
import pickle
import shutil
import sys
import tracemalloc
import types

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

import vhgen.dataset as vd
from tests.conftest import write_synthetic_store
from vhgen.errors import ShardError, StoreError

slow = pytest.mark.slow


@pytest.fixture(scope="module")
def truth(small_store):
    """The whole store read with plain zarr and pyarrow, to compare against."""
    import zarr

    g = zarr.open_group(str(small_store), mode="r")
    return {**{k: g[k][:] for k in ("depth", "labels", "raw", "classes", "instances")},
            "manifest": pq.read_table(small_store / "manifest.parquet")}


@slow
def test_random_access_matches_zarr_and_manifest(small_store, truth):
    ds = vd.open(small_store)
    assert len(ds) == 8 and ds.arrays == ("depth", "labels", "raw", "classes", "instances")
    assert ds.label_names[0] == "LU_head" and len(ds.label_names) == 31
    for i in (5, 0, 7, 3, -1):  # out of shard order, and a negative index
        item = ds[i]
        f = i % 8
        assert item["frame"] == f
        for name in ("depth", "labels", "raw", "classes", "instances"):
            assert item[name].dtype == truth[name].dtype
            assert np.array_equal(item[name], truth[name][f])
        row = truth["manifest"].slice(f, 1).to_pylist()[0]
        m = item["manifest"]
        assert m["motion_file"] == row["motion_file"] and m["seed"] == row["seed"]
        assert m["world_to_camera"].shape == (4, 4)
        assert np.array_equal(m["world_to_camera"].ravel(), row["world_to_camera"])
        assert m["joints_cam"].shape == (31, 3) and m["joints_cam"].dtype == np.float32
        assert m["body_pixels"] == int((item["labels"] > 0).sum())
    item = ds[1]
    item["depth"][:] = 0  # a copy: the cached shard is untouched
    assert np.array_equal(ds[1]["depth"], truth["depth"][1])
    with pytest.raises(IndexError):
        ds[8]
    assert [it["frame"] for it in ds] == list(range(8))


@slow
def test_arrays_and_columns_selection(small_store, truth):
    ds = vd.open(small_store, arrays=["labels"], columns=["avatar_id"], cache="frame")
    item = ds[4]
    assert set(item) == {"frame", "labels", "manifest"}
    assert item["manifest"] == {"frame": 4, "avatar_id": truth["manifest"]["avatar_id"][4]
                                .as_py()}
    assert np.array_equal(item["labels"], truth["labels"][4])
    with pytest.raises(StoreError, match="no array 'normals'"):
        vd.open(small_store, arrays=["normals"])


@slow
def test_shard_sampler_is_shard_local_seeded_and_complete(small_store):
    ds = vd.open(small_store)
    shard = ds.shard_of()
    assert shard.tolist() == [0, 0, 0, 1, 1, 1, 2, 2]
    orders = set()
    for epoch in range(6):
        s = ds.sampler(seed=3, epoch=epoch)
        order = list(s)
        assert sorted(order) == list(range(8)) and len(s) == 8
        # positions of one shard are consecutive: each shard is decoded once per epoch
        runs = [shard[order[0]]] + [shard[b] for a, b in zip(order, order[1:], strict=False)
                                    if shard[a] != shard[b]]
        assert len(runs) == 3 == len(set(runs))
        assert order == list(ds.sampler(seed=3, epoch=epoch))  # same seed+epoch, same order
        orders.add(tuple(order))
    assert len(orders) > 1  # epochs differ
    assert list(ds.sampler(shuffle=False)) == list(range(8))
    parts = [list(ds.sampler(seed=1, num_replicas=2, rank=r)) for r in (0, 1)]
    assert sorted(parts[0] + parts[1]) == list(range(8))
    assert not set(parts[0]) & set(parts[1])
    assert {len(set(shard[p])) for p in parts} <= {1, 2}


@slow
def test_filter_by_columns_and_predicate(small_store, truth):
    ds = vd.open(small_store)
    man = truth["manifest"]
    motion = man["motion_file"][0].as_py()
    want = [i for i in range(8) if man["motion_file"][i].as_py() == motion]
    sub = ds.filter(motion_file=motion)
    assert sub.frames.tolist() == want and 0 < len(sub) < 8
    both = ds.filter(avatar_id=[0, 1])
    assert len(both) == 8
    one = ds.filter(avatar_id=1, motion_file=[motion])
    assert one.frames.tolist() == [i for i in want if man["avatar_id"][i].as_py() == 1]
    big = ds.filter(lambda t: pc.greater(t["body_pixels"], 18000))
    expect = [i for i in range(8) if man["body_pixels"][i].as_py() > 18000]
    assert big.frames.tolist() == expect and 0 < len(expect) < 8
    assert [big[j]["frame"] for j in range(len(big))] == expect
    assert np.array_equal(big[0]["depth"], truth["depth"][expect[0]])
    assert sorted(big.sampler(seed=0)) == list(range(len(big)))
    with pytest.raises(StoreError, match="no manifest column 'subject'"):
        ds.filter(subject=1)


def _worker_sum(args):
    ds, indices = args
    return [(ds[i]["frame"], int(ds[i]["depth"].astype(np.int64).sum())) for i in indices]


@slow
def test_pickles_into_spawned_workers(small_store, truth):
    """DataLoader workers receive the dataset pickled (spawn) or forked; both must read."""
    ds = vd.open(small_store).filter(avatar_id=[1])
    ds[0]  # a warm cache and an open zarr handle must not travel
    blob = pickle.dumps(ds)
    assert len(blob) < 2000
    idx = list(range(len(ds)))
    expect = [(int(f), int(truth["depth"][f].astype(np.int64).sum())) for f in ds.frames]
    for method in ("spawn", "fork"):
        with multiprocessing.get_context(method).Pool(2) as pool:
            got = pool.map(_worker_sum, [(ds, idx[:2]), (ds, idx[2:])])
        assert got[0] + got[1] == expect, method


def _collate(items: list) -> object:
    """What torch's default_collate does, in NumPy: stack arrays and numbers, recurse into
    dicts, keep strings as lists."""
    first = items[0]
    if isinstance(first, dict):
        return {k: _collate([it[k] for it in items]) for k in first}
    if isinstance(first, np.ndarray | int | float):
        return np.stack([np.asarray(x) for x in items])
    return list(items)


def _loader(ds, sampler, batch_size: int):
    """A DataLoader stand-in: len(dataset), a sampler, __getitem__, batching by stacking."""
    assert len(sampler) == len(ds)
    batch: list = []
    for i in sampler:
        batch.append(ds[i])
        if len(batch) == batch_size:
            yield _collate(batch)
            batch = []
    if batch:
        yield _collate(batch)


@slow
def test_dataloader_style_loop(small_store, truth):
    ds = vd.open(small_store)
    seen = []
    for epoch in range(2):
        sampler = ds.sampler(seed=7, epoch=epoch)
        for batch in _loader(ds, sampler, batch_size=3):
            assert batch["depth"].dtype == np.uint16 and batch["depth"].shape[1:] == (480, 640)
            assert batch["labels"].shape == batch["depth"].shape
            assert batch["manifest"]["world_to_camera"].shape[1:] == (4, 4)
            assert isinstance(batch["manifest"]["motion_file"], list)
            for k, f in enumerate(batch["frame"]):
                assert np.array_equal(batch["depth"][k], truth["depth"][f])
                assert batch["manifest"]["frame"][k] == f
            seen += batch["frame"].tolist()
    assert sorted(seen) == sorted(list(range(8)) * 2)


@slow
def test_to_ray(small_store, truth):
    import ray

    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR")
    try:
        from ray.data import DataContext

        DataContext.get_current().enable_progress_bars = False
        rd = vd.to_ray(small_store)
        rows = sorted(rd.take_all(), key=lambda r: r["frame"])
        assert [r["frame"] for r in rows] == list(range(8))
        for r in rows:
            f = r["frame"]
            assert np.array_equal(r["depth"], truth["depth"][f])
            assert np.array_equal(r["labels"], truth["labels"][f])
            assert np.array_equal(r["raw"], truth["raw"][f])
            assert r["world_to_camera"].shape == (4, 4) and r["joints_cam"].shape == (31, 3)
            assert r["seed"] == truth["manifest"]["seed"][f].as_py()
        sub = vd.to_ray(small_store, arrays=["labels"], avatar_id=1,
                        predicate=lambda t: pc.greater(t["body_pixels"], 0))
        frames = sorted(r["frame"] for r in sub.take_all())
        man = truth["manifest"]
        assert frames == [i for i in range(8) if man["avatar_id"][i].as_py() == 1]
        batch = next(iter(sub.iter_batches(batch_size=2, batch_format="numpy")))
        assert batch["labels"].shape == (2, 480, 640) and "depth" not in batch
        assert vd.to_ray(small_store, avatar_id=99).count() == 0  # nothing matches
        shuffled = [r["frame"] for r in vd.to_ray(small_store, arrays=["labels"],
                                                   seed=3).iter_rows()]
        assert sorted(shuffled) == list(range(8))
    finally:
        ray.shutdown()


# --- batched reads and streams, bit for bit against the reader as it was -----------------

def _reference_item(store, table, i: int, arrays) -> dict:
    """``ds[i]`` as vhgen.dataset made it before batched reads: the frame sliced out by
    zarr, the manifest row by ``table.slice(i, 1).to_pylist()``, the array columns made
    NumPy arrays (the slow obvious reference)."""
    import zarr

    g = zarr.open_group(str(store), mode="r")
    frame = table["frame"][i].as_py()
    row = table.slice(i, 1).to_pylist()[0]
    for name, shape in vd.ARRAY_COLUMNS.items():
        if name in row and row[name] is not None:
            dtype = np.float32 if name == "joints_cam" else np.float64
            row[name] = np.asarray(row[name], dtype).reshape(shape)
    return {"frame": frame, **{n: np.asarray(g[n][frame]) for n in arrays}, "manifest": row}


def _same(a, b, where: str = "item") -> None:
    """Equal in value, type, dtype, shape and key order, recursively."""
    assert type(a) is type(b), (where, type(a), type(b))
    if isinstance(a, dict):
        assert list(a) == list(b), (where, list(a), list(b))
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b), where
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{k}]")
    else:
        assert a == b, (where, a, b)


def _check_batch(batch: dict, refs: list[dict], arrays) -> None:
    """A get_batch batch holds the reference items, frame k = refs[k]."""
    assert batch["frame"].tolist() == [r["frame"] for r in refs]
    for n in arrays:
        _same(batch[n], np.stack([r[n] for r in refs]), n)
    for col, values in batch["manifest"].items():
        want = [r["manifest"][col] for r in refs]
        if isinstance(values, np.ndarray):
            assert len(values) == len(want)
            for k, w in enumerate(want):
                assert np.array_equal(values[k], w) and np.asarray(w).shape == values[k].shape
        else:
            _same(values, want, col)


def _all_paths_match(store, **open_args) -> None:
    ds = vd.open(store, **open_args)
    refs = [_reference_item(store, ds.manifest, i, ds.arrays) for i in range(len(ds))]
    n = len(ds)
    rng = np.random.default_rng(1)
    for cache in ("shard", "frame"):
        view = vd.open(store, cache=cache, **open_args)
        for i in [*rng.permutation(n), *view.sampler(seed=2), 1, 1, -1]:
            _same(view[int(i)], refs[int(i) % n], f"ds[{i}] cache={cache}")
    order = rng.permutation(n)
    for got, i in zip(ds.__getitems__(order.tolist()), order, strict=True):
        _same(got, refs[i], f"__getitems__ {i}")
    picks = np.concatenate([order[:5], order[:2]])  # repeats read once, given twice
    _check_batch(ds.get_batch(picks), [refs[i] for i in picks], ds.arrays)
    stream = ds.stream(seed=4, buffer_size=5)
    seen = [item["frame"] for item in stream]
    for item in stream:
        _same(item, refs[int(np.searchsorted(ds.frames, item["frame"]))], "stream")
    assert sorted(seen) == ds.frames.tolist()
    for batch in ds.stream(seed=4, batch_size=3):
        pos = np.searchsorted(ds.frames, batch["frame"])
        _check_batch(batch, [refs[p] for p in pos], ds.arrays)


@slow
def test_every_path_matches_the_reference(small_store):
    _all_paths_match(small_store)
    _all_paths_match(small_store, arrays=["depth", "labels"], columns=["avatar_id", "seed"])


def test_every_path_matches_the_reference_synthetic(tmp_path):
    store = write_synthetic_store(tmp_path / "s.zarr", frames=18, frames_per_shard=4)
    _all_paths_match(store)
    _all_paths_match(store, arrays=["labels"], columns=["scene", "joints_cam", "people"])


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    return write_synthetic_store(tmp_path_factory.mktemp("synthetic") / "s.zarr", frames=42,
                                 frames_per_shard=4, height=24, width=32)


@pytest.mark.parametrize("world_size,num_workers", [(1, 1), (1, 3), (2, 2), (3, 1)])
def test_stream_splits_without_overlap_every_frame_once(synthetic, world_size, num_workers):
    ds = vd.open(synthetic).filter(lambda t: pc.not_equal(t["avatar_id"], 2))
    shard = ds.shard_of()
    orders = []
    for epoch in range(3):
        parts = [ds.stream(seed=9, epoch=epoch, rank=r, world_size=world_size, worker=w,
                           num_workers=num_workers, buffer_size=6).positions()
                 for r in range(world_size) for w in range(num_workers)]
        flat = np.concatenate(parts)
        assert sorted(flat.tolist()) == list(range(len(ds)))  # every frame once
        shard_sets = [set(shard[p].tolist()) for p in parts]
        assert sum(map(len, shard_sets)) == len(set().union(*shard_sets))  # shards not shared
        counts = [len(x) for x in shard_sets]
        assert max(counts) - min(counts) <= 1  # at most one shard apart
        again = [ds.stream(seed=9, epoch=epoch, rank=r, world_size=world_size, worker=w,
                           num_workers=num_workers, buffer_size=6).positions()
                 for r in range(world_size) for w in range(num_workers)]
        assert all(np.array_equal(a, b) for a, b in zip(parts, again, strict=True))
        orders.append(flat.tolist())
        got = sorted(f for r in range(world_size) for w in range(num_workers)
                     for f in (it["frame"] for it in ds.stream(
                         seed=9, epoch=epoch, rank=r, world_size=world_size, worker=w,
                         num_workers=num_workers)))
        assert got == ds.frames.tolist()
    assert orders[0] != orders[1] != orders[2]
    assert ds.stream(shuffle=False).positions().tolist() == list(range(len(ds)))


def test_stream_batches_and_length(synthetic):
    ds = vd.open(synthetic, arrays=["depth"])
    s = ds.stream(seed=0, batch_size=5)
    sizes = [len(b["frame"]) for b in s]
    assert sizes == [5] * 8 + [2] and len(s) == 9
    s = ds.stream(seed=0, batch_size=5, drop_last=True)
    assert [len(b["depth"]) for b in s] == [5] * 8 and len(s) == 8
    with pytest.raises(ValueError, match="rank 2"):
        ds.stream(rank=2, world_size=2)
    with pytest.raises(ValueError, match="together"):
        ds.stream(worker=1)


def test_stream_uses_torch_worker_info(synthetic, monkeypatch):
    """With torch imported, the stream is an IterableDataset and reads its DataLoader
    worker's share (a stand-in torch: the real one is not a dependency)."""
    torch = types.ModuleType("torch")
    data = types.ModuleType("torch.utils.data")

    class IterableDataset:
        pass

    data.IterableDataset = IterableDataset  # type: ignore[attr-defined]
    data.get_worker_info = lambda: types.SimpleNamespace(id=1, num_workers=3)  # type: ignore[attr-defined]
    torch.utils = types.ModuleType("torch.utils")  # type: ignore[attr-defined]
    torch.utils.data = data  # type: ignore[attr-defined]
    for name, mod in (("torch", torch), ("torch.utils", torch.utils),
                      ("torch.utils.data", data)):
        monkeypatch.setitem(sys.modules, name, mod)
    monkeypatch.setattr(vd, "_TORCH_STREAM", [])
    ds = vd.open(synthetic)
    s = ds.stream(seed=5, rank=1, world_size=2)
    assert isinstance(s, IterableDataset) and isinstance(s, vd.FrameStream)
    assert s.consumer() == (4, 6)
    want = ds.stream(seed=5, rank=1, world_size=2, worker=1, num_workers=3).positions()
    assert np.array_equal(s.positions(), want)
    back = pickle.loads(pickle.dumps(s))  # as DataLoader sends it to spawned workers
    assert type(back).__name__ == "TorchFrameStream" and np.array_equal(back.positions(), want)


def test_memory_holds_at_most_one_shard(tmp_path):
    store = write_synthetic_store(tmp_path / "m.zarr", frames=48, frames_per_shard=4,
                                  height=240, width=320)
    frame_bytes = 240 * 320 * (2 + 1 + 1 + 1)
    ds = vd.open(store, threads=2)
    ds.get_batch([0])  # threads, indexes and the manifest columns made before measuring
    tracemalloc.start()
    try:
        for i in ds.sampler(seed=0):
            ds[i]
        _, walk = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for i in np.random.default_rng(0).permutation(48):
            ds[int(i)]
        _, scattered = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for batch in ds.stream(seed=0, batch_size=6):
            del batch
        _, stream = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for item in ds.stream(seed=0):
            del item
        _, items = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # kept per thread to decode depth stored through vhgen.palette: a plane of indexes
    # (2 decode threads and the stream's read-ahead thread)
    slack = 300_000 + 3 * 240 * 320
    # the store is 48 frames; a reader that kept what it decoded would hold all of them
    assert walk < (4 + 1) * frame_bytes + slack  # one shard read ahead + the item
    assert scattered < (4 + 1) * frame_bytes + slack
    assert stream < 2 * 6 * frame_bytes + slack  # the batch yielded and the next one
    assert items < 2 * 4 * frame_bytes + slack


@pytest.fixture
def damaged(synthetic, tmp_path):
    out = tmp_path / "damaged.zarr"
    shutil.copytree(synthetic, out)
    (out / "labels" / "c" / "2" / "0" / "0").unlink()
    return out


def test_damaged_shard_names_store_and_shard_and_the_rest_reads(damaged, synthetic, caplog):
    ds = vd.open(damaged)
    good = vd.open(synthetic)
    with pytest.raises(ShardError) as e:
        ds[9]
    msg = str(e.value)
    assert "\n" not in msg and str(damaged) in msg and "labels shard 2 (frames 8-11)" in msg
    assert "labels/c/2/0/0 missing" in msg
    _same(ds[1], good[1])
    _same(ds[12], good[12])
    with pytest.raises(ShardError, match="labels shard 2"):
        ds.get_batch([1, 9])
    with pytest.raises(ShardError, match="labels shard 2"):
        list(ds.stream(seed=0))
    with caplog.at_level("WARNING", logger="vhgen.dataset"):
        frames = sorted(it["frame"] for it in ds.stream(seed=0, skip_damaged=True))
    assert frames == [f for f in range(42) if not 8 <= f <= 11]
    assert sum("labels shard 2" in r.getMessage() for r in caplog.records) == 1
    assert vd.open(damaged, arrays=["depth"])[9]["frame"] == 9  # the array not asked for


def test_unfinished_store_and_missing_array(synthetic, tmp_path):
    store = tmp_path / "writing.zarr"
    shutil.copytree(synthetic, store)
    (store / "manifest.parquet").unlink()
    (store / "manifest" / "part-000003.parquet").unlink()  # shard 3 not finished
    with pytest.raises(StoreError) as e:
        vd.open(store)
    assert str(store) in str(e.value) and "\n" not in str(e.value)
    assert "10 shards finished" in str(e.value) and "partial=True" in str(e.value)
    ds = vd.open(store, partial=True)
    assert ds.frames.tolist() == [f for f in range(42) if not 12 <= f <= 15]
    good = vd.open(synthetic)
    for i, f in ((0, 0), (12, 16), (-1, 41)):
        _same(ds[i], good[f])
    shutil.rmtree(store / "classes")
    with pytest.raises(StoreError, match=f"{store}: no array 'classes'"):
        vd.open(store, arrays=["classes"], partial=True)
    assert "classes" not in vd.open(store, partial=True).arrays


def test_view_in_any_frame_order(synthetic):
    """A dataset made with its frames in another order reads them in that order."""
    good = vd.open(synthetic)
    frames = np.array([13, 2, 14, 3, 12, 40, 15])
    ds = vd.FrameDataset(synthetic, frames=frames)
    assert ds.frames.tolist() == frames.tolist()
    for i in range(len(frames)):
        _same(ds[i], good[int(frames[i])])
    _check_batch(ds.get_batch([6, 0]), [good[15], good[13]], ds.arrays)
