"""Train a forest from stores: in process (default) or on Ray actors (the only Ray user
in vhgen.forest; Ray is imported inside :func:`train_forest` when asked for).

Ray workers each read a disjoint round-robin share of the frames from the stores
themselves (no image passes through the driver), draw their samples and return per-level
integer histograms; the driver sums them and picks the splits (vhgen.forest.train). The
sums are exact, so the same seed gives the same forest for any number of workers.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.errors import ForestError
from vhgen.forest.data import check_compatible, read_frames, select_frames, store_info
from vhgen.forest.model import Forest
from vhgen.forest.train import ImageShard, LocalPool, TrainParams, grow_forest

log = logging.getLogger(__name__)


class FrameShard(ImageShard):
    """An ImageShard that reads its own frames (store path, frame, global id)."""

    def __init__(self, frames: list[tuple[str, int, int]], params: TrainParams,
                 threads: int | None = None):
        if threads is not None:
            import numba

            # one Ray CPU per actor: do not let numba spread over every core of the node
            numba.set_num_threads(max(1, min(threads, numba.get_num_threads())))
        depth, labels = read_frames(frames)
        super().__init__(depth, labels, [g for _, _, g in frames], params)


class RayPool:
    """ShardPool over Ray actors; large arrays are put in the object store once per call."""

    def __init__(self, ray: Any, actors: list[Any]):
        self.ray = ray
        self.actors = actors

    def map(self, method: str, *args: Any) -> list[Any]:
        refs = [self.ray.put(a) if isinstance(a, np.ndarray) and a.nbytes > 4096 else a
                for a in args]
        return self.ray.get([getattr(a, method).remote(*refs) for a in self.actors])


def training_meta(stores: list[str], frames: list[tuple[str, int, int]]) -> dict:
    """What a forest records about its data: scheme, names, colours, focal length, stores."""
    import zarr

    infos = [store_info(s) for s in stores]
    ref = check_compatible(infos)
    attrs = json.loads(json.dumps(dict(zarr.open_group(ref.path, mode="r").attrs)))
    return {"label_scheme": ref.label_scheme, "label_names": list(ref.label_names),
            "label_colors": attrs.get("label_colors"), "fx": ref.fx, "fy": ref.fy,
            "sensors": sorted({i.sensor for i in infos}),
            "stores": [str(Path(s).resolve()) for s in stores], "frames": len(frames)}


def train_forest(stores: list[str], params: TrainParams, *, max_frames: int | None = None,
                 workers: int | None = None, address: str | None = None,
                 progress: Callable[[str], None] | None = None) -> Forest:
    """Train on the frames of ``stores`` (all, or a seeded subset of ``max_frames``).

    ``workers``/``address`` unset: one in-process shard (numba threads use the cores).
    Otherwise ``workers`` Ray actors (default: one per CPU of the cluster) on the cluster at
    ``address`` (default: a local Ray).
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
    if workers is None and address is None:
        pool: Any = LocalPool([FrameShard(frames, params)])
        forest = grow_forest(pool, num_classes, params, meta, progress)
    else:
        import ray

        ray.init(address=address, ignore_reinit_error=True, log_to_driver=False,
                 logging_level=logging.WARNING)
        try:
            n = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
            n = max(1, min(n, len(frames)))
            actor_cls = ray.remote(num_cpus=1)(FrameShard)
            actors = [actor_cls.remote(frames[w::n], params, 1) for w in range(n)]
            if progress is not None:
                progress(f"{n} Ray workers, {len(frames)} frames")
            forest = grow_forest(RayPool(ray, actors), num_classes, params, meta, progress)
        finally:
            if address is None:
                ray.shutdown()
    forest.meta["train_seconds"] = round(time.perf_counter() - t0, 2)
    forest.meta["workers"] = workers if workers is not None or address is not None else 0
    return forest
