"""LZF (liblzf, Marc Lehmann; the codec of PCD ``binary_compressed``) in numba.

Format: a stream of chunks, each starting with a control byte ``c``.

* ``c < 32``: a literal run; the next ``c + 1`` bytes are copied.
* else: a back-reference of length ``(c >> 5) + 2`` (when ``c >> 5 == 7`` the next byte
  adds to it), at distance ``((c & 31) << 8) + next byte + 1`` behind the output
  position; source and destination may overlap (runs).

The decoder checks every read and write against the buffers, so a damaged stream is an
error code, never a crash. Both functions compile on first use (cached on disk); this
module imports numba, so import it inside functions.
"""

from __future__ import annotations

import numba
import numpy as np

# decoder error codes (negative return values)
E_INPUT = -1  # the stream ends inside a chunk
E_OUTPUT = -2  # the stream decodes to more bytes than the output holds
E_REF = -3  # a back-reference before the start of the output

_MESSAGES = {E_INPUT: "the LZF stream ends inside a chunk",
             E_OUTPUT: "the LZF stream decodes to more bytes than the header says",
             E_REF: "an LZF back-reference points before the start of the data"}


@numba.njit(cache=True, nogil=True)
def _decompress(src, dst):  # pragma: no cover  (compiled)
    ip = 0
    op = 0
    n_in = src.shape[0]
    n_out = dst.shape[0]
    while ip < n_in:
        c = np.int64(src[ip])
        ip += 1
        if c < 32:
            run = c + 1
            if ip + run > n_in:
                return E_INPUT
            if op + run > n_out:
                return E_OUTPUT
            for k in range(run):
                dst[op + k] = src[ip + k]
            ip += run
            op += run
        else:
            length = c >> 5
            ref = op - ((c & 31) << 8) - 1
            if ip >= n_in:
                return E_INPUT
            if length == 7:
                length += np.int64(src[ip])
                ip += 1
                if ip >= n_in:
                    return E_INPUT
            ref -= np.int64(src[ip])
            ip += 1
            length += 2
            if op + length > n_out:
                return E_OUTPUT
            if ref < 0:
                return E_REF
            for k in range(length):  # byte by byte: overlapping runs repeat
                dst[op + k] = dst[ref + k]
            op += length
    return op


@numba.njit(cache=True, nogil=True)
def _compress(src, dst):  # pragma: no cover  (compiled)
    """Greedy LZF with a 3-byte hash table (liblzf's scheme, without its lazy matching).
    Returns the compressed length, or -1 when ``dst`` is too small."""
    n = src.shape[0]
    hbits = 14
    table = np.full(1 << hbits, -1, np.int64)
    ip = 0
    op = 1  # the first literal run's control byte goes at lit_at
    lit_at = 0
    lit = 0
    cap = dst.shape[0]
    if cap < 1:
        return -1
    while ip < n:
        best = 0
        ref = -1
        if ip + 2 < n:
            h = ((np.int64(src[ip]) << 16) | (np.int64(src[ip + 1]) << 8)
                 | np.int64(src[ip + 2]))
            h = ((h * 2654435761) >> 10) & ((1 << hbits) - 1)
            ref = table[h]
            table[h] = ip
            if ref >= 0 and ip - ref - 1 < 8192 and src[ref] == src[ip] and \
                    src[ref + 1] == src[ip + 1] and src[ref + 2] == src[ip + 2]:
                maxlen = min(264, n - ip)
                best = 3
                while best < maxlen and src[ref + best] == src[ip + best]:
                    best += 1
        if best >= 3:
            if lit == 0:  # no pending literals: drop the reserved control byte
                op -= 1
            else:
                dst[lit_at] = lit - 1
            off = ip - ref - 1
            ln = best - 2
            if op + 3 > cap:
                return -1
            if ln < 7:
                dst[op] = (ln << 5) | (off >> 8)
                op += 1
            else:
                dst[op] = (7 << 5) | (off >> 8)
                dst[op + 1] = ln - 7
                op += 2
            dst[op] = off & 255
            op += 1
            ip += best
            lit_at = op
            op += 1  # reserve the next literal run's control byte
            lit = 0
            if op > cap:
                return -1
        else:
            if op >= cap:
                return -1
            dst[op] = src[ip]
            op += 1
            ip += 1
            lit += 1
            if lit == 32:
                dst[lit_at] = 31
                lit = 0
                lit_at = op
                op += 1
                if op > cap:
                    return -1
    if lit == 0:
        op -= 1
    else:
        dst[lit_at] = lit - 1
    return op


def decompress(data: bytes | np.ndarray, size: int) -> np.ndarray:
    """LZF bytes -> exactly ``size`` bytes (uint8). ValueError with the reason when the
    stream is damaged or decodes to another size."""
    src = np.frombuffer(data, np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) \
        else np.ascontiguousarray(data, np.uint8)
    dst = np.empty(size, np.uint8)
    n = int(_decompress(src, dst))
    if n < 0:
        raise ValueError(_MESSAGES[n])
    if n != size:
        raise ValueError(f"the LZF stream decodes to {n} bytes, the header says {size}")
    return dst


def compress(data: bytes | np.ndarray) -> bytes:
    """Bytes -> an LZF stream with back-references (any input compresses to at most
    n + n/32 + 1 bytes)."""
    src = np.frombuffer(data, np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) \
        else np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    dst = np.empty(src.size + src.size // 32 + 16, np.uint8)
    n = int(_compress(src, dst))
    if n < 0:  # cannot happen with the bound above; keep the check honest
        raise RuntimeError("LZF output buffer too small")
    return dst[:n].tobytes()
