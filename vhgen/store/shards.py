"""Frames read straight from a store's shard files, many inner chunks decoded at once.

A vhgen array is sharded along frames (:func:`vhgen.store.zarr_store.create_store`): shard
``s`` of array ``name`` is one file, ``name/c/<s>/0/0``, holding ``frames_per_shard`` inner
chunks of one frame each (bytes little-endian, for uint16 arrays then
:mod:`vhgen.store.palette`, then zstd, or blosc for stores written with ``output.codec:
lz4``) and, at its end, the shard index: one (offset, nbytes) uint64 pair per inner
chunk, then the index's crc32c. zarr-python reads one frame through its async
codec pipeline in ~2 ms of Python per frame and array, several times the decode itself.
Here a frame costs a ``pread`` of its chunk (the index is read once and cached) and one
decode straight into the caller's array, and the frames of a request are decoded in
threads (numcodecs' zstd and blosc release the GIL), each inner chunk once. Arrays in any
other layout (unsharded stores of older vhgen, other codecs) are read through zarr, with
the same values.

A shard that cannot be read (file missing, index truncated or failing its checksum, chunk
that does not decode to one frame) raises :class:`vhgen.errors.ShardError` naming the
store, the array and the shard; the other shards, and the other frames of a shard whose
index is sound, still read.

The layout itself (:class:`ArrayLayout`, :func:`array_layout`) and the writer of shard
files live in :mod:`vhgen.store.shard_files`.
"""

from __future__ import annotations

import json
import os
import threading
from collections import OrderedDict
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.errors import ShardError, StoreError
from vhgen.store.shard_files import (
    EMPTY,
    ArrayLayout,
    array_layout,
    crc32c,
)

_ZSTD_MAGIC = 0xFD2FB528


def blosc_content_size(chunk: bytes | memoryview) -> int | None:
    """The decoded size a blosc chunk's header states (None: too short to hold one)."""
    return int.from_bytes(chunk[4:8], "little") if len(chunk) >= 16 else None


def zstd_content_size(chunk: bytes | memoryview) -> int | None:
    """The decoded size a zstd frame's header states (None: not stated or no zstd frame)."""
    if len(chunk) < 6 or int.from_bytes(chunk[:4], "little") != _ZSTD_MAGIC:
        return None
    desc = chunk[4]
    fcs_flag, single = desc >> 6, (desc >> 5) & 1
    pos = 5 + (0 if single else 1) + (0, 1, 2, 4)[desc & 3]
    size = (1 if single else 0, 2, 4, 8)[fcs_flag]
    if size == 0 or len(chunk) < pos + size:
        return None
    value = int.from_bytes(chunk[pos:pos + size], "little")
    return value + 256 if size == 2 else value


# one read job: array name, shard, and (frame, output array of one frame) pairs in it
Job = tuple[str, int, list[tuple[int, np.ndarray]]]


class ShardReader:
    """Decodes frames of a store's arrays into caller-given arrays, each inner chunk once.

    threads : decode threads (default ``min(4, os.cpu_count())``; 1 decodes in the calling
        thread). A reader in a DataLoader worker process may want 1.
    Holds no decoded frames: only the shard indexes (16 bytes per frame and array, at most
    ``index_cache`` shards), a zarr handle for arrays of other layouts and its threads.
    """

    def __init__(self, store: str | Path, names: Sequence[str], *, threads: int | None = None,
                 index_cache: int = 4096):
        self.store = Path(store)
        self.layouts = {n: array_layout(self.store, n) for n in names}
        self.specs: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
        for n in names:
            try:
                meta = json.loads((self.store / n / "zarr.json").read_text())
                self.specs[n] = (tuple(meta["shape"][1:]), np.dtype(meta["data_type"]))
            except (OSError, ValueError, KeyError, TypeError) as e:
                raise StoreError(f"{self.store}: array {n!r} unreadable ({n}/zarr.json: "
                                 f"{e})") from None
        self.threads = max(1, int(threads if threads is not None
                                  else min(4, os.cpu_count() or 1)))
        self._index: OrderedDict[tuple[str, int], np.ndarray] = OrderedDict()
        self._index_cache = int(index_cache)
        self._lock = threading.Lock()
        self._pool: ThreadPoolExecutor | None = None
        self._pool_pid = 0
        self._root: Any = None

    def empty(self, name: str, count: int | None = None) -> np.ndarray:
        """An uninitialised array for one frame of ``name`` (or ``count`` frames)."""
        shape, dtype = self.specs[name]
        return np.empty(shape if count is None else (count, *shape), dtype)

    def close(self) -> None:
        """Stop the decode threads (a later read starts them again)."""
        if self._pool is not None and self._pool_pid == os.getpid():
            self._pool.shutdown(wait=True)
        self._pool = None

    def _executor(self) -> ThreadPoolExecutor:
        # a pool inherited through fork has no threads in the child: start a new one
        if self._pool is None or self._pool_pid != os.getpid():
            self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="vhgen-read")
            self._pool_pid = os.getpid()
        return self._pool

    def read_into(self, requests: Sequence[tuple[str, int, np.ndarray]],
                  errors: list[ShardError] | None = None) -> None:
        """Decode each (array name, frame, out) request into ``out`` (one frame's shape and
        dtype, C-contiguous). Requests are grouped by array and shard and spread over the
        threads. A shard that cannot be read raises :class:`ShardError`, or, when
        ``errors`` is a list, is appended to it and its requests left unfilled."""
        groups: dict[tuple[str, int], list[tuple[int, np.ndarray]]] = {}
        for name, frame, out in requests:
            layout = self.layouts[name]
            fps = layout.frames_per_shard if layout is not None else 1
            groups.setdefault((name, int(frame) // fps), []).append((int(frame), out))
        jobs: list[Job] = [(n, s, g) for (n, s), g in groups.items()]
        found: list[ShardError] = []
        if self.threads == 1 or len(jobs) == 1 or len(requests) < 2:
            self._run(jobs, found)
        else:
            # one task per thread, bytes to decode spread evenly (largest jobs first)
            cost = [sum(o.nbytes for _, o in g) for _, _, g in jobs]
            parts: list[list[Job]] = [[] for _ in range(self.threads)]
            load = [0] * self.threads
            for j in np.argsort(cost)[::-1]:
                k = load.index(min(load))
                parts[k].append(jobs[j])
                load[k] += cost[j]
            pool = self._executor()
            futures = [pool.submit(self._run, p, found) for p in parts if p]
            for f in futures:
                f.result()
        if found:
            if errors is None:
                raise found[0]
            errors.extend(found)

    def _run(self, jobs: list[Job], found: list[ShardError]) -> None:
        for name, shard, group in jobs:
            try:
                layout = self.layouts[name]
                if layout is None:
                    self._read_zarr(name, group)
                else:
                    self._read_shard(layout, shard, group)
            except ShardError as e:
                found.append(e)  # list.append is atomic: threads may share the list

    def _read_zarr(self, name: str, group: list[tuple[int, np.ndarray]]) -> None:
        from vhgen.store.zarr_store import open_store

        with self._lock:
            if self._root is None:
                self._root = open_store(self.store)
        arr = self._root[name]
        for frame, out in group:
            out[...] = arr[frame]

    def _fail(self, layout: ArrayLayout, shard: int, message: str) -> ShardError:
        return ShardError(self.store, layout.name, shard, layout.frames_of(shard), message)

    def _shard_index(self, layout: ArrayLayout, shard: int, fd: int) -> np.ndarray:
        key = (layout.name, shard)
        with self._lock:
            idx = self._index.get(key)
            if idx is not None:
                self._index.move_to_end(key)
                return idx
        n = layout.frames_per_shard
        size = 16 * n + (4 if layout.index_crc else 0)
        file_size = os.fstat(fd).st_size
        if file_size < size:
            raise self._fail(layout, shard, f"shard file {self._rel(layout, shard)} is "
                             f"{file_size} bytes, shorter than its index ({size})")
        raw = os.pread(fd, size, file_size - size if layout.index_at_end else 0)
        body = raw[:16 * n]
        if layout.index_crc:
            if crc32c(body) != int.from_bytes(raw[16 * n:], "little"):
                raise self._fail(layout, shard, f"shard file {self._rel(layout, shard)}: "
                                 "index checksum does not match (damaged or truncated)")
        idx = np.frombuffer(body, "<u8").reshape(n, 2)
        used = idx[:, 0] != EMPTY
        if np.any(idx[used].sum(axis=1) > file_size):
            raise self._fail(layout, shard, f"shard file {self._rel(layout, shard)}: index "
                             "points past the end of the file (truncated)")
        with self._lock:
            self._index[key] = idx
            if len(self._index) > self._index_cache:
                self._index.popitem(last=False)
        return idx

    def _rel(self, layout: ArrayLayout, shard: int) -> str:
        return str(layout.shard_path(shard).relative_to(self.store))

    def _read_shard(self, layout: ArrayLayout, shard: int,
                    group: list[tuple[int, np.ndarray]]) -> None:
        import numcodecs.blosc  # type: ignore[import-untyped]
        import numcodecs.zstd  # type: ignore[import-untyped]

        from vhgen.store import palette

        path = layout.shard_path(shard)
        try:
            fd = os.open(path, os.O_RDONLY)
        except FileNotFoundError:
            raise self._fail(layout, shard, f"shard file {self._rel(layout, shard)} "
                             "missing") from None
        except OSError as e:
            raise self._fail(layout, shard, f"shard file {self._rel(layout, shard)}: "
                             f"{e.strerror}") from None
        try:
            idx = self._shard_index(layout, shard, fd)
            base = shard * layout.frames_per_shard
            want = int(np.prod(layout.frame_shape)) * layout.dtype.itemsize
            for frame, out in group:
                offset, nbytes = (int(v) for v in idx[frame - base])
                if offset == EMPTY and nbytes == EMPTY:
                    out[...] = layout.fill_value
                    continue
                chunk = os.pread(fd, nbytes, offset)
                if len(chunk) != nbytes:
                    raise self._fail(layout, shard, f"frame {frame}: chunk cut short")
                if layout.compressor:
                    zstd = layout.compressor == "zstd"
                    codec = numcodecs.zstd if zstd else numcodecs.blosc
                    stated = (zstd_content_size if zstd else blosc_content_size)(chunk)
                    if stated is not None and stated != want and not layout.palette:
                        raise self._fail(layout, shard, f"frame {frame}: chunk decodes to "
                                         f"{stated} bytes, expected {want}")
                    try:
                        if layout.palette:  # values in native order: no swap after
                            palette.decompress_into(codec.decompress, chunk, stated, out)
                        else:
                            codec.decompress(chunk, out)
                    except (RuntimeError, ValueError) as e:
                        raise self._fail(layout, shard, f"frame {frame}: {e}") from None
                elif nbytes != want:
                    raise self._fail(layout, shard, f"frame {frame}: chunk of {nbytes} "
                                     f"bytes, expected {want}")
                else:
                    out.reshape(-1).view(np.uint8)[:] = np.frombuffer(chunk, np.uint8)
                if layout.swap:
                    out.byteswap(inplace=True)
        finally:
            os.close(fd)
