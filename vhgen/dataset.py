"""Reading a store for training: a map-style dataset, a shard-local sampler, Ray Data.

    import vhgen.dataset
    ds = vhgen.dataset.open("out/default.zarr")          # len(ds) frames
    item = ds[0]    # {"frame", "depth" (H, W) uint16, "labels" (H, W) uint8, "raw"?, "manifest"}
    walk = ds.filter(avatar_id=[0, 1]).filter(lambda t: pc.greater(t["body_pixels"], 5000))
    for i in walk.sampler(seed=0, epoch=3): walk[i]      # shard by shard, shuffled

:class:`FrameDataset` has ``__len__`` and ``__getitem__`` and pickles to a few numbers, so
PyTorch's ``DataLoader`` uses it as is (``DataLoader(ds, sampler=ds.sampler(seed),
batch_size=...)``), in worker processes too; vhgen never imports torch. Frames are read a
shard at a time: each process keeps the last decoded shard (one array slice of
``frames_per_shard`` frames per array), so a sampler that walks shard by shard decodes
every shard once per epoch. :func:`to_ray` gives the same frames as a Ray Data dataset.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.errors import StoreError
from vhgen.store.manifest import read_manifest_table
from vhgen.store.zarr_store import MANIFEST_FILE, open_store, read_frames

# contract arrays first, in this order; other (N, ...) arrays of the group follow by name
CONTRACT_ORDER = ("depth", "labels", "raw")
# fixed-size list columns returned as arrays of this shape (-1: as many rows as needed)
ARRAY_COLUMNS = {"world_to_camera": (4, 4), "joints_cam": (-1, 3), "body_offset": (3,)}


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


def _row_dict(table, i: int) -> dict[str, Any]:
    """Row ``i`` of a manifest table as a dict; list columns become NumPy arrays."""
    row = table.slice(i, 1).to_pylist()[0]
    for name, shape in ARRAY_COLUMNS.items():
        if name in row and row[name] is not None:
            dtype = np.float32 if name == "joints_cam" else np.float64
            row[name] = np.asarray(row[name], dtype).reshape(shape)
    return row


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
        self.epoch = int(epoch)

    def _groups(self) -> list[np.ndarray]:
        shards, first = np.unique(self.shard_of, return_index=True)
        order = np.argsort(self.shard_of, kind="stable")
        groups = np.split(order, np.searchsorted(self.shard_of[order], shards)[1:])
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
    """Random access to the frames of a store (map-style: ``len``, ``[i]``).

    ``ds[i]`` is a dict: ``frame`` (int, the frame index in the store), one (H, W) array per
    array of the store (``depth`` uint16 mm, ``labels`` uint8, ``raw`` uint16 if present,
    any later array likewise) and ``manifest``, the frame's manifest row as a dict
    (``world_to_camera`` as a (4, 4) float64 array, ``joints_cam`` as (J, 3) float32 metres
    in the camera frame, ``body_offset`` (3,) float64, JSON columns as strings).
    Returned arrays are copies: changing them does not change the cache.

    cache : ``"shard"`` keeps the last decoded shard per process (best with
        :meth:`sampler`), ``"frame"`` reads one frame per access (best for scattered access).
    """

    def __init__(self, store: str | Path, *, arrays: Sequence[str] | None = None,
                 columns: Sequence[str] | None = None, cache: str = "shard",
                 frames: np.ndarray | None = None):
        if cache not in ("shard", "frame"):
            raise ValueError(f"cache must be 'shard' or 'frame', got {cache!r}")
        self.store = str(Path(store).expanduser())
        path = Path(self.store)
        root = open_store(path)
        self.attrs: dict[str, Any] = json.loads(json.dumps(dict(root.attrs)))
        man_path = path / MANIFEST_FILE
        if not man_path.is_file():
            raise StoreError(f"{path}: no {MANIFEST_FILE} (job not finished? run "
                             "'vhgen generate ... --resume')")
        cols = None if columns is None else list(dict.fromkeys(["frame", *columns]))
        try:
            table = read_manifest_table(man_path, cols).sort_by("frame")
        except (KeyError, ValueError) as e:
            raise StoreError(f"{man_path}: {e}") from None
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
        all_frames = table.column("frame").to_numpy()
        if frames is not None:
            pos = np.searchsorted(all_frames, frames)
            if len(frames) and (pos.max() >= len(all_frames)
                                or not np.array_equal(all_frames[pos], frames)):
                raise StoreError(f"{path}: frames requested that the manifest lacks")
            table = table.take(pos)
        self.manifest = table
        self.frames = table.column("frame").to_numpy().astype(np.int64)
        self._root: Any = None
        self._shard: tuple[int, dict[str, np.ndarray]] | None = None

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
    # store and the zarr handle and shard cache are per process
    def __getstate__(self) -> dict[str, Any]:
        return {"store": self.store, "arrays": self.arrays, "columns": self.columns,
                "cache": self.cache, "frames": self.frames}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["store"], arrays=state["arrays"],  # type: ignore[misc]
                      columns=state["columns"], cache=state["cache"], frames=state["frames"])

    def _group(self) -> Any:
        if self._root is None:
            self._root = open_store(self.store)
        return self._root

    def shard_of(self) -> np.ndarray:
        """(len(self),) int64: the shard holding each position's frame."""
        return self.frames // self.frames_per_shard

    def _read(self, frame: int) -> dict[str, np.ndarray]:
        if self.cache == "frame":
            root = self._group()
            return {n: np.asarray(root[n][frame]) for n in self.arrays}
        shard = frame // self.frames_per_shard
        if self._shard is None or self._shard[0] != shard:
            start = shard * self.frames_per_shard
            stop = min(self.num_frames, start + self.frames_per_shard)
            root = self._group()
            self._shard = None  # free the old shard before decoding the next one
            self._shard = (shard, {n: np.asarray(root[n][start:stop]) for n in self.arrays})
        k = frame - shard * self.frames_per_shard
        return {n: a[k].copy() for n, a in self._shard[1].items()}

    def __getitem__(self, i: int) -> dict[str, Any]:
        n = len(self.frames)
        i = int(i)
        if not -n <= i < n:
            raise IndexError(f"index {i} out of range for {n} frames")
        i %= n
        frame = int(self.frames[i])
        return {"frame": frame, **self._read(frame), "manifest": _row_dict(self.manifest, i)}

    def __iter__(self) -> Iterator[dict[str, Any]]:
        for i in range(len(self)):
            yield self[i]

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
                            cache=self.cache, frames=self.frames[mask])

    def sampler(self, seed: int = 0, *, shuffle: bool = True, epoch: int = 0,
                num_replicas: int = 1, rank: int = 0) -> ShardSampler:
        """A :class:`ShardSampler` over this dataset's positions (for ``DataLoader(sampler=)``)."""
        return ShardSampler(self.shard_of(), seed=seed, shuffle=shuffle, epoch=epoch,
                            num_replicas=num_replicas, rank=rank)


def open(store: str | Path, *, arrays: Sequence[str] | None = None,  # noqa: A001
         columns: Sequence[str] | None = None, cache: str = "shard") -> FrameDataset:
    """Open a finished store for reading; see :class:`FrameDataset`.

    arrays : which arrays to read (default: all, e.g. depth, labels, raw).
    columns : which manifest columns to return (default: all; ``frame`` always).
    """
    return FrameDataset(store, arrays=arrays, columns=columns, cache=cache)


class _ShardArrays:
    """Ray Data map_batches callable: add the store's arrays to a batch of manifest rows."""

    def __init__(self, store: str, arrays: Sequence[str], frames_per_shard: int):
        self.store, self.arrays, self.fps = store, tuple(arrays), frames_per_shard
        self._root: Any = None

    def __call__(self, batch: Any) -> dict[str, np.ndarray]:
        if self._root is None:
            self._root = open_store(self.store)
        frames = batch.column("frame").to_numpy()
        out: dict[str, np.ndarray] = {"frame": frames.astype(np.int64)}
        out.update(read_frames(self._root, self.arrays, frames, self.fps))
        for name in batch.column_names:
            if name == "frame":
                continue
            col = batch.column(name)
            if name in ARRAY_COLUMNS:
                dtype = np.float32 if name == "joints_cam" else np.float64
                flat = np.asarray(col.combine_chunks().flatten().to_numpy(zero_copy_only=False),
                                  dtype)
                out[name] = flat.reshape(len(frames), *ARRAY_COLUMNS[name])
            else:
                out[name] = np.asarray(col.to_numpy(zero_copy_only=False))
        return out


def to_ray(store: str | Path, *, arrays: Sequence[str] | None = None,
           columns: Sequence[str] | None = None,
           predicate: Callable[[Any], Any] | None = None, **where: Any) -> Any:
    """The store's frames as a ``ray.data.Dataset`` (one row per frame, store order).

    Columns: ``frame``, one (H, W) tensor column per array, and the manifest columns
    (``world_to_camera`` (4, 4), ``joints_cam`` (J, 3), others as scalars/strings).
    ``predicate`` and ``where`` filter as :meth:`FrameDataset.filter`. Each read task
    decodes whole shards (a batch is one shard's frames), so iterate with
    ``iter_batches``/``iter_torch_batches`` and shuffle with Ray's
    ``randomize_block_order`` or a local shuffle buffer. Needs ``ray[data]`` (pandas);
    Ray is imported here only.
    """
    import ray.data

    ds = open(store, arrays=arrays, columns=columns)
    if predicate is not None or where:
        ds = ds.filter(predicate, **where)
    fps = ds.frames_per_shard
    table = ds.manifest
    # one block per shard's worth of rows keeps reads shard-local and spreads them over
    # the cluster
    blocks = [table.slice(i, fps) for i in range(0, table.num_rows, fps)] or [table]
    return ray.data.from_arrow(blocks).map_batches(
        _ShardArrays(ds.store, ds.arrays, fps), batch_size=None, batch_format="pyarrow")


__all__ = ["FrameDataset", "ShardSampler", "open", "read_frames", "to_ray"]
