"""The frame worker: one GL context per process, one shard per call.

The same class runs in a Ray actor (``vhgen.pipeline.driver``) and in a process of the
local pool (``vhgen.pipeline.local``); it imports neither.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.config import JobConfig
from vhgen.errors import RenderError, VhgenError


class FrameWorker:
    """``__init__`` does the set-up that needs only the config (GL context, compiled sensor
    kernels), so it runs while the driver is still planning; :meth:`load` then receives
    the poses and the plan; :meth:`run` renders and writes one shard.

    ``faults`` (tests only): ``{"die_once": (marker folder, shards)}`` kills the process the
    first time one of those shards is attempted; ``{"write_error": (errno, shards)}`` makes
    writing those shards fail with that OSError; ``{"setup_error": message}`` makes the
    set-up fail with a RenderError; ``{"crash": shards}`` raises a plain bug (RuntimeError)
    on those shards. With ``die_once``, faults of a replacement worker (one loading after
    a ``die_once`` death): ``{"die_in_setup": n}`` kills the process in :meth:`load`, the
    first ``n`` times; ``{"replacement_setup_error": message}`` makes its load fail with a
    RenderError; ``{"replacement_waits_for": paths}`` holds its load until these files
    exist (a RenderError after 30 s).
    """

    def __init__(self, cfg: JobConfig, asset_dir: str, faults: dict | None = None):
        from vhgen.pipeline.resources import worker_context
        from vhgen.render.context import create_context
        from vhgen.sensor.model import SensorModel

        self.cfg = cfg
        self.asset_dir = asset_dir
        self.faults = faults or {}
        self.gen: Any = None
        # a user-facing failure here (no GL backend, ...) is kept and raised by load():
        # a constructor's exception reaches a Ray driver only as a multi-line traceback
        self.setup_error: VhgenError | None = None
        try:
            if "setup_error" in self.faults:
                raise RenderError(self.faults["setup_error"])
            # llvmpipe (Mesa's software GL) would start one thread per core in every
            # worker; the workers are the parallelism. Read when the first context is
            # created, so set here, in the worker's own process
            os.environ.setdefault("LP_NUM_THREADS", "1")
            # a GPU worker opens the EGL device Ray gave it; otherwise the config's backend
            self.ctx = worker_context(cfg, os.environ.get("CUDA_VISIBLE_DEVICES")) \
                or create_context(cfg.backend)
            # load (or compile) the sensor's numba kernels now, not in the first frame:
            # with arrays of the types and layouts the renderer hands over (a kernel is
            # compiled per signature): float32 depth, uint32 packed ids, float32 incidence
            h, w = cfg.sensor.intrinsics.height, cfg.sensor.intrinsics.width
            SensorModel(cfg.sensor).simulate(
                np.full((h, w), 2.0, np.float32), np.random.default_rng(0),
                labels=np.ones((h, w), np.uint32), incidence=np.ones((h, w), np.float32),
                projector_depth=np.full((h, w), 2.0, np.float32))
        except VhgenError as e:
            self.setup_error = e

    def load(self, rotations: np.ndarray, roots: np.ndarray, pose_meta: dict,
             plan_arrays: dict, avatars: list[dict], bodies: dict | None = None,
             base_hip_drop: float | None = None) -> str:
        """Receive the poses and the plan (and the bodies the driver built for the first
        shards); returns the GL renderer string."""
        from vhgen.pipeline.frames import FrameGenerator

        if self.setup_error is not None:
            raise self.setup_error
        try:
            if "die_once" in self.faults:
                _replacement_faults(self.faults)
            self.gen = FrameGenerator(self.cfg, self.asset_dir, rotations, roots, pose_meta,
                                      plan_arrays, avatars, context=self.ctx, bodies=bodies,
                                      base_hip_drop=base_hip_drop)
        except VhgenError as e:
            self.setup_error = e  # raised again by run(): a task after a failed load
            raise
        return str(self.gen.renderer_info)

    def run(self, store: str, shard: int, start: int, stop: int) -> dict:
        """Render and write frames ``start:stop`` as shard ``shard`` of ``store``; returns
        the shard's metadata and its ``seconds``. A worker whose set-up or load failed
        raises that error again (a Ray actor runs a task queued after its load even
        when the load raised)."""
        if self.gen is None:
            raise self.setup_error or RuntimeError("FrameWorker.run before load")
        die = self.faults.get("die_once")
        if die is not None and shard in die[1]:
            # die as a killed process would, the first time this shard is attempted
            marker = Path(die[0]) / f"failed-{shard}"
            if not marker.exists():
                marker.touch()
                os._exit(1)
        if shard in self.faults.get("crash", ()):
            raise RuntimeError(f"injected bug on shard {shard}")
        bad = self.faults.get("write_error")
        if bad is not None and shard in bad[1]:
            import vhgen.pipeline.frames as frames

            real = frames.write_shard

            def failing(path: str | Path, *args: Any, **kw: Any) -> None:
                raise OSError(bad[0], os.strerror(bad[0]), str(Path(path) / "depth"))

            frames.write_shard = failing
            try:
                return self.gen.run_task(store, shard, start, stop)
            finally:
                frames.write_shard = real
        t = time.perf_counter()
        result = self.gen.run_task(store, shard, start, stop)
        return {**result, "seconds": time.perf_counter() - t}


def _replacement_faults(faults: dict) -> None:
    """``die_in_setup``, ``replacement_setup_error`` and ``replacement_waits_for``, in a
    worker loading after a worker died on a shard (its replacement): the job's first
    workers set up unharmed."""
    folder = Path(faults["die_once"][0])
    if not any(folder.glob("failed-*")):
        return
    if "replacement_setup_error" in faults:
        raise RenderError(faults["replacement_setup_error"])
    waits = [Path(p) for p in faults.get("replacement_waits_for", ())]
    deadline = time.monotonic() + 30.0
    while not all(p.exists() for p in waits):
        if time.monotonic() > deadline:
            raise RenderError(f"waited 30 s in set-up for {[str(p) for p in waits]}")
        time.sleep(0.05)
    for k in range(faults.get("die_in_setup", 0)):
        try:  # O_EXCL: two replacements loading at once never both take the same turn
            (folder / f"setup-died-{k}").open("x").close()
        except FileExistsError:
            continue
        os._exit(1)  # as a GL driver crash or an OOM kill in the set-up would
