"""Reading a store for training: a map-style dataset, batched reads, a stream, Ray Data.

    import vhgen.dataset
    ds = vhgen.dataset.open("out/default.zarr")          # len(ds) frames
    item = ds[0]    # {"frame", "depth" (H, W) uint16, "labels" (H, W) uint8, "raw"?, "manifest"}
    batch = ds.get_batch([5, 0, 3])   # {"frame" (3,), "depth" (3, H, W), ..., "manifest"}
    walk = ds.filter(avatar_id=[0, 1]).filter(lambda t: pc.greater(t["body_pixels"], 5000))
    for i in walk.sampler(seed=0, epoch=3): walk[i]      # shard by shard, shuffled
    for batch in ds.stream(seed=0, epoch=3, batch_size=32): ...   # shards read in order

:class:`FrameDataset` has ``__len__``, ``__getitem__`` and ``__getitems__`` and pickles to a
few numbers, so PyTorch's ``DataLoader`` uses it as is (``DataLoader(ds,
sampler=ds.sampler(seed), batch_size=...)`` reads each batch with one ``__getitems__``
call), in worker processes too; :meth:`FrameDataset.stream` is the iterable form for
large jobs. vhgen never imports torch. Frames are decoded straight from the shard files
(:mod:`vhgen.store.shards`): a request decodes the inner chunk of each frame and array it
needs, once, in threads. :func:`to_ray` gives the same frames as a Ray Data dataset.

Memory per process: ``ds[i]`` keeps at most one shard's frames decoded (``frames_per_shard``
frames of each selected array, those of the last shard it read ahead in); ``get_batch`` and
``__getitems__`` keep nothing once they return; a stream keeps the batch it yields and one
read ahead (``2 * batch_size`` frames, or ``2 * frames_per_shard`` frame by frame). Shard
indexes (16 bytes per frame and array) are cached for at most 4,096 shards.
"""

from __future__ import annotations

import importlib
import json
import logging
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.errors import ShardError, StoreError
from vhgen.store.manifest import (
    ARRAY_COLUMNS,
    ManifestColumns,
    array_dtype,
    read_manifest_table,
    read_parts,
)
from vhgen.store.shards import ShardReader
from vhgen.store.zarr_store import MANIFEST_FILE, completed_shards, open_store, read_frames

log = logging.getLogger(__name__)

# contract arrays first, in this order; other (N, ...) arrays of the group follow by name
CONTRACT_ORDER = ("depth", "labels", "raw")


def _array_names(store: Path, num_frames: int) -> list[str]:
    """The group's arrays with ``num_frames`` along axis 0, contract arrays first."""
    found = []
    for meta in sorted(store.glob("*/zarr.json")):
        try:
            d = json.loads(meta.read_text())
        except (OSError, ValueError):
            continue
        if d.get("node_type") == "array" and d.get("shape", [None])[0] == num_frames:
            found.append(meta.parent.name)
    return [n for n in CONTRACT_ORDER if n in found] + sorted(
        n for n in found if n not in CONTRACT_ORDER)


def _shard_groups(shard_of: np.ndarray) -> list[np.ndarray]:
    """Positions grouped by shard, shards ascending, positions ascending in each."""
    shards = np.unique(shard_of)
    order = np.argsort(shard_of, kind="stable")
    return np.split(order, np.searchsorted(shard_of[order], shards)[1:]) if len(order) else []


class ShardSampler:
    """Dataset positions grouped by shard: shard order and frames within each shard shuffled.

    Iterating gives every position of the dataset (of this replica) exactly once per epoch;
    ``seed`` and ``epoch`` (``set_epoch``, as PyTorch's DistributedSampler) fix the order.
    With ``num_replicas > 1`` each replica takes every ``num_replicas``-th shard of the
    shuffled shard order (replicas may differ in length by up to one shard).
    """

    def __init__(self, shard_of: np.ndarray, *, seed: int = 0, shuffle: bool = True,
                 num_replicas: int = 1, rank: int = 0, epoch: int = 0):
        if num_replicas < 1 or not 0 <= rank < num_replicas:
            raise ValueError(f"rank {rank} is outside [0, num_replicas={num_replicas})")
        self.shard_of = np.asarray(shard_of, np.int64)
        self.seed, self.shuffle, self.epoch = int(seed), bool(shuffle), int(epoch)
        self.num_replicas, self.rank = int(num_replicas), int(rank)

    def set_epoch(self, epoch: int) -> None:
        """Use ``epoch``'s order from the next iteration on."""
        self.epoch = int(epoch)

    def _groups(self) -> list[np.ndarray]:
        groups = _shard_groups(self.shard_of)
        if self.shuffle:
            rng = np.random.default_rng([self.seed, self.epoch])
            groups = [groups[j] for j in rng.permutation(len(groups))]
            groups = [rng.permutation(g) for g in groups]
        return groups[self.rank::self.num_replicas]

    def __iter__(self) -> Iterator[int]:
        for g in self._groups():
            yield from (int(i) for i in g)

    def __len__(self) -> int:
        return int(sum(len(g) for g in self._groups()))


class FrameDataset:
    """Random access to the frames of a store (map-style: ``len``, ``[i]``), and batches.

    ``ds[i]`` is a dict: ``frame`` (int, the frame index in the store), one (H, W) array per
    array of the store (``depth`` uint16 mm, ``labels`` uint8, ``raw`` uint16 if present,
    any later array likewise) and ``manifest``, the frame's manifest row as a dict
    (``world_to_camera`` as a (4, 4) float64 array, ``joints_cam`` as (J, 3) float32 metres
    in the camera frame, ``body_offset`` (3,) float64, JSON columns as strings).
    Returned arrays are the caller's: changing them changes nothing in the reader.
    :meth:`get_batch` reads many positions at once (fastest), ``__getitems__`` gives them
    as a list of such dicts (PyTorch's ``DataLoader`` calls it for each batch).

    cache : ``"shard"`` (default): when ``ds[i]`` reads a second frame of a shard in a row
        it decodes the rest of that shard's frames at once, in threads, and keeps them
        until asked for (at most one shard); best with :meth:`sampler`. ``"frame"``: every
        access decodes its frame only. Either way a random access decodes one frame.
    threads : decode threads of this process (default ``min(4, cpu count)``; with many
        DataLoader workers, 1).
    partial : open a store still being written (no ``manifest.parquet`` yet): the frames
        of the shards finished so far.
    """

    def __init__(self, store: str | Path, *, arrays: Sequence[str] | None = None,
                 columns: Sequence[str] | None = None, cache: str = "shard",
                 frames: np.ndarray | None = None, threads: int | None = None,
                 partial: bool = False):
        if cache not in ("shard", "frame"):
            raise ValueError(f"cache must be 'shard' or 'frame', got {cache!r}")
        self.store = str(Path(store).expanduser())
        path = Path(self.store)
        root = open_store(path)
        self.attrs: dict[str, Any] = json.loads(json.dumps(dict(root.attrs)))
        man_path = path / MANIFEST_FILE
        cols = None if columns is None else list(dict.fromkeys(["frame", *columns]))
        if man_path.is_file():
            try:
                table = read_manifest_table(man_path, cols).sort_by("frame")
            except (KeyError, ValueError) as e:
                raise StoreError(f"{man_path}: {e}") from None
        elif partial:
            table = read_parts(path)
            if table is None:
                raise StoreError(f"{path}: no shard finished yet (no manifest parts)")
            if cols is not None:
                missing = [c for c in cols if c not in table.column_names]
                if missing:
                    raise StoreError(f"{path}: no manifest column {missing[0]!r}")
                table = table.select(cols)
        else:
            done = len(completed_shards(path))
            raise StoreError(f"{path}: no {MANIFEST_FILE}: still being written or stopped "
                             f"({done} shards finished; finish it with 'vhgen generate ... "
                             "--resume', or open it with partial=True to read those)")
        if not (path / "depth" / "zarr.json").is_file():
            raise StoreError(f"{path}: no 'depth' array; not a vhgen store")
        self.num_frames = int(root["depth"].shape[0])
        available = _array_names(path, self.num_frames)
        if arrays is None:
            arrays = available
        unknown = [a for a in arrays if a not in available]
        if unknown:
            raise StoreError(f"{path}: no array {unknown[0]!r} (available: "
                             f"{', '.join(available)})")
        self.arrays = tuple(arrays)
        d = root["depth"]
        self.frames_per_shard = int(d.shards[0] if d.shards else d.chunks[0])
        self.columns = None if columns is None else tuple(columns)
        self.cache = cache
        self.threads = threads
        self.partial = bool(partial)
        all_frames = table.column("frame").to_numpy()
        if frames is not None:
            pos = np.searchsorted(all_frames, frames)
            if len(frames) and (pos.max() >= len(all_frames)
                                or not np.array_equal(all_frames[pos], frames)):
                raise StoreError(f"{path}: frames requested that the manifest lacks")
            table = table.take(pos)
        self.manifest = table
        self.frames = table.column("frame").to_numpy().astype(np.int64)
        self.frames.setflags(write=False)
        self._sorted = bool(np.all(np.diff(self.frames) >= 0))
        self._root: Any = None
        self._reader: ShardReader | None = None
        self._columns: ManifestColumns | None = None
        # ds[i]'s read-ahead: (shard, frame -> decoded arrays not returned yet, frames
        # returned or decoded since the shard was entered)
        self._ahead: tuple[int, dict[int, dict[str, np.ndarray]], set[int]] | None = None

    @property
    def label_names(self) -> list[str]:
        """K part names: label k is ``label_names[k - 1]`` (0 is background)."""
        return list(self.attrs.get("label_names", []))

    def __len__(self) -> int:
        return len(self.frames)

    def __repr__(self) -> str:
        return (f"FrameDataset({self.store!r}, {len(self)} of {self.num_frames} frames, "
                f"arrays={list(self.arrays)})")

    # pickling: a few numbers and the store path; the manifest view is rebuilt from the
    # store, and the reader (threads, caches) is per process
    def __getstate__(self) -> dict[str, Any]:
        return {"store": self.store, "arrays": self.arrays, "columns": self.columns,
                "cache": self.cache, "frames": np.array(self.frames), "threads": self.threads,
                "partial": self.partial}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["store"], arrays=state["arrays"],  # type: ignore[misc]
                      columns=state["columns"], cache=state["cache"], frames=state["frames"],
                      threads=state.get("threads"), partial=state.get("partial", False))

    def _group(self) -> Any:
        if self._root is None:
            self._root = open_store(self.store)
        return self._root

    def reader(self) -> ShardReader:
        """This process's :class:`~vhgen.store.shards.ShardReader` of the selected arrays."""
        if self._reader is None:
            self._reader = ShardReader(self.store, self.arrays, threads=self.threads)
        return self._reader

    def _manifest_columns(self) -> ManifestColumns:
        if self._columns is None:
            self._columns = ManifestColumns(self.manifest)
        return self._columns

    def shard_of(self) -> np.ndarray:
        """(len(self),) int64: the shard holding each position's frame."""
        return self.frames // self.frames_per_shard

    def _positions(self, indices: Sequence[int] | np.ndarray) -> np.ndarray:
        idx = np.asarray(indices)
        if idx.dtype.kind not in "iu" and idx.size:
            raise TypeError(f"indices must be integers, got {idx.dtype}")
        idx = idx.astype(np.int64).reshape(-1)
        n = len(self.frames)
        bad = (idx < -n) | (idx >= n)
        if bad.any():
            raise IndexError(f"index {int(idx[bad][0])} out of range for {n} frames")
        return idx % n if n else idx

    def _decode(self, frames: Sequence[int]) -> list[dict[str, np.ndarray]]:
        """Each frame's arrays, freshly decoded (one request per frame and array)."""
        reader = self.reader()
        outs = [{n: reader.empty(n) for n in self.arrays} for _ in frames]
        reader.read_into([(n, f, o[n]) for f, o in zip(frames, outs, strict=True)
                          for n in self.arrays])
        return outs

    def _read(self, frame: int) -> dict[str, np.ndarray]:
        if self.cache == "frame":
            return self._decode([frame])[0]
        shard = frame // self.frames_per_shard
        if self._ahead is None or self._ahead[0] != shard:
            self._ahead = None  # drop the old shard's frames before decoding new ones
            self._ahead = (shard, {}, {frame})
            return self._decode([frame])[0]
        _, ready, seen = self._ahead
        got = ready.pop(frame, None)
        if got is not None:
            return got
        # a second frame of this shard in a row: a shard-by-shard walk; decode the rest of
        # the shard's frames (of this view) at once
        bounds = [shard * self.frames_per_shard, (shard + 1) * self.frames_per_shard]
        if self._sorted:
            lo, hi = np.searchsorted(self.frames, bounds)
            here = self.frames[lo:hi]
        else:  # a view made with frames in another order
            here = self.frames[(self.frames >= bounds[0]) & (self.frames < bounds[1])]
        rest = [int(f) for f in np.unique(here) if f != frame and f not in seen]
        decoded = self._decode([frame, *rest])
        ready.update(zip(rest, decoded[1:], strict=True))
        seen.update(rest)
        seen.add(frame)
        return decoded[0]

    def __getitem__(self, i: int) -> dict[str, Any]:
        n = len(self.frames)
        i = int(i)
        if not -n <= i < n:
            raise IndexError(f"index {i} out of range for {n} frames")
        i %= n
        frame = int(self.frames[i])
        return {"frame": frame, **self._read(frame),
                "manifest": self._manifest_columns().row(i)}

    def get_batch(self, indices: Sequence[int] | np.ndarray) -> dict[str, Any]:
        """Positions ``indices`` (any order, repeats allowed) read at once: ``frame`` (B,)
        int64, one (B, H, W) array per selected array, ``manifest`` column by column
        (:meth:`~vhgen.store.manifest.ManifestColumns.take`: numbers (B,) in the column's
        dtype, ``world_to_camera`` (B, 4, 4), ``joints_cam`` (B, J, 3), others lists).
        Frame ``k`` of the batch equals ``ds[indices[k]]``; each frame's chunks are
        decoded once, grouped by shard, in threads."""
        batch, _ = self._read_batch(self._positions(indices))
        return batch

    def _read_batch(self, pos: np.ndarray, skip: bool = False,
                    reported: set[tuple[str, int]] | None = None
                    ) -> tuple[dict[str, Any], np.ndarray]:
        """The batch of positions ``pos`` and the positions it holds (all of them, or with
        ``skip`` those whose frames decoded; a damaged shard is logged once per
        ``reported`` set)."""
        reader = self.reader()
        frames = self.frames[pos]
        uniq, inverse = np.unique(frames, return_inverse=True)
        direct = len(uniq) == len(frames)
        target = frames if direct else uniq
        arrays = {n: reader.empty(n, len(target)) for n in self.arrays}
        errors: list[ShardError] | None = [] if skip else None
        reader.read_into([(n, int(f), arrays[n][k]) for n in self.arrays
                          for k, f in enumerate(target)], errors)
        if not direct:
            arrays = {n: a[inverse] for n, a in arrays.items()}
        if errors:
            bad = np.zeros(len(frames), bool)
            for e in errors:
                if reported is None or (e.array, e.shard) not in reported:
                    log.warning("skipped: %s", e)
                    if reported is not None:
                        reported.add((e.array, e.shard))
                bad |= (frames >= e.frames[0]) & (frames <= e.frames[1])
            pos, frames = pos[~bad], frames[~bad]
            arrays = {n: a[~bad] for n, a in arrays.items()}
        return ({"frame": np.array(frames, np.int64), **arrays,
                 "manifest": self._manifest_columns().take(pos)}, pos)

    def __getitems__(self, indices: Sequence[int]) -> list[dict[str, Any]]:
        """``[ds[i] for i in indices]``, read as one :meth:`get_batch` (PyTorch's
        ``DataLoader`` calls this with each batch of its sampler's indices)."""
        pos = self._positions(indices)
        batch, _ = self._read_batch(pos)
        cols = self._manifest_columns()
        return [{"frame": int(batch["frame"][k]), **{n: batch[n][k] for n in self.arrays},
                 "manifest": cols.row(int(p))} for k, p in enumerate(pos)]

    def __iter__(self) -> Iterator[dict[str, Any]]:
        for i in range(len(self)):
            yield self[i]

    def close(self) -> None:
        """Stop the decode threads and drop the read-ahead (reading again restarts them)."""
        self._ahead = None
        if self._reader is not None:
            self._reader.close()

    def filter(self, predicate: Callable[[Any], Any] | None = None,
               **where: Any) -> FrameDataset:
        """A view on the frames whose manifest rows match.

        predicate : called with the view's manifest (a ``pyarrow.Table``), returns a boolean
            mask (pyarrow or NumPy) with one entry per row.
        where : ``column=value`` keeps rows equal to value; ``column=[v1, v2]`` keeps rows
            equal to any of them (e.g. ``motion_file=path``, ``avatar_id=[0, 3]``).
        """
        import pyarrow as pa
        import pyarrow.compute as pc

        table = self.manifest
        mask = np.ones(table.num_rows, bool)
        for col, want in where.items():
            if col not in table.column_names:
                raise StoreError(f"filter: no manifest column {col!r} (columns: "
                                 f"{', '.join(table.column_names)})")
            values = want if isinstance(want, list | tuple | set | frozenset) else [want]
            hit = pc.is_in(table.column(col), value_set=pa.array(list(values)))
            mask &= np.asarray(hit.to_numpy(zero_copy_only=False), bool)
        if predicate is not None:
            m = predicate(table)
            if hasattr(m, "to_numpy"):
                m = m.to_numpy(zero_copy_only=False)
            m = np.asarray(m, bool)
            if m.shape != (table.num_rows,):
                raise ValueError(f"filter predicate returned shape {m.shape}, expected "
                                 f"({table.num_rows},)")
            mask &= m
        return FrameDataset(self.store, arrays=self.arrays, columns=self.columns,
                            cache=self.cache, frames=self.frames[mask], threads=self.threads,
                            partial=self.partial)

    def sampler(self, seed: int = 0, *, shuffle: bool = True, epoch: int = 0,
                num_replicas: int = 1, rank: int = 0) -> ShardSampler:
        """A :class:`ShardSampler` over this dataset's positions (for ``DataLoader(sampler=)``)."""
        return ShardSampler(self.shard_of(), seed=seed, shuffle=shuffle, epoch=epoch,
                            num_replicas=num_replicas, rank=rank)

    def stream(self, seed: int = 0, *, epoch: int = 0, shuffle: bool = True,
               buffer_size: int = 1024, batch_size: int | None = None,
               drop_last: bool = False, rank: int = 0, world_size: int = 1,
               worker: int | None = None, num_workers: int | None = None,
               skip_damaged: bool = False) -> FrameStream:
        """A :class:`FrameStream` of this dataset: the iterable form for large jobs.

        With torch already imported the stream is a ``torch.utils.data.IterableDataset``
        (``DataLoader(ds.stream(...), batch_size=None, num_workers=4)``)."""
        cls = _torch_stream_class() if "torch" in sys.modules else FrameStream
        return cls(self, seed=seed, epoch=epoch, shuffle=shuffle, buffer_size=buffer_size,
                   batch_size=batch_size, drop_last=drop_last, rank=rank,
                   world_size=world_size, worker=worker, num_workers=num_workers,
                   skip_damaged=skip_damaged)


def _buffer_shuffle(seq: np.ndarray, size: int, rng: np.random.Generator) -> np.ndarray:
    """``seq`` passed through a shuffle buffer of ``size``: each step emits a random
    element of the buffer and puts the next element of ``seq`` in its place."""
    n = len(seq)
    if n <= size:
        return rng.permutation(seq)
    out = np.empty_like(seq)
    buf = seq[:size].copy()
    picks = rng.integers(0, size, n - size)
    for t in range(n - size):
        j = picks[t]
        out[t] = buf[j]
        buf[j] = seq[size + t]
    out[n - size:] = rng.permutation(buf)
    return out


def _torch_worker() -> tuple[int, int]:
    """(worker id, workers) of the PyTorch DataLoader worker this runs in, else (0, 1).
    A DataLoader worker has imported torch, so torch is never imported here."""
    if "torch" not in sys.modules:
        return 0, 1
    info = importlib.import_module("torch.utils.data").get_worker_info()
    return (0, 1) if info is None else (int(info.id), int(info.num_workers))


class FrameStream:
    """The frames of a dataset streamed shard by shard, every frame once per epoch.

    Each epoch the shard order is shuffled with ``(seed, epoch)``; the shards are dealt
    round-robin to the consumers (``world_size`` distributed ranks times ``num_workers``
    DataLoader workers each; a consumer takes shards ``c, c + C, ...`` of that order, so
    no two overlap and consumers differ by at most one shard), and each consumer passes
    its frames, shard after shard, through a shuffle buffer of ``buffer_size`` positions
    (seeded with ``(seed, epoch, consumer)``). The buffer holds positions, not frames:
    frames are decoded when emitted, ``batch_size`` at a time (or a shard's worth when
    yielding single frames), the next batch read ahead in a thread.

    Items are ``ds[i]``'s dicts, or with ``batch_size`` :meth:`FrameDataset.get_batch`'s
    batches (``drop_last`` drops a short last one). ``worker``/``num_workers`` default to
    PyTorch's ``get_worker_info()`` when torch is imported, else one worker.
    ``skip_damaged`` logs a frame whose shard cannot be read (one line naming the store
    and the shard) and goes on, instead of raising :class:`~vhgen.errors.ShardError`.
    Memory: two batches (or two shards' worth of frames) decoded at a time.
    """

    def __init__(self, dataset: FrameDataset, *, seed: int = 0, epoch: int = 0,
                 shuffle: bool = True, buffer_size: int = 1024, batch_size: int | None = None,
                 drop_last: bool = False, rank: int = 0, world_size: int = 1,
                 worker: int | None = None, num_workers: int | None = None,
                 skip_damaged: bool = False):
        if world_size < 1 or not 0 <= rank < world_size:
            raise ValueError(f"rank {rank} is outside [0, world_size={world_size})")
        if (worker is None) != (num_workers is None):
            raise ValueError("give worker and num_workers together (or neither)")
        if worker is not None and num_workers is not None and not 0 <= worker < num_workers:
            raise ValueError(f"worker {worker} is outside [0, num_workers={num_workers})")
        if batch_size is not None and batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.dataset = dataset
        self.seed, self.epoch, self.shuffle = int(seed), int(epoch), bool(shuffle)
        self.buffer_size = max(1, int(buffer_size))
        self.batch_size, self.drop_last = batch_size, bool(drop_last)
        self.rank, self.world_size = int(rank), int(world_size)
        self.worker, self.num_workers = worker, num_workers
        self.skip_damaged = bool(skip_damaged)

    def set_epoch(self, epoch: int) -> None:
        """Use ``epoch``'s order from the next iteration on."""
        self.epoch = int(epoch)

    def consumer(self) -> tuple[int, int]:
        """(this consumer's number, consumers): rank-major over the workers of each rank."""
        if self.worker is not None and self.num_workers is not None:
            worker, workers = self.worker, self.num_workers
        else:
            worker, workers = _torch_worker()
        return self.rank * workers + worker, self.world_size * workers

    def positions(self) -> np.ndarray:
        """The dataset positions this consumer yields this epoch, in order (no reading)."""
        consumer, consumers = self.consumer()
        groups = _shard_groups(self.dataset.shard_of())
        if self.shuffle:
            rng = np.random.default_rng([self.seed, self.epoch])
            groups = [groups[j] for j in rng.permutation(len(groups))]
        mine = groups[consumer::consumers]
        seq = np.concatenate(mine) if mine else np.empty(0, np.int64)
        if not self.shuffle:
            return seq
        return _buffer_shuffle(seq, self.buffer_size,
                               np.random.default_rng([self.seed, self.epoch, consumer]))

    def __len__(self) -> int:
        n = len(self.positions())
        if self.batch_size is None:
            return n
        return n // self.batch_size if self.drop_last else -(-n // self.batch_size)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        ds = self.dataset
        pos = self.positions()
        step = self.batch_size or ds.frames_per_shard
        chunks = [pos[a:a + step] for a in range(0, len(pos), step)]
        if self.batch_size is not None and self.drop_last and chunks and len(chunks[-1]) < step:
            chunks.pop()
        if not chunks:
            return
        ahead = ThreadPoolExecutor(1, thread_name_prefix="vhgen-stream")
        reported: set[tuple[str, int]] = set()
        try:
            nxt: Future = ahead.submit(ds._read_batch, chunks[0], self.skip_damaged, reported)
            for j in range(len(chunks)):
                batch, held = nxt.result()
                if j + 1 < len(chunks):
                    nxt = ahead.submit(ds._read_batch, chunks[j + 1], self.skip_damaged,
                                       reported)
                if self.batch_size is not None:
                    if len(held):
                        yield batch
                    continue
                cols = ds._manifest_columns()
                for k, p in enumerate(held):
                    yield {"frame": int(batch["frame"][k]),
                           **{n: batch[n][k] for n in ds.arrays},
                           "manifest": cols.row(int(p))}
                del batch
        finally:
            ahead.shutdown(wait=True, cancel_futures=True)


_TORCH_STREAM: list[type] = []


def _torch_stream_class() -> type:
    """FrameStream as a ``torch.utils.data.IterableDataset`` (made on first use, so that
    torch is never imported by vhgen; pickles as ``vhgen.dataset.TorchFrameStream``)."""
    if not _TORCH_STREAM:
        base = importlib.import_module("torch.utils.data").IterableDataset
        _TORCH_STREAM.append(type("TorchFrameStream", (FrameStream, base),
                                  {"__module__": __name__, "__doc__": FrameStream.__doc__}))
    return _TORCH_STREAM[0]


def __getattr__(name: str) -> Any:
    # PEP 562: a spawned DataLoader worker unpickling a TorchFrameStream finds it here
    if name == "TorchFrameStream":
        return _torch_stream_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def open(store: str | Path, *, arrays: Sequence[str] | None = None,  # noqa: A001
         columns: Sequence[str] | None = None, cache: str = "shard",
         threads: int | None = None, partial: bool = False) -> FrameDataset:
    """Open a store for reading; see :class:`FrameDataset`.

    arrays : which arrays to read (default: all, e.g. depth, labels, raw); the others are
        never touched.
    columns : which manifest columns to return (default: all; ``frame`` always).
    threads : decode threads of this process. partial : read a store still being written.
    """
    return FrameDataset(store, arrays=arrays, columns=columns, cache=cache, threads=threads,
                        partial=partial)


class _ShardArrays:
    """Ray Data map_batches callable: add the store's arrays to a batch of manifest rows."""

    def __init__(self, store: str, arrays: Sequence[str], frames_per_shard: int):
        self.store, self.arrays, self.fps = store, tuple(arrays), frames_per_shard
        self._reader: ShardReader | None = None

    def __call__(self, batch: Any) -> dict[str, np.ndarray]:
        if self._reader is None:
            self._reader = ShardReader(self.store, self.arrays)
        frames = batch.column("frame").to_numpy().astype(np.int64)
        out: dict[str, np.ndarray] = {"frame": frames}
        arrays = {n: self._reader.empty(n, len(frames)) for n in self.arrays}
        self._reader.read_into([(n, int(f), arrays[n][k]) for n in self.arrays
                                for k, f in enumerate(frames)])
        out.update(arrays)
        for name in batch.column_names:
            if name == "frame":
                continue
            col = batch.column(name)
            if name in ARRAY_COLUMNS:
                flat: np.ndarray = np.asarray(
                    col.combine_chunks().flatten().to_numpy(zero_copy_only=False),
                    array_dtype(name))
                out[name] = flat.reshape(len(frames), *ARRAY_COLUMNS[name])
            else:
                out[name] = np.asarray(col.to_numpy(zero_copy_only=False))
        return out


def to_ray(store: str | Path, *, arrays: Sequence[str] | None = None,
           columns: Sequence[str] | None = None,
           predicate: Callable[[Any], Any] | None = None, seed: int | None = None,
           **where: Any) -> Any:
    """The store's frames as a ``ray.data.Dataset`` (one row per frame).

    Columns: ``frame``, one (H, W) tensor column per array, and the manifest columns
    (``world_to_camera`` (4, 4), ``joints_cam`` (J, 3), others as scalars/strings).
    ``predicate`` and ``where`` filter as :meth:`FrameDataset.filter`. Each read task
    decodes one shard's frames (a block is one shard), in store order, or with ``seed`` in
    a shard order shuffled with it (pass ``seed + epoch`` for a new order each epoch).
    Shuffle frames with a local buffer (``iter_batches(local_shuffle_buffer_size=...,
    local_shuffle_seed=...)``) and split between workers with ``streaming_split``. Needs
    ``ray[data]`` (pandas); Ray is imported here only.
    """
    import ray.data

    ds = open(store, arrays=arrays, columns=columns)
    if predicate is not None or where:
        ds = ds.filter(predicate, **where)
    fps = ds.frames_per_shard
    table = ds.manifest
    # one block per shard keeps reads shard-local and spreads them over the cluster
    groups = _shard_groups(ds.shard_of())
    blocks = [table.take(g) for g in groups] or [table]
    rd: Any = ray.data.from_arrow(blocks)
    if seed is not None:
        rd = rd.randomize_block_order(seed=int(seed))
    return rd.map_batches(_ShardArrays(ds.store, ds.arrays, fps), batch_size=None,
                          batch_format="pyarrow")


__all__ = ["FrameDataset", "FrameStream", "ShardSampler", "open", "read_frames", "to_ray"]
