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
