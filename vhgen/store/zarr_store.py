"""The dataset store: a Zarr v3 group plus a Parquet manifest.

Contract (later work may add arrays and columns, never change these):

* ``depth``  (N, H, W) uint16 millimetres, 0 = no measurement;
* ``raw`` (N, H, W) uint16, optional: the sensor's 11-bit raw disparity (2047 = invalid),
  present when the config's ``output.arrays`` asks for it (the sensor's ``encode``
  effect must have ``raw11``; stores written before ``output.arrays`` existed have it
  whenever the sensor kept raw11);
* ``labels`` (N, H, W) uint8, 0 = background, 1..K = body parts; the group attributes
  ``label_names`` (K names, label k = names[k-1]) and ``label_colors`` ((K+1) x RGB,
  row 0 background) describe them;
* ``instances`` (N, H, W) uint8, 0 = no person, k = the k-th person of the frame's
  manifest row; ``classes`` (N, H, W) uint8 scene classes, named by the group attribute
  ``class_names`` (class c = names[c]: background, floor, wall, prop, person, ...);
  stores written before these existed lack both and stay readable;
* ``manifest.parquet`` inside the group folder, one row per frame (see
  :mod:`vhgen.store.manifest`).

Each array is sharded along frames: one shard holds ``frames_per_shard`` frames (one
chunk per frame inside), and exactly one task writes each shard, whole, once. A shard is
complete when its manifest part ``manifest/part-<shard>.parquet`` exists (written after
the arrays), which is what resuming checks; the merge at the end writes
``manifest.parquet`` and then removes the parts (a merged manifest marks its shards
complete).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from vhgen.errors import StoreError
from vhgen.scene.geometry import SCENE_CLASSES

CONTRACT_VERSION = 1
MANIFEST_PARTS = "manifest"
MANIFEST_FILE = "manifest.parquet"
MANIFEST_MERGING = MANIFEST_FILE + ".tmp"  # the merge writes here, then renames


CODECS = ("zstd", "lz4")

# The arrays a store can hold: name -> (dtype, fill value, zstd level). The levels were
# chosen by measurement (benchmarks/bench_codecs.py on a cluttered_room store, the table
# in docs/performance.md): zstd 7 shrinks noisy depth and raw by 14-16% against level 3
# and decodes them no slower, at ~11 ms a frame to encode; levels 9-15 gain at most 1 kB
# more (85.3 kB against 86.1 at 11) for 2-6x the encode time, which a GPU node's CPU
# workers pay on every frame, and 16+ (another 15%) take as long as a frame; the uint8
# arrays took level 12 (17-23% smaller, 1-3 ms each to encode; below). Byte or bit
# shuffling before zstd (blosc) made every array but instances larger. With the palette
# (vhgen.store.palette, output.palette: the default with zstd) the uint16 arrays take
# another 9-11% less at the same level and encode faster. Since 2026-11-29 the palette's
# indexes are stored as differences down the rows (configuration.rows): depth at zstd 3
# is then 2% smaller than it was at 7 and encodes in 0.4x the time (3.7 against 9.1 ms
# a frame on a cluttered_room store; at 7 it would be 9% smaller than before, in the
# old time), so depth takes level 3. The uint8 arrays took level 12 until later that day;
# at 3 the three together are 3.3 kB a frame larger (15.8 against 12.5 kB, of about 100)
# and encode in 0.7 against 6-8 ms (one core), which a GPU node's CPU workers pay on
# every frame (issue 28), so they take 3 as well (docs/performance.md "Store size"). The
# codecs of each array are recorded in its zarr.json, which is what readers go by: stores
# written with other levels or codecs read the same.
ARRAYS: dict[str, tuple[str, int, int]] = {
    "depth": ("uint16", 0, 3),
    "labels": ("uint8", 0, 3),
    "instances": ("uint8", 0, 3),
    "classes": ("uint8", 0, 3),
    "raw": ("uint16", 2047, 7),
}
REQUIRED_ARRAYS = ("depth", "labels")
# written unless the config's output.arrays says otherwise (raw doubles the depth's bytes
# and few users want it: it is opt-in)
DEFAULT_ARRAYS = ("depth", "labels", "instances", "classes")


def _codecs(codec: str, level: int, itemsize: int, palette: bool = False):
    """Compressors of one frame chunk. ``zstd`` (default): zstd at ``level``, the smallest;
    ``lz4``: blosc lz4 over bytes shuffled by ``itemsize``, about twice the size of zstd
    3 on depth and three times faster to decode (the same values either way). ``palette``:
    uint16 frames go through :mod:`vhgen.store.palette` first (one byte a pixel, as
    differences down the rows)."""
    from zarr.codecs import BloscCodec, ZstdCodec

    if codec not in CODECS:
        raise StoreError(f"unknown codec {codec!r} (known: {', '.join(CODECS)})")
    first = []
    if palette and itemsize == 2:
        from vhgen.store.palette import PaletteCodec, register

        register()
        first, itemsize = [PaletteCodec(rows=True)], 1
    if codec == "zstd":
        return [*first, ZstdCodec(level=level)]
    return [*first, BloscCodec(cname="lz4", clevel=5, shuffle="shuffle" if itemsize > 1
                               else "noshuffle", typesize=itemsize)]


def create_store(path: str | Path, *, num_frames: int, height: int, width: int,
                 frames_per_shard: int, attrs: dict, compression_level: int | None = None,
                 overwrite: bool = False, arrays: Sequence[str] = DEFAULT_ARRAYS,
                 codec: str = "zstd", palette: bool | None = None) -> None:
    """Create the group and its empty ``arrays`` (driver only, before any worker writes);
    ``codec``, ``palette``: see :func:`_codecs` (``palette`` None: with zstd);
    ``compression_level``: the zstd level of every array (None: each array's level in
    :data:`ARRAYS`)."""
    import zarr

    path = Path(path)
    if path.exists() and not overwrite:
        raise StoreError(f"{path} exists; pass overwrite (or resume) to reuse it")
    unknown = [a for a in arrays if a not in ARRAYS]
    if unknown:
        raise StoreError(f"unknown array {unknown[0]!r} (known: {', '.join(ARRAYS)})")
    root = zarr.open_group(str(path), mode="w", zarr_format=3)
    for name in [a for a in ARRAYS if a in arrays]:
        dtype, fill, level = ARRAYS[name]
        root.create_array(name, shape=(num_frames, height, width), dtype=dtype,
                          chunks=(1, height, width),
                          shards=(frames_per_shard, height, width),
                          compressors=_codecs(codec, compression_level or level,
                                              np.dtype(dtype).itemsize,
                                              codec == "zstd" if palette is None else palette),
                          fill_value=fill,
                          dimension_names=("frame", "y", "x"))
    root.attrs.update({"class_names": list(SCENE_CLASSES), **attrs,
                       "vhgen_contract": CONTRACT_VERSION})
    (path / MANIFEST_PARTS).mkdir(exist_ok=True)


def open_store(path: str | Path, mode: Literal["r", "r+"] = "r") -> Any:
    import zarr

    from vhgen.store.palette import register

    path = Path(path)
    if not (path / "zarr.json").is_file():
        raise StoreError(f"{path} is not a Zarr v3 group (no zarr.json)")
    register()  # installed vhgen registers it by entry point; this covers a bare checkout
    return zarr.open_group(str(path), mode=mode, zarr_format=3)


def set_codec_threads(count: int) -> None:
    """Compress (and decompress) with at most ``count`` threads in this process: zarr's
    pool, made at its first use, has one per core otherwise, and a frame worker is one of
    many processes on the machine: on a 16-core GPU node with 16 workers, a pool of 1
    each gave 17% more frames/s than 16 pools of 16 (docs/performance.md). The bytes
    written do not depend on it. ``ZARR_THREADING__MAX_WORKERS`` in the environment wins."""
    import zarr

    if "ZARR_THREADING__MAX_WORKERS" not in os.environ:
        zarr.config.set({"threading.max_workers": max(1, int(count))})


def _writer(array: Any) -> Any:
    """The array with every chunk written, even one equal to the fill value: zarr's check
    for such chunks (to omit them) compared each 640x480 frame to a fresh fill-value array,
    ~40% of a shard's write time; a frame that is all fill value is rare and reads back the
    same either way. (zarr < 3.1.6 has no ``with_config``: there an array opened while
    the global config says so carries the setting.)"""
    if hasattr(array, "with_config"):
        return array.with_config({"write_empty_chunks": True})
    import zarr

    with zarr.config.set({"array.write_empty_chunks": True}):
        return zarr.open_array(array.store_path, mode="r+", zarr_format=3)


def write_shard(path: str | Path, shard: int, frames_per_shard: int, depth: np.ndarray,
                labels: np.ndarray, raw: np.ndarray | None = None,
                extra: dict[str, np.ndarray] | None = None) -> None:
    """Write one whole shard of every array (the only writer of this shard); ``extra``
    holds further (n, H, W) arrays by name (``instances``, ``classes``), each of which
    the store must have, as it must ``raw`` when it is given; the caller leaves out the
    arrays the store was made without."""
    from vhgen.store.shard_files import array_layout, write_shard_file, writes_directly

    start = shard * frames_per_shard
    n = depth.shape[0]
    if labels.shape != depth.shape:
        raise StoreError(f"shard {shard}: depth {depth.shape} vs labels {labels.shape}")
    if depth.dtype != np.uint16 or labels.dtype != np.uint8:
        raise StoreError(f"shard {shard}: dtypes {depth.dtype}/{labels.dtype}, "
                         "expected uint16/uint8")
    arrays = {"depth": depth, "labels": labels,
              **({} if raw is None else {"raw": raw}), **(extra or {})}
    for name, arr in arrays.items():
        if name not in ARRAYS:
            raise StoreError(f"{path}: unknown array {name!r} (known: {', '.join(ARRAYS)})")
        dtype = np.dtype(ARRAYS[name][0])
        if arr.shape != depth.shape or arr.dtype != dtype:
            raise StoreError(f"shard {shard}: {name} {arr.shape} {arr.dtype}, expected "
                             f"{depth.shape} {dtype}")
    root = None
    for name, arr in arrays.items():
        # the layout create_store makes (zstd, sharded by frames): written straight to
        # its shard file, the bytes zarr would write; any other through zarr
        layout = array_layout(path, name)
        if (writes_directly(layout) and layout.frames_per_shard == frames_per_shard
                and layout.frames_of(shard) == (start, start + n - 1)):
            write_shard_file(layout, shard, arr, _codec_threads())
            continue
        if root is None:
            root = open_store(path, mode="r+")
        if name not in root:
            raise StoreError(f"{path}: no {name!r} array (the store was made by an older "
                             "vhgen); generate it again with --overwrite")
        _writer(root[name])[start:start + n] = arr


def _codec_threads() -> int:
    """The threads this process compresses with (:func:`set_codec_threads`)."""
    import zarr

    return max(1, int(zarr.config.get("threading.max_workers") or os.cpu_count() or 1))


def completed_shards(path: str | Path) -> set[int]:
    """Shards whose manifest part exists (their arrays were written before it), and the
    shards of a merged ``manifest.parquet`` (the merge removes the parts)."""
    parts = Path(path) / MANIFEST_PARTS
    done = {int(p.stem.split("-")[1]) for p in parts.glob("part-*.parquet")}
    merged = Path(path) / MANIFEST_FILE
    if merged.is_file():
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            shards = pq.read_table(merged, columns=["shard"]).column("shard")
        except (OSError, pa.ArrowException):
            return done  # unreadable: its shards are rendered again, then merged anew
        done |= {int(s) for s in np.unique(shards.to_numpy())}
    return done


def clean_partials(path: str | Path) -> int:
    """Remove temp files a killed writer left behind; returns how many."""
    n = 0
    for p in Path(path).rglob("*.partial"):
        p.unlink()
        n += 1
    for p in (Path(path) / MANIFEST_PARTS).glob("*.tmp"):
        p.unlink()
        n += 1
    merging = Path(path) / MANIFEST_MERGING  # a merge the driver did not finish
    if merging.is_file():
        merging.unlink()
        n += 1
    return n


def read_attrs(path: str | Path) -> dict:
    return json.loads(json.dumps(dict(open_store(path).attrs)))


def read_frames(root: Any, names: Sequence[str], frames: np.ndarray,
                frames_per_shard: int) -> dict[str, np.ndarray]:
    """Read ``frames`` (sorted or not) of each array; one contiguous slice per shard touched.

    Returns name -> (len(frames), ...) arrays in the order of ``frames``.
    """
    frames = np.asarray(frames, np.int64)
    out: dict[str, np.ndarray] = {}
    shards = frames // frames_per_shard
    for name in names:
        arr = root[name]
        res = np.empty((len(frames), *arr.shape[1:]), arr.dtype)
        for s in np.unique(shards):
            sel = np.nonzero(shards == s)[0]
            lo, hi = int(frames[sel].min()), int(frames[sel].max())
            block = arr[lo:hi + 1]
            res[sel] = block[frames[sel] - lo]
        out[name] = res
    return out
