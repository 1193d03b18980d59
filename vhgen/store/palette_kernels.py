"""The compiled look-ups of :mod:`vhgen.store.palette` (numba, cached on disk): apart, so
that registering the codec with zarr does not import numba; the first frame decoded does.
"""

from __future__ import annotations

import numba
import numpy as np


# The look-ups, compiled (cached on disk) and without the GIL: the store reader decodes
# frames in threads. One pass, a table in L1 cache: ~0.2 ms for 640x480 against ~0.3 ms
# for numpy's take over a table of value pairs, and they scale with threads where the
# numpy calls around a take did not.
@numba.njit(cache=True, nogil=True)
def lookup8(plane, table, out):  # pragma: no cover  (compiled)
    """out[i] = table[plane[i]]; returns an index past the table (table[0] is written
    for it), or -1."""
    n = table.shape[0]
    bad = -1
    for i in range(out.shape[0]):
        k = np.int64(plane[i])
        if k >= n:
            bad = k
            k = 0
        out[i] = table[k]
    return bad


@numba.njit(cache=True, nogil=True)
def lookup16(lo, hi, table, out):  # pragma: no cover  (compiled)
    """out[i] = table[lo[i] | hi[i] << 8], as :func:`lookup8`."""
    n = table.shape[0]
    bad = -1
    for i in range(out.shape[0]):
        k = np.int64(lo[i]) | (np.int64(hi[i]) << 8)
        if k >= n:
            bad = k
            k = 0
        out[i] = table[k]
    return bad


# The differences down the rows added up a row at a time, in three loops over the row
# (add; look up; the largest index) that the compiler vectorises: as fast as lookup8
# (~0.2 ms a frame), where one loop doing all three took twice as long.
@numba.njit(cache=True, nogil=True)
def _rows(plane, width, table, size, out):  # pragma: no cover  (compiled)
    """out[i] = table[k] where k, per column, adds up ``plane`` down the rows of
    ``width`` modulo ``size`` (the plane's dtype: 256 or 65536)."""
    n = table.shape[0]
    padded = np.zeros(size, np.uint16)  # any index of the dtype reads it; past n: reported
    padded[:n] = table[:size]
    acc = np.zeros(width, plane.dtype)
    most = 0
    for r in range(out.shape[0] // width):
        base = r * width
        for j in range(width):
            acc[j] += plane[base + j]  # stored in the plane's dtype: modulo its size
        for j in range(width):
            out[base + j] = padded[acc[j]]
        for j in range(width):
            most = max(most, acc[j])
    return most if most >= n and out.shape[0] else -1


@numba.njit(cache=True, nogil=True)
def rows8(plane, width, table, out):  # pragma: no cover  (compiled)
    """The indexes stored as differences down the rows of ``width`` (modulo 256), looked
    up; as :func:`lookup8`."""
    return _rows(plane, width, table, 256, out)


@numba.njit(cache=True, nogil=True)
def rows16(lo, hi, width, table, out):  # pragma: no cover  (compiled)
    """:func:`rows8` over two planes (modulo 65536), as :func:`lookup16`."""
    plane = np.empty(lo.shape[0], np.uint16)  # uint16, so that the sums wrap at 65536
    for i in range(lo.shape[0]):
        plane[i] = np.uint16(lo[i]) | (np.uint16(hi[i]) << np.uint16(8))
    return _rows(plane, width, table, 65536, out)


@numba.njit(cache=True, nogil=True)
def table_of(flat, rank, table):  # pragma: no cover  (compiled)
    """The sorted distinct values of ``flat`` into ``table`` (65536,) and each value's
    index among them into ``rank`` (65536,); returns how many there are."""
    present = np.zeros(65536, np.uint8)
    for i in range(flat.shape[0]):
        present[flat[i]] = 1
    n = 0
    for v in range(65536):
        if present[v]:
            rank[v] = n
            table[n] = v
            n += 1
    return n


@numba.njit(cache=True, nogil=True)
def index_planes(flat, rank, width, two, planes):  # pragma: no cover  (compiled)
    """Each element's index (``rank`` of its value) into ``planes``: the low bytes, then,
    when ``two``, the high bytes after them; with ``width`` > 0 each index less the one a
    row above (modulo 65536; the first row as it is). A row at a time, in loops the
    compiler vectorises (look up; subtract; split the bytes)."""
    size = flat.shape[0]
    w = width if width else max(size, 1)
    above = np.zeros(w, np.uint16)
    cur = np.empty(w, np.uint16)
    diff = np.empty(w, np.uint16)
    for r in range(size // w):
        base = r * w
        for j in range(w):
            cur[j] = rank[flat[base + j]]
        if width:
            for j in range(w):
                diff[j] = cur[j] - above[j]  # stored as uint16: modulo 65536
            above, cur = cur, above
            out = diff
        else:
            out = cur
        for j in range(w):
            planes[base + j] = np.uint8(out[j] & 0xFF)
        if two:
            for j in range(w):
                planes[size + base + j] = np.uint8(out[j] >> 8)
