"""Train a forest from stores: in this process (default), in worker processes of this
machine, or on Ray actors, through the pools of :mod:`vhgen.executor`.

Each worker (a :class:`FrameShard`) reads a disjoint round-robin share of the frames from
the stores itself (no image passes through the caller), draws its samples and returns
per-level integer histograms; the caller sums them and picks the splits
(:mod:`vhgen.forest.train`). The sums are exact, so the same seed gives the same forest
for any number of workers and any executor.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vhgen.errors import ForestError
from vhgen.executor import InlinePool
from vhgen.executor.choice import choose_executor
from vhgen.forest.data import check_compatible, read_frames, select_frames, store_info
from vhgen.forest.train import ImageShard, TrainParams, grow_forest
from vhgen.forest.trees import Forest

log = logging.getLogger(__name__)


class FrameShard(ImageShard):
    """An ImageShard that reads its own frames (store path, frame, global id)."""

    def __init__(self, frames: list[tuple[str, int, int]], params: TrainParams,
                 threads: int | None = None):
        if threads is not None:
            import numba

            # one CPU per worker: do not let numba spread over every core of the node
            numba.set_num_threads(max(1, min(threads, numba.get_num_threads())))
        depth, labels = read_frames(frames)
        super().__init__(depth, labels, [g for _, _, g in frames], params)


def training_meta(stores: list[str], frames: list[tuple[str, int, int]]) -> dict:
    """What a forest records about its data: scheme, names, colours, focal length, stores."""
    infos = [store_info(s) for s in stores]
    ref = check_compatible(infos)
    return {"label_scheme": ref.label_scheme, "label_names": list(ref.label_names),
            "label_colors": [list(c) for c in ref.label_colors] if ref.label_colors else None,
            "fx": ref.fx, "fy": ref.fy,
            "sensors": sorted({i.sensor for i in infos}),
            "stores": [str(Path(s).resolve()) for s in stores], "frames": len(frames)}


def train_forest(stores: list[str], params: TrainParams, *, max_frames: int | None = None,
                 workers: int | None = None, address: str | None = None,
                 executor: str = "auto",
                 progress: Callable[[str], None] | None = None) -> Forest:
    """Train on the frames of ``stores`` (all, or a seeded subset of ``max_frames``).

    ``workers``/``address`` unset: one shard in this process (numba threads use the
    cores). ``workers``: that many workers holding disjoint frames, as processes of this
    machine (``executor`` ``local``, the default without ``address``) or Ray actors
    (``ray``, the default with ``address``: the cluster there, else a local Ray; default
    one actor per CPU of the cluster).
    """
    params.check()
    if max_frames is not None and max_frames < 1:
        raise ForestError(f"--max-frames {max_frames}: must be >= 1")
    infos = [store_info(s) for s in stores]
    check_compatible(infos)
    frames = select_frames(infos, max_frames, params.seed)
    meta = training_meta(stores, frames)
    num_classes = len(meta["label_names"]) + 1
    t0 = time.perf_counter()
    pool: Any
    if choose_executor(executor, address, error=ForestError) == "ray":
        from vhgen.executor.raypool import RayPool

        pool = RayPool.connect(FrameShard, address=address, local_cpus=workers or 1,
                               options={"num_cpus": 1})
        n = workers or max(1, int(pool.ray.cluster_resources().get("CPU", 1)))
    elif workers is not None:
        from vhgen.executor.local import LocalPool

        pool, n = LocalPool(FrameShard), workers
    else:
        pool, n = InlinePool(FrameShard), 1
    n = max(1, min(n, len(frames)))
    try:
        # an inline shard lets numba use every core; a pool's workers are the parallelism
        threads = None if isinstance(pool, InlinePool) else 1
        pool.start([(frames[w::n], params, threads) for w in range(n)])
        if progress is not None and n > 1:
            progress(f"{n} workers, {len(frames)} frames")
        forest = grow_forest(pool, num_classes, params, meta, progress)
    finally:
        pool.close()
    forest.meta["train_seconds"] = round(time.perf_counter() - t0, 2)
    forest.meta["workers"] = n if workers is not None or address is not None or \
        executor == "ray" else 0
    return forest
