"""vhgen.dataset on a real store: random access, shard-local sampling, filtering, pickling
into spawned worker processes, a DataLoader-style loop (no torch), and Ray Data."""

from __future__ import annotations

import multiprocessing
import pickle

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

import vhgen.dataset as vd
from vhgen.errors import StoreError

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def truth(small_store):
    """The whole store read with plain zarr and pyarrow, to compare against."""
    import zarr

    g = zarr.open_group(str(small_store), mode="r")
    return {**{k: g[k][:] for k in ("depth", "labels", "raw", "classes", "instances")},
            "manifest": pq.read_table(small_store / "manifest.parquet")}


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


def test_arrays_and_columns_selection(small_store, truth):
    ds = vd.open(small_store, arrays=["labels"], columns=["avatar_id"], cache="frame")
    item = ds[4]
    assert set(item) == {"frame", "labels", "manifest"}
    assert item["manifest"] == {"frame": 4, "avatar_id": truth["manifest"]["avatar_id"][4]
                                .as_py()}
    assert np.array_equal(item["labels"], truth["labels"][4])
    with pytest.raises(StoreError, match="no array 'normals'"):
        vd.open(small_store, arrays=["normals"])


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
    finally:
        ray.shutdown()
