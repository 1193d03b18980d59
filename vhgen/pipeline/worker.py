"""The frame worker: one GL context per process, one shard per call.

The same class runs in a Ray actor and in a process of the local pool (both in
:mod:`vhgen.executor`); it imports neither.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np

from vhgen.body.avatar import Body
from vhgen.errors import VhgenError
from vhgen.job_config import JobConfig
from vhgen.pipeline.frames import FrameGenerator, ShardResult
from vhgen.pipeline.job import Job
from vhgen.store.zarr_store import set_codec_threads


class FrameWorker:
    """``__init__`` does the set-up that needs only the config (GL context, compiled sensor
    kernels), so it runs while the driver is still preparing the job; :meth:`load` then
    receives the :class:`~vhgen.pipeline.job.Job`; :meth:`run` renders and writes one
    shard. A subclass may override any of the three (the tests inject faults that way).
    """

    def __init__(self, cfg: JobConfig):
        from vhgen.pipeline.resources import worker_context
        from vhgen.render.context import create_context
        from vhgen.sensor.simulator import SensorModel

        self.cfg = cfg
        self.gen: Any = None
        # a user-facing failure here (no GL backend, ...) is kept and raised by load():
        # a constructor's exception reaches a Ray driver only as a multi-line traceback
        self.setup_error: VhgenError | None = None
        try:
            # llvmpipe (Mesa's software GL) would start one thread per core in every
            # worker; the workers are the parallelism. Read when the first context is
            # created, so set here, in the worker's own process
            os.environ.setdefault("LP_NUM_THREADS", "1")
            # and zarr's codec threads: this worker's share of the machine's cores
            cores = (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                     else os.cpu_count() or 1)
            set_codec_threads(cores // max(cfg.num_workers, 1))
            # a GPU worker opens the EGL device Ray gave it; otherwise the config's backend
            self.ctx = worker_context(cfg, os.environ.get("CUDA_VISIBLE_DEVICES")) \
                or create_context(cfg.backend)
            # load (or compile) the sensor's numba kernels now, not in the first frame:
            # with arrays of the types and layouts the renderer hands over (a kernel is
            # compiled per signature): float32 depth, uint32 packed ids, float32 incidence
            h, w = cfg.sensor.intrinsics.height, cfg.sensor.intrinsics.width
            if cfg.sensor.backend == "cpu":  # (the GL sensor compiles its passes in load)
                SensorModel(cfg.sensor).simulate(
                    np.full((h, w), 2.0, np.float32), np.random.default_rng(0),
                    labels=np.ones((h, w), np.uint32), incidence=np.ones((h, w), np.float32),
                    projector_depth=np.full((h, w), 2.0, np.float32))
            else:  # the decoding of its batches' frames
                from vhgen.render.frame_words import warm as warm_words
                warm_words()
            # and placement's (people and props kept in view; clutter)
            if not cfg.scene.is_person_only:
                from vhgen.scene.placement_kernels import warm as warm_placement
                warm_placement()
            if cfg.scene.clutter is not None:
                from vhgen.scene.clutter.place_kernels import warm as warm_clutter
                warm_clutter()
        except VhgenError as e:
            self.setup_error = e

    def load(self, job: Job, bodies: dict[int, Body] | None = None) -> str:
        """Receive the job (and the bodies the driver built for the first shards);
        returns the GL renderer string."""
        if self.setup_error is not None:
            raise self.setup_error
        try:
            self.gen = FrameGenerator(job, context=self.ctx, bodies=bodies)
        except VhgenError as e:
            self.setup_error = e  # raised again by run(): a task after a failed load
            raise
        return str(self.gen.renderer_info)

    def run(self, store: str, shard: int, start: int, stop: int) -> ShardResult:
        """Render and write frames ``start:stop`` as shard ``shard`` of ``store``. A
        worker whose set-up or load failed raises that error again (a Ray actor runs a
        task queued after its load even when the load raised)."""
        if self.gen is None:
            raise self.setup_error or RuntimeError("FrameWorker.run before load")
        from vhgen.render.context import GL_LOST_EXIT, gl_failures

        try:
            return self.gen.run_task(store, shard, start, stop)
        except gl_failures() as e:
            # a lost context (a GPU reset, a driver fault, out of GPU memory) is a dead
            # worker: nothing of the shard is written yet (write_shard comes after its
            # last frame), so the driver redoes it whole on a new worker, as after a crash
            first = (str(e).strip().splitlines() or [""])[0][:200]
            sys.stderr.write(f"vhgen worker (pid {os.getpid()}): GL failed on shard {shard} "
                             f"({type(e).__name__}: {first}); the process exits and the "
                             "shard is redone on a new worker\n")
            sys.stderr.flush()
            os._exit(GL_LOST_EXIT)
