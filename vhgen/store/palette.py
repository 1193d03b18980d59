"""``vhgen.palette``: a lossless zarr v3 filter for sensor depth (bytes to bytes, before zstd).

A frame of simulated (or real) structured-light depth holds few distinct values: the
sensor measures disparity in 1/8 px steps, so a 640x480 ``openni_525`` frame has 80-500
distinct millimetre values (median ~170) among its 307,200 pixels. The filter stores the
frame's sorted distinct values once and each pixel as its index into them, one byte per
pixel (the index's high byte follows as a second plane only when a frame has more than
256 values). Zstd then compresses half the bytes with the same structure: on a
``cluttered_room`` store depth took 78.5 kB a frame at zstd 7 against 86.1 kB plain
(docs/performance.md, "Store size"), and encoded in less time; decoding is one table
look-up per pixel.

Layout of an encoded chunk (all little-endian)::

    uint32 n | n x uint16 values, ascending | N x uint8 low index bytes
             | N x uint8 high index bytes (only when n > 256)

where N is the number of uint16 elements. The codec takes the little-endian uint16 bytes
of the ``bytes`` codec before it (``configuration.typesize`` 2, the only one).

With ``configuration.rows`` true (what vhgen writes since 2026-11-29), each index is
stored as its difference from the index one image row above it (modulo 256, or 65536
with two planes; the first row as it is). Neighbouring pixels of a surface have nearby
depths, so nearby indexes (the table is sorted): most differences are 0 or +-1, and zstd
3 then makes depth smaller than zstd 7 did without them, in less than half the time
(docs/performance.md, "Differences down the rows"). Such a chunk says so itself::

    uint32 n | ROWS | uint32 width | n x uint16 values | the index planes, as differences

(``ROWS`` is the top bit of the first word: a decoder that does not know it sees far too
many values and stops with a size error, never wrong values). Stores written before read
as they did.

It is not a codec of the zarr v3 specification: zarr finds it through the ``zarr.codecs``
entry point vhgen installs (or :func:`register`), so a store written with it reads with
plain zarr wherever vhgen is installed; ``output.palette: false`` writes depth with
specification codecs only.
"""

from __future__ import annotations

import asyncio
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from zarr.abc.codec import BytesBytesCodec

if TYPE_CHECKING:
    from zarr.core.array_spec import ArraySpec
    from zarr.core.buffer import Buffer

NAME = "vhgen.palette"
_HEADER = 4
ROWS = 1 << 31  # the first word's flag: indexes stored as differences down the rows
_local = threading.local()  # per thread: scratch bytes (decompress_into)


class PaletteError(ValueError):
    """An encoded chunk that is not a palette chunk of the expected size."""


def encode(values: np.ndarray, width: int | None = None) -> np.ndarray:
    """The palette encoding (uint8 bytes) of a uint16 array; ``width``: the length of its
    image rows, to store each index as its difference from the one a row above (see the
    module docstring; None: the plain indexes). Compiled: 0.7-0.9 ms a 640x480 frame
    here (2 cores; the NumPy code it replaced 1.5-2.0)."""
    from vhgen.store.palette_kernels import index_planes, table_of  # numba: when used

    flat = np.ascontiguousarray(values, dtype="<u2").reshape(-1)
    if width is not None and (width < 1 or flat.size % width):
        raise ValueError(f"{NAME}: {flat.size} elements are not rows of {width}")
    rank = np.empty(65536, np.uint16)
    table = np.empty(65536, "<u2")
    n = int(table_of(flat.view(np.uint16), rank, table.view(np.uint16)))
    head = _HEADER + (4 if width is not None else 0)
    two = n > 256
    out = np.empty(head + 2 * n + flat.size * (2 if two else 1), np.uint8)
    out[:4] = np.array([n | (ROWS if width is not None else 0)], "<u4").view(np.uint8)
    if width is not None:
        out[4:8] = np.array([width], "<u4").view(np.uint8)
    out[head:head + 2 * n] = table[:n].view(np.uint8)
    # one plane: the differences modulo 65536 keep their low byte, and the low bytes of
    # indexes below 256 add up again modulo 256
    index_planes(flat.view(np.uint16), rank, width or 0, two, out[head + 2 * n:])
    return out


def decode_into(encoded: np.ndarray | bytes | memoryview, out: np.ndarray) -> None:
    """Decode a palette chunk into ``out`` (uint16, C-contiguous, the chunk's size), in
    native byte order. Raises :class:`PaletteError` on a chunk of the wrong size or with
    an index past its table."""
    if out.dtype != np.uint16 or not out.flags.c_contiguous:
        raise TypeError(f"decode_into needs a C-contiguous uint16 array, got {out.dtype}")
    buf = np.frombuffer(encoded, np.uint8)
    flat = out.reshape(-1)
    size = flat.size
    if buf.size < _HEADER:
        raise PaletteError(f"palette chunk of {buf.size} bytes, shorter than its header")
    first = int(buf[:_HEADER].view("<u4")[0])
    n, head, width = first & ~ROWS, _HEADER, 0
    if first & ROWS:
        if buf.size < _HEADER + 4:
            raise PaletteError(f"palette chunk of {buf.size} bytes, shorter than its header")
        head += 4
        width = int(buf[_HEADER:head].view("<u4")[0])
        if width < 1 or size % width:
            raise PaletteError(f"palette chunk: {size} elements are not rows of {width}")
    planes = 2 if n > 256 else 1
    if buf.size != head + 2 * n + planes * size:
        raise PaletteError(f"palette chunk of {buf.size} bytes, expected "
                           f"{head + 2 * n + planes * size} for {n} values and "
                           f"{size} elements")
    if n == 0 and size:
        raise PaletteError(f"palette chunk: no values for {size} elements")
    from vhgen.store.palette_kernels import (  # numba: loaded when used
        lookup8,
        lookup16,
        rows8,
        rows16,
    )

    table = buf[head:head + 2 * n].view("<u2").astype(np.uint16)
    body = buf[head + 2 * n:]
    if n > 256:
        bad = (rows16(body[:size], body[size:], width, table, flat) if width
               else lookup16(body[:size], body[size:], table, flat))
    else:
        bad = rows8(body, width, table, flat) if width else lookup8(body, table, flat)
    if bad >= 0:
        raise PaletteError(f"palette chunk: index {bad} past its {n} values")


def decompress_into(decompress: Any, chunk: bytes, nbytes: int | None,
                    out: np.ndarray) -> None:
    """Decode a compressed palette chunk into ``out``: ``decompress(chunk[, dest])`` (a
    numcodecs zstd or blosc ``decompress``) into this thread's scratch space when the
    chunk states its decoded size ``nbytes`` (kept, grown as needed: no allocation per
    frame), then :func:`decode_into`."""
    if nbytes is None:
        decode_into(decompress(chunk), out)
        return
    buf = getattr(_local, "scratch", None)
    if buf is None or buf.size < nbytes:
        buf = _local.scratch = np.empty(nbytes, np.uint8)
    decode_into(decompress(chunk, buf[:nbytes]), out)


@dataclass(frozen=True)
class PaletteCodec(BytesBytesCodec):
    """The zarr v3 codec (``{"name": "vhgen.palette", "configuration": {"typesize": 2,
    "rows": true}}``; ``rows`` absent or false: the plain indexes, as stores written
    before 2026-11-29 hold them)."""

    is_fixed_size = False
    typesize: int = 2
    rows: bool = False

    def __init__(self, *, typesize: int = 2, rows: bool = False) -> None:
        if typesize != 2:
            raise ValueError(f"{NAME}: typesize must be 2 (uint16), got {typesize!r}")
        if not isinstance(rows, bool):
            raise ValueError(f"{NAME}: rows must be true or false, got {rows!r}")
        object.__setattr__(self, "typesize", 2)
        object.__setattr__(self, "rows", rows)

    def validate(self, *, shape: Any, dtype: Any, chunk_grid: Any) -> None:
        # zarr >= 3.1 passes its own dtype wrapper, 3.0 a numpy dtype
        native = dtype.to_native_dtype() if hasattr(dtype, "to_native_dtype") else dtype
        if np.dtype(native).itemsize != 2:
            raise ValueError(f"{NAME} encodes 2-byte integers (uint16), not {native}")

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PaletteCodec:
        if data.get("name") != NAME:
            raise ValueError(f"not a {NAME} codec: {data!r}")
        return cls(**(data.get("configuration") or {}))

    def to_dict(self) -> dict[str, Any]:
        conf: dict[str, Any] = {"typesize": self.typesize}
        if self.rows:
            conf["rows"] = True
        return {"name": NAME, "configuration": conf}

    def _decode_sync(self, chunk_bytes: Buffer, chunk_spec: ArraySpec) -> Buffer:
        size = int(np.prod(chunk_spec.shape))
        out = np.empty(size, np.uint16)
        decode_into(chunk_bytes.as_numpy_array(), out)
        return chunk_spec.prototype.buffer.from_array_like(
            out.astype("<u2", copy=False).view(np.uint8))

    def _encode_sync(self, chunk_bytes: Buffer, chunk_spec: ArraySpec) -> Buffer | None:
        data = chunk_bytes.as_numpy_array()
        if data.size % 2:
            raise ValueError(f"{NAME}: {data.size} bytes is not a whole number of uint16")
        width = int(chunk_spec.shape[-1]) if self.rows and chunk_spec.shape else None
        return chunk_spec.prototype.buffer.from_array_like(encode(data.view("<u2"), width))

    async def _decode_single(self, chunk_bytes: Buffer, chunk_spec: ArraySpec) -> Buffer:
        return await asyncio.to_thread(self._decode_sync, chunk_bytes, chunk_spec)

    async def _encode_single(self, chunk_bytes: Buffer,
                             chunk_spec: ArraySpec) -> Buffer | None:
        return await asyncio.to_thread(self._encode_sync, chunk_bytes, chunk_spec)

    def compute_encoded_size(self, _input_byte_length: int, _chunk_spec: ArraySpec) -> int:
        raise NotImplementedError


def register() -> None:
    """Make the codec known to zarr in this process (the entry point does it wherever
    vhgen is installed; this covers a checkout run without installing)."""
    from zarr.registry import register_codec

    register_codec(NAME, PaletteCodec)
