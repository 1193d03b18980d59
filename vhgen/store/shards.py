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
"""

from __future__ import annotations

import json
import os
import sys
import threading
from collections import OrderedDict
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.errors import ShardError, StoreError

EMPTY = 2**64 - 1  # offset and nbytes of an inner chunk never written (read as fill value)
_ZSTD_MAGIC = 0xFD2FB528


@dataclass(frozen=True)
class ArrayLayout:
    """Where and how one array's frames lie on disk (the layout ``create_store`` writes)."""

    name: str
    directory: Path
    shape: tuple[int, ...]  # (N, H, W)
    dtype: np.dtype
    frames_per_shard: int
    fill_value: Any
    separator: str  # chunk key separator: "c/<s>/0/0" or "c.<s>.0.0"
    index_at_end: bool
    index_crc: bool
    compressor: str  # "zstd", "blosc" or "" (bytes only)
    swap: bool  # stored byte order differs from this machine's
    palette: bool = False  # vhgen.palette before the compressor (uint16 arrays)
    rows: bool = False  # the palette's indexes as differences down the rows
    level: int | None = None  # the zstd level (zstd arrays)

    @property
    def frame_shape(self) -> tuple[int, ...]:
        return self.shape[1:]

    def shard_path(self, shard: int) -> Path:
        key = self.separator.join(["c", str(shard), *["0"] * (len(self.shape) - 1)])
        return self.directory / key

    def frames_of(self, shard: int) -> tuple[int, int]:
        """First and last frame of ``shard`` (inclusive)."""
        start = shard * self.frames_per_shard
        return start, min(self.shape[0], start + self.frames_per_shard) - 1


def array_layout(store: str | Path, name: str) -> ArrayLayout | None:
    """The layout of array ``name`` if it is the sharded one-frame-per-chunk layout this
    module reads directly, else None (read it through zarr)."""
    directory = Path(store) / name
    try:
        meta = json.loads((directory / "zarr.json").read_text())
        shape = tuple(int(n) for n in meta["shape"])
        grid = [int(n) for n in meta["chunk_grid"]["configuration"]["chunk_shape"]]
        keys = meta["chunk_key_encoding"]
        (codec,) = meta["codecs"]
        conf = codec["configuration"]
        dtype = np.dtype(meta["data_type"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    separator = keys.get("configuration", {}).get("separator", "/")
    if (meta.get("zarr_format") != 3 or meta.get("node_type") != "array" or len(shape) < 2
            or keys.get("name") != "default" or codec.get("name") != "sharding_indexed"
            or grid[1:] != list(shape[1:]) or conf.get("chunk_shape") != [1, *shape[1:]]
            or not isinstance(meta.get("fill_value"), int | float)):
        return None
    inner = [c.get("name") for c in conf.get("codecs", [])]
    index = [c.get("name") for c in conf.get("index_codecs", [])]
    palette = inner[1:2] == ["vhgen.palette"]
    rows = False
    if palette:
        pconf = conf["codecs"][1].get("configuration", {})
        if dtype != np.uint16 or pconf.get("typesize", 2) != 2:
            return None
        rows = pconf.get("rows", False) is True
        inner = inner[:1] + inner[2:]
    level = conf["codecs"][-1].get("configuration", {}).get("level")
    if inner not in (["bytes", "zstd"], ["bytes", "blosc"], *([] if palette else [["bytes"]])
                     ) or index not in (["bytes"], ["bytes", "crc32c"]):
        return None
    endian = conf["codecs"][0].get("configuration", {}).get("endian", "little")
    index_endian = conf["index_codecs"][0].get("configuration", {}).get("endian", "little")
    if index_endian != "little":
        return None
    return ArrayLayout(
        name=name, directory=directory, shape=shape, dtype=dtype, frames_per_shard=grid[0],
        fill_value=meta["fill_value"], separator=separator,
        index_at_end=conf.get("index_location", "end") == "end",
        index_crc=index[-1] == "crc32c", compressor=inner[-1] if len(inner) > 1 else "",
        swap=dtype.itemsize > 1 and endian != sys.byteorder and not palette,
        palette=palette, rows=rows,
        level=int(level) if inner[-1] == "zstd" and isinstance(level, int) else None)


def writes_directly(layout: ArrayLayout | None) -> bool:
    """Whether :func:`write_shard_file` writes this layout (the one ``create_store``
    makes with zstd: the index at the end with its crc32c, little-endian values)."""
    return (layout is not None and layout.compressor == "zstd" and layout.level is not None
            and layout.index_at_end and layout.index_crc and not layout.swap)


def write_shard_file(layout: ArrayLayout, shard: int, frames: np.ndarray,
                     threads: int = 1) -> None:
    """Write shard ``shard`` of a :func:`writes_directly` layout whole, ``frames`` (every
    frame of the shard, (n, H, W)): the bytes zarr's sharding codec writes for it (every
    inner chunk, even one all fill value, as ``write_shard`` asks of zarr; the chunks in
    frame order, then one (offset, nbytes) pair each, empty past the array's end, and the
    index's crc32c; tested byte for byte), without zarr's async codec pipeline, which
    costs about 5 ms of Python a frame on top of the encoding itself. ``threads``: chunks
    encoded at once (numcodecs' zstd and the palette's kernels release the GIL). The file
    is written under a temporary name and renamed, so a reader never sees half of it."""
    import numcodecs.zstd  # type: ignore[import-untyped]

    from vhgen.store import palette

    first, last = layout.frames_of(shard)
    if not writes_directly(layout) or frames.shape != (last - first + 1,
                                                       *layout.frame_shape):
        raise ValueError(f"{layout.name}: shard {shard} is not written directly "
                         f"({frames.shape} frames)")
    width = layout.frame_shape[-1] if layout.rows else None
    little = layout.dtype.newbyteorder("<")

    def encode(frame: np.ndarray) -> bytes:
        if layout.palette:
            data = palette.encode(frame, width)
        else:
            data = np.ascontiguousarray(frame, dtype=little)
        return numcodecs.zstd.compress(data, layout.level)

    if threads > 1 and len(frames) > 1:
        with ThreadPoolExecutor(min(threads, len(frames))) as pool:
            chunks = list(pool.map(encode, frames))
    else:
        chunks = [encode(f) for f in frames]
    index = np.full((layout.frames_per_shard, 2), EMPTY, "<u8")
    sizes = np.array([len(c) for c in chunks], np.uint64)
    index[:len(chunks), 0] = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.uint64)
    index[:len(chunks), 1] = sizes
    body = index.tobytes()
    path = layout.shard_path(shard)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        for c in chunks:
            f.write(c)
        f.write(body)
        f.write(_crc32c(body).to_bytes(4, "little"))
    os.replace(tmp, path)


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
            if _crc32c(body) != int.from_bytes(raw[16 * n:], "little"):
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
        import numcodecs.zstd

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


def _crc32c(data: bytes) -> int:
    """CRC-32C of ``data``, with whichever implementation zarr's version brought:
    google_crc32c (zarr >= 3.1) or crc32c (numcodecs' choice under zarr 3.0)."""
    try:
        import google_crc32c

        return int(google_crc32c.value(data))
    except ImportError:
        import crc32c

        return int(crc32c.crc32c(data))
