"""How fast a store reads for training: frames/s by order, arrays and reader, beside zarr.

    python benchmarks/bench_read.py [--store STORE] [--frames 256] [--seconds 1.5]
        [--workers 2] [--batch 32] [--threads N] [--arrays depth labels ...]

Without ``--store`` it first makes one: the recommended training scene
(configs/forest/people_room.yaml: shards of 16 frames, the default codecs, or ``--codec
lz4``) limited to ``--frames`` frames, in a temporary folder (``--out`` keeps it). Every shard
file is read once before measuring, so all rows see a warm page cache.

Rows: three orders, each over every frame once at most (one epoch), stopped after
``--seconds``: *random* (a seeded permutation of the positions), *sampler*
(``ds.sampler()``: shard by shard, shuffled) and *stream* (``ds.stream()``: shuffled shard
order through a shuffle buffer); two selections: all arrays (or those of ``--arrays``)
with the manifest row (or columns, for batches), and depth+labels (still with the
manifest); readers: plain zarr
(``group[name][frame]`` per frame and array, no manifest; whole-shard slices for the
stream order), ``ds[i]``, ``ds.get_batch`` of ``--batch`` positions of the order, and
``ds.stream(batch_size=--batch)``. Columns: one process (``--threads`` decode threads,
default the reader's), and a pool of ``--workers`` processes (plain multiprocessing, one
decode thread each, started together; each reads its own share: its own permutation, its
sampler replica, its stream worker). Every cell runs in fresh processes.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

SELECTIONS = {"all+manifest": None, "depth+labels": ("depth", "labels")}
ROWS = [("random", "zarr"), ("random", "ds[i]"), ("random", "get_batch"),
        ("sampler", "zarr"), ("sampler", "ds[i]"), ("sampler", "get_batch"),
        ("stream", "zarr"), ("stream", "stream")]


def make_store(out: Path, frames: int, backend: str, codec: str) -> None:
    from dataclasses import replace

    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    cfg = JobConfig.load(REPO / "configs" / "forest" / "people_room.yaml", backend=backend,
                         num_workers=1)
    run_job(replace(cfg, codec=codec, palette=codec == "zstd"), out, max_frames=frames)


def _order(ds, order: str, rank: int, ranks: int) -> list[np.ndarray]:
    """The positions of one epoch of ``order`` for process ``rank`` of ``ranks``, in read
    units (single positions, or a shard's positions for zarr in stream order)."""
    if order == "random":
        return list(np.random.default_rng([7, rank]).permutation(len(ds)))
    if order == "sampler":
        return list(np.fromiter(ds.sampler(seed=7, num_replicas=ranks, rank=rank), np.int64))
    return list(np.split(*_shard_split(ds, rank, ranks)))


def _shard_split(ds, rank: int, ranks: int) -> tuple[np.ndarray, list[int]]:
    """Positions of this rank's shards in the stream's shard order, and where each ends."""
    pos = ds.stream(seed=7, shuffle=True, worker=rank, num_workers=ranks,
                    buffer_size=1).positions()
    shard = ds.shard_of()[pos]
    cuts = list(np.nonzero(np.diff(shard))[0] + 1)
    return pos, cuts


def measure(store: str, order: str, reader: str, arrays, seconds: float, batch: int,
            threads: int | None, rank: int = 0, ranks: int = 1, barrier=None) -> tuple[int, float]:
    """(frames read, seconds taken) for one row in one process."""
    import zarr

    import vhgen.dataset as vd

    ds = vd.open(store, arrays=arrays, threads=threads)
    names = ds.arrays
    g = zarr.open_group(store, mode="r")
    ds[0]
    for _ in range(2):  # threads started, the heap grown to a batch, as in a long run
        ds.get_batch(np.arange(min(batch, len(ds))))
    for n in names:  # warm zarr's own metadata cache too
        g[n][0]
    if reader == "stream":
        units: list = []
        stream = ds.stream(seed=7, batch_size=batch, worker=rank, num_workers=ranks)
    else:
        units = _order(ds, order, rank, ranks)
    if barrier is not None:
        barrier.wait()
    count = 0
    t0 = time.perf_counter()
    if reader == "stream":
        for b in stream:
            count += len(b["frame"])
            if time.perf_counter() - t0 > seconds:
                break
    elif reader == "zarr" and order == "stream":
        frames = ds.frames
        for unit in units:
            lo, hi = int(frames[unit].min()), int(frames[unit].max())
            for n in names:
                np.asarray(g[n][lo:hi + 1])
            count += len(unit)
            if time.perf_counter() - t0 > seconds:
                break
    elif reader == "zarr":
        arrs = [g[n] for n in names]
        for i in units:
            f = int(ds.frames[i])
            for a in arrs:
                np.asarray(a[f])
            count += 1
            if time.perf_counter() - t0 > seconds:
                break
    elif reader == "ds[i]":
        for i in units:
            ds[int(i)]
            count += 1
            if time.perf_counter() - t0 > seconds:
                break
    else:
        for a in range(0, len(units), batch):
            count += len(ds.get_batch(np.asarray(units[a:a + batch]))["frame"])
            if time.perf_counter() - t0 > seconds:
                break
    return count, time.perf_counter() - t0


def _worker(args: tuple, barrier, results) -> None:
    results.put(measure(*args, barrier=barrier))


def pool_rate(store: str, order: str, reader: str, arrays, seconds: float, batch: int,
              workers: int, threads: int | None = 1) -> float:
    """Frames/s of ``workers`` fresh processes started together, each reading its share
    (fresh: a process that read through zarr first decodes slower in threads, its heap
    left in another state by zarr's large buffers)."""
    ctx = mp.get_context("spawn")
    barrier, results = ctx.Barrier(workers), ctx.Queue()
    procs = [ctx.Process(target=_worker, args=((store, order, reader, arrays, seconds, batch,
                                                threads, w, workers), barrier, results))
             for w in range(workers)]
    for p in procs:
        p.start()
    got = [results.get() for _ in procs]
    for p in procs:
        p.join()
    return sum(c for c, _ in got) / max(t for _, t in got)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--store", help="a finished store (default: make one)")
    ap.add_argument("--frames", type=int, default=256, help="frames of the store made")
    ap.add_argument("--out", help="keep the store made here")
    ap.add_argument("--backend", default="osmesa", choices=["egl", "osmesa"])
    ap.add_argument("--codec", default="zstd", choices=["zstd", "lz4"],
                    help="output.codec of the store made")
    ap.add_argument("--seconds", type=float, default=1.5, help="per measurement")
    ap.add_argument("--workers", type=int, default=2, help="processes of the pool")
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--threads", type=int, default=None, help="decode threads, one process")
    ap.add_argument("--arrays", nargs="*", help="the arrays of the all+manifest rows "
                    "(default: every array of the store; to compare stores that hold "
                    "different arrays)")
    args = ap.parse_args()
    selections = {**SELECTIONS, "all+manifest": tuple(args.arrays) if args.arrays else None}

    tmp = None
    if args.store:
        store = Path(args.store)
    else:
        tmp = Path(tempfile.mkdtemp(prefix="bench_read_"))
        store = Path(args.out) if args.out else tmp / "people_room.zarr"
        t = time.perf_counter()
        make_store(store, args.frames, args.backend, args.codec)
        print(f"made {store} ({args.frames} frames) in {time.perf_counter() - t:.0f} s")
    try:
        import vhgen.dataset as vd

        ds = vd.open(store, arrays=selections["all+manifest"])
        for f in sorted(store.glob("*/c/**/*")):  # warm the page cache
            if f.is_file():
                f.read_bytes()
        print(f"{store}: {len(ds)} frames, shards of {ds.frames_per_shard}, arrays "
              f"{', '.join(ds.arrays)}; {mp.cpu_count()} cores; batch {args.batch}; "
              f"{args.seconds} s per cell")
        head = (f"| order   | arrays       | reader         | 1 process | pool of {args.workers} |")
        print(head)
        print("|" + "|".join("-" * (len(c)) for c in head.split("|")[1:-1]) + "|")
        for sel, arrays in selections.items():
            for order, reader in ROWS:
                one = pool_rate(str(store), order, reader, arrays, args.seconds, args.batch,
                                1, args.threads)
                pool = pool_rate(str(store), order, reader, arrays, args.seconds, args.batch,
                                 args.workers)
                name = reader if reader != "get_batch" else f"get_batch({args.batch})"
                if reader == "stream":
                    name = f"stream({args.batch})"
                print(f"| {order:7s} | {sel:12s} | {name:14s} | {one:9.0f} | "
                      f"{pool:{len(f'pool of {args.workers}')}.0f} |", flush=True)
    finally:
        if tmp is not None and not args.out:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
