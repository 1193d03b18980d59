"""A store's shard files as vhgen lays them out: where an array's frames lie, and one
shard written straight to its file.

A vhgen array is sharded along frames (:func:`vhgen.store.zarr_store.create_store`): shard
``s`` of array ``name`` is one file, ``name/c/<s>/0/0``, holding ``frames_per_shard`` inner
chunks of one frame each (bytes little-endian, for uint16 arrays then
:mod:`vhgen.store.palette`, then zstd, or blosc for stores written with ``output.codec:
lz4``) and, at its end, the shard index: one (offset, nbytes) uint64 pair per inner chunk,
then the index's crc32c. :mod:`vhgen.store.shards` reads such files without zarr;
:func:`write_shard_file` writes them (``write_shard`` of :mod:`vhgen.store.zarr_store`
calls it). Of vhgen's store it imports only the palette codec (when writing), so both
can use it without an import cycle.
"""

from __future__ import annotations

import json
import os
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np

EMPTY = 2**64 - 1  # offset and nbytes of an inner chunk never written (read as fill value)


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


def writes_directly(layout: ArrayLayout | None) -> TypeGuard[ArrayLayout]:
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

    from vhgen.store.palette import encode as palette_encode

    first, last = layout.frames_of(shard)
    if not writes_directly(layout) or frames.shape != (last - first + 1,
                                                       *layout.frame_shape):
        raise ValueError(f"{layout.name}: shard {shard} is not written directly "
                         f"({frames.shape} frames)")
    width = layout.frame_shape[-1] if layout.rows else None
    little = layout.dtype.newbyteorder("<")

    def encode(frame: np.ndarray) -> bytes:
        if layout.palette:
            data = palette_encode(frame, width)
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
        f.write(crc32c(body).to_bytes(4, "little"))
    os.replace(tmp, path)


def crc32c(data: bytes) -> int:
    """CRC-32C of ``data``, with whichever implementation zarr's version brought:
    google_crc32c (zarr >= 3.1) or crc32c (numcodecs' choice under zarr 3.0)."""
    try:
        import google_crc32c

        return int(google_crc32c.value(data))
    except ImportError:
        import crc32c

        return int(crc32c.crc32c(data))
