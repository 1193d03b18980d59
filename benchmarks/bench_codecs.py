"""Bytes per frame and encode / decode time of each array under candidate codecs.

    python benchmarks/bench_codecs.py STORE [--frames 64] [--arrays depth labels ...]
        [--codecs zstd-3 blosc-zstd-5-shuffle ...] [--against OTHER_STORE]
    python benchmarks/bench_codecs.py STORE --write [--frames 64] [--levels default uint8:12]

Reads up to ``--frames`` frames of each array of a finished store (for example one made
by ``vhgen generate configs/scenes/cluttered_room.yaml --max-frames 128``) and compresses
every frame alone, as the store's one-frame inner chunks are, with each candidate. A
candidate is ``zstd-LEVEL`` (zarr's ``ZstdCodec``) or ``blosc-CNAME-CLEVEL-SHUFFLE``
(zarr's ``BloscCodec``: cname zstd, lz4, lz4hc, zlib; shuffle noshuffle, shuffle or
bitshuffle), both codecs of the zarr v3 specification that zarr 3.0.8 (the floor) writes
and reads, or, for uint16 arrays, ``palette-zstd-LEVEL``: vhgen's ``vhgen.palette`` filter
(:mod:`vhgen.store.palette`) before zstd, and ``palette-rows-zstd-LEVEL`` the same with
the indexes as differences down the rows (what vhgen writes since 2026-11-29). Times
are one core: blosc's own threads are off, as they are in the store reader's decode
threads. The candidates of an array take
turns for ``--repeat`` passes over the frames and each cell is a candidate's fastest
pass. ``x store``: the candidate's bytes over the store's own for that array (its inner
chunks, from the shard indexes). ``--against`` compares two stores of the same frames
written with different codecs instead: ms per frame to decode each array through the
training reader (``vhgen.store.shards.ShardReader``, one thread), the stores taking
turns. ``--write`` times the worker's last step instead: ``write_shard`` of the store's
first ``--frames`` frames (every array it has) into new stores, with one codec thread as
a GPU node's worker has, straight to the shard files (what vhgen does) and through
zarr-python (what it did before), at the levels of ``--levels`` (``default``: the
per-array levels of ``ARRAYS``; ``N``: every array at N; ``uint8:N``: the uint8 arrays at
N, as vhgen wrote them before 2026-11-29), all taking turns for ``--repeat`` passes; ms per frame
(median and least) and kB per frame of the arrays written.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

DEFAULT_CODECS = {
    "uint16": ["zstd-3", "zstd-6", "zstd-9", "zstd-11", "zstd-12", "zstd-15", "zstd-16",
               "zstd-19", "blosc-zstd-3-shuffle", "blosc-zstd-5-shuffle",
               "blosc-zstd-5-bitshuffle", "blosc-lz4-5-shuffle", "palette-zstd-3",
               "palette-zstd-5", "palette-zstd-7", "palette-zstd-11", "palette-zstd-16",
               "palette-rows-zstd-1", "palette-rows-zstd-3", "palette-rows-zstd-5",
               "palette-rows-zstd-7", "palette-rows-zstd-11"],
    "uint8": ["zstd-3", "zstd-6", "zstd-9", "zstd-12", "zstd-15", "zstd-19",
              "blosc-zstd-5-bitshuffle", "blosc-lz4-5-noshuffle"],
}


class PaletteZstd:
    """``vhgen.palette`` then zstd, as a store's depth chunks are written and read;
    ``rows``: the indexes as differences down the rows (``configuration.rows``)."""

    def __init__(self, level: int, rows: bool = False):
        import numcodecs

        self.zstd = numcodecs.Zstd(level=level)
        self.rows = rows

    def encode(self, frame: np.ndarray) -> bytes:
        from vhgen.store import palette

        return self.zstd.encode(palette.encode(frame, frame.shape[-1] if self.rows else None))

    def decode(self, chunk: bytes, out: np.ndarray) -> np.ndarray:
        import numcodecs.zstd

        from vhgen.store import palette
        from vhgen.store.shards import zstd_content_size

        # as the store reader does
        palette.decompress_into(numcodecs.zstd.decompress, chunk, zstd_content_size(chunk),
                                out)
        return out


def numcodec(name: str, itemsize: int) -> Any:
    """The numcodecs object behind the zarr codec a candidate name stands for."""
    import numcodecs

    kind, *rest = name.split("-")
    if kind == "palette" and itemsize == 2 and len(rest) == 2 and rest[0] == "zstd":
        return PaletteZstd(int(rest[1]))
    if (kind == "palette" and itemsize == 2 and len(rest) == 3 and rest[:2] == ["rows", "zstd"]):
        return PaletteZstd(int(rest[2]), rows=True)
    if kind == "zstd":
        return numcodecs.Zstd(level=int(rest[0]))
    if kind == "blosc":
        cname, clevel, shuffle = rest
        code = {"noshuffle": numcodecs.Blosc.NOSHUFFLE, "shuffle": numcodecs.Blosc.SHUFFLE,
                "bitshuffle": numcodecs.Blosc.BITSHUFFLE}[shuffle]
        return numcodecs.Blosc(cname=cname, clevel=int(clevel), shuffle=code)
    raise SystemExit(f"unknown candidate {name!r}: zstd-LEVEL, blosc-CNAME-CLEVEL-SHUFFLE "
                     "or (uint16) palette-zstd-LEVEL, palette-rows-zstd-LEVEL")


def stored_bytes(store: Path, name: str, frames: int) -> float | None:
    """Mean bytes of the store's inner chunks of ``name`` over its first ``frames`` frames
    (None when the array is not in the sharded layout)."""
    from vhgen.store.shards import EMPTY, array_layout

    layout = array_layout(store, name)
    if layout is None:
        return None
    sizes = []
    for shard in range(-(-frames // layout.frames_per_shard)):
        path = layout.shard_path(shard)
        n = layout.frames_per_shard
        data = path.read_bytes()
        size = 16 * n + (4 if layout.index_crc else 0)
        idx = np.frombuffer(data[len(data) - size:][:16 * n] if layout.index_at_end
                            else data[:16 * n], "<u8").reshape(n, 2)
        sizes += [int(b) for o, b in idx if o != EMPTY]
    return float(np.mean(sizes[:frames]))


def measure(frames: np.ndarray, names: list[str], repeat: int
            ) -> dict[str, tuple[float, float, float]]:
    """name -> (bytes per frame, encode ms per frame, decode ms per frame) of each
    candidate. The candidates take turns, pass after pass, and each keeps its fastest
    pass: on a shared machine another job's burst slows one pass, not one candidate."""
    codecs = {n: numcodec(n, frames.dtype.itemsize) for n in names}
    chunks = {n: [c.encode(f) for f in frames] for n, c in codecs.items()}
    out = np.empty(frames.shape[1:], frames.dtype)
    for n, c in codecs.items():  # the round trip is exact
        for f, chunk in zip(frames, chunks[n], strict=True):
            c.decode(chunk, out)
            if not np.array_equal(out, f):
                raise SystemExit(f"{n}: the decoded frame differs")
    enc = {n: np.inf for n in names}
    dec = {n: np.inf for n in names}
    for _ in range(repeat):
        for n, c in codecs.items():
            t0 = time.perf_counter()
            for f in frames:
                c.encode(f)
            t1 = time.perf_counter()
            for chunk in chunks[n]:
                c.decode(chunk, out)
            t2 = time.perf_counter()
            enc[n], dec[n] = min(enc[n], t1 - t0), min(dec[n], t2 - t1)
    k = 1e3 / len(frames)
    return {n: (float(np.mean([len(c) for c in chunks[n]])), k * enc[n], k * dec[n])
            for n in names}


def read_ms(stores: list[Path], names: list[str], frames: int, repeat: int
            ) -> dict[tuple[Path, str], float]:
    """(store, array) -> ms per frame to decode the first ``frames`` frames of each array
    through :class:`vhgen.store.shards.ShardReader` (the training reader's path, one
    thread), the stores taking turns, each cell its fastest pass."""
    from vhgen.store.shards import ShardReader

    readers = {s: ShardReader(s, names, threads=1) for s in stores}
    best = {(s, n): np.inf for s in stores for n in names}
    for _ in range(repeat):
        for s, reader in readers.items():
            for n in names:
                out = reader.empty(n, frames)
                t0 = time.perf_counter()
                reader.read_into([(n, f, out[f]) for f in range(frames)])
                best[s, n] = min(best[s, n], time.perf_counter() - t0)
    return {k: 1e3 * v / frames for k, v in best.items()}


def _set_level(store: Path, names: list[str], level: int) -> None:
    """Set the zstd level of arrays ``names`` of a new store in their zarr.json (which
    zarr and vhgen's writer both go by)."""
    import json

    for name in names:
        meta_path = store / name / "zarr.json"
        meta = json.loads(meta_path.read_text())
        inner = meta["codecs"][0]["configuration"]["codecs"]
        assert inner[-1]["name"] == "zstd", inner
        inner[-1]["configuration"]["level"] = level
        meta_path.write_text(json.dumps(meta))


def write_ms(store: Path, frames: int, levels: list[str], repeat: int) -> None:
    """Print the --write table (see the module docstring)."""
    import shutil
    import tempfile

    from vhgen.store.zarr_store import (
        ARRAYS,
        _writer,
        create_store,
        open_store,
        set_codec_threads,
        write_shard,
    )

    set_codec_threads(1)
    root = open_store(store)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        names = [n for n in ARRAYS if n in set(root.array_keys())]
    n = min(frames, root["depth"].shape[0])
    data = {k: np.ascontiguousarray(root[k][:n]) for k in names}
    per = int(root["depth"].shards[0]) if root["depth"].shards else 8
    h, w = data["depth"].shape[1:]
    runs: dict[tuple[str, str], list[float]] = {}
    sizes: dict[tuple[str, str], float] = {}
    work = Path(tempfile.mkdtemp(prefix="vhgen-write-"))
    try:
        for _ in range(repeat):
            for level in levels:
                for how in ("direct", "zarr"):
                    out = work / f"{how}-{level}.zarr"
                    shutil.rmtree(out, ignore_errors=True)
                    every = None if level == "default" or ":" in level else int(level)
                    create_store(out, num_frames=n, height=h, width=w, frames_per_shard=per,
                                 attrs={}, arrays=names, compression_level=every)
                    if ":" in level:  # uint8:L, the per-array levels but the uint8 ones
                        _set_level(out, [k for k in names if ARRAYS[k][0] == "uint8"],
                                   int(level.split(":")[1]))
                    t0 = time.perf_counter()
                    for s in range(-(-n // per)):
                        part = {k: v[s * per:(s + 1) * per] for k, v in data.items()}
                        if how == "direct":
                            write_shard(out, s, per, part["depth"], part["labels"],
                                        part.get("raw"), extra={k: part[k] for k in part
                                                               if k not in ("depth", "labels",
                                                                            "raw")})
                        else:
                            group = open_store(out, mode="r+")
                            for k, v in part.items():
                                _writer(group[k])[s * per:s * per + len(v)] = v
                    runs.setdefault((level, how), []).append(time.perf_counter() - t0)
                    sizes[level, how] = sum(f.stat().st_size for k in names
                                            for f in (out / k).rglob("*")
                                            if f.is_file() and f.name != "zarr.json") / n
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"{store}: write_shard of the first {n} frames ({', '.join(names)}), shards of "
          f"{per}, one codec thread, {repeat} passes in turns")
    print("| levels | written | ms per frame (median / least) | kB per frame |")
    print("|---|---|---:|---:|")
    for (level, how), v in runs.items():
        what = "straight to the shard files" if how == "direct" else "through zarr-python"
        print(f"| {level} | {what} | {1e3 * np.median(v) / n:.2f} / {1e3 * min(v) / n:.2f} "
              f"| {sizes[level, how] / 1e3:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("store", type=Path)
    ap.add_argument("--frames", type=int, default=64, help="frames of each array measured")
    ap.add_argument("--arrays", nargs="*", help="default: every array of the store")
    ap.add_argument("--codecs", nargs="*", help="candidates (default: a set per dtype)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--against", type=Path, help="another store of the same frames: "
                    "instead of the candidates, decode both stores' arrays through the "
                    "store reader, side by side")
    ap.add_argument("--write", action="store_true",
                    help="time write_shard, straight to the files and through zarr")
    ap.add_argument("--levels", nargs="*", default=["default", "uint8:12"],
                    help="with --write: zstd levels: default (ARRAYS'), N (every array) "
                    "or uint8:N (ARRAYS' but the uint8 arrays at N, as before 2026-11-29)")
    args = ap.parse_args()
    if args.write:
        write_ms(args.store, args.frames, args.levels, max(args.repeat, 3))
        return

    import numcodecs.blosc

    from vhgen.store.zarr_store import open_store

    numcodecs.blosc.use_threads = False
    root = open_store(args.store)
    with warnings.catch_warnings():  # the manifest and report files are not zarr nodes
        warnings.simplefilter("ignore")
        names = args.arrays or sorted(root.array_keys())
    if args.against:
        stores = [args.store, args.against]
        names = [n for n in names if (args.against / n / "zarr.json").is_file()]
        n_frames = min(args.frames, root[names[0]].shape[0])
        ms = read_ms(stores, names, n_frames, max(args.repeat, 7))
        print(f"decode ms per frame, first {n_frames} frames, ShardReader, one thread")
        print("| array | " + " | ".join(str(s) for s in stores) + " |")
        print("|---|" + "---:|" * len(stores))
        for n in [*names, "all"]:
            cells = [sum(ms[s, m] for m in names) if n == "all" else ms[s, n]
                     for s in stores]
            print(f"| {n} | " + " | ".join(f"{c:.2f}" for c in cells) + " |")
        return
    print(f"{args.store}: first {args.frames} frames; bytes and ms per frame, one core")
    print("| array     | codec                   |   kB | x store | encode ms | decode ms |")
    print("|-----------|-------------------------|------|---------|-----------|-----------|")
    for name in names:
        arr = root[name]
        frames = np.ascontiguousarray(arr[:min(args.frames, arr.shape[0])])
        now = stored_bytes(args.store, name, len(frames))
        cands = args.codecs or DEFAULT_CODECS[str(frames.dtype)]
        for cand, (size, enc, dec) in measure(frames, cands, args.repeat).items():
            ratio = f"{size / now:7.2f}" if now else "      -"
            print(f"| {name:9s} | {cand:23s} | {size / 1e3:4.1f} | {ratio} | {enc:9.2f} "
                  f"| {dec:9.2f} |", flush=True)


if __name__ == "__main__":
    main()
