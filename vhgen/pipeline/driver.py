"""The driver: prepare the job once, start the workers, dispatch the shards, merge.

It orchestrates only: the job is prepared by :func:`~vhgen.pipeline.job.prepare_job`,
the output checked and opened by :mod:`vhgen.store.output`, the workers run in a pool of
:mod:`vhgen.executor` (processes of this machine, the default for a local job: a local Ray
costs seconds to start; or Ray actors: a cluster, GPU workers), shards go out through
:func:`~vhgen.pipeline.dispatch.dispatch`. Only metadata travels back; every worker writes
its own shards.

Start-up is overlapped: the workers start (and Ray, for a Ray job) while a thread reads
and retargets the motions; they set up their GL context and warm their compiled kernels
while the driver plans and writes the store's metadata; the job reaches them afterwards.
"""

from __future__ import annotations

import json
import logging
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.assets import resolve_asset_dir
from vhgen.body.avatar import Body
from vhgen.body.labels import LabelScheme
from vhgen.errors import StoreError, VhgenError
from vhgen.job_config import JobConfig
from vhgen.pipeline.dispatch import MAX_ATTEMPTS, dispatch
from vhgen.pipeline.frames import ShardResult
from vhgen.pipeline.job import Job, prepare_job
from vhgen.pipeline.progress import Progress
from vhgen.pipeline.resources import actor_options, choose_executor
from vhgen.pipeline.worker import FrameWorker
from vhgen.store.manifest import ManifestMerger
from vhgen.store.output import (
    check_output,
    check_same_config,
    open_output,
    os_error_line,
)
from vhgen.store.zarr_store import completed_shards
from vhgen.version import __version__

log = logging.getLogger(__name__)

__all__ = ["MAX_ATTEMPTS", "RunSummary", "run_job"]

PREBUILT_BODIES = 2  # avatar bodies the driver builds for the workers' first shards


@dataclass(frozen=True)
class RunSummary:
    """What a job did. Timings in seconds: ``seconds`` the whole job, ``ray_init_seconds``
    (0 without Ray), ``render_seconds`` the dispatch, ``first_shard_seconds`` start to
    the first shard written, ``tail_seconds`` last shard to return,
    ``steady_seconds_per_frame`` one worker's median time per frame, ``fixed_seconds``
    the wall time minus the frames at that steady rate (what does not grow with the
    frames)."""

    frames: int  # in the store
    shards: int  # in the store
    written: int  # shards written by this run (fewer when resuming)
    retries: int  # shard attempts beyond the first (workers that died)
    executor: str  # local or ray
    store: str
    poses: int
    renderers: list[str]
    skipped: list[dict[str, Any]]  # motion files not used, with their clip reports
    dropped: dict[str, int]  # people / props that found no place (manifest: scene)
    valid_fraction: float  # of the pixels of the frames written
    seconds: float
    ray_init_seconds: float
    render_seconds: float
    first_shard_seconds: float
    tail_seconds: float
    steady_seconds_per_frame: float
    fixed_seconds: float
    results: list[ShardResult] = field(default_factory=list, repr=False)


def _prepare(cfg: JobConfig, max_frames: int | None, num_workers: int
             ) -> tuple[Job, dict[int, Body]]:
    """The job, and the bodies the workers' first shards start with: the driver is idle
    while the workers set up, so it builds them (a worker would spend about 0.25 s on its
    first one); a few only, so that a wide cluster job does not wait on the driver
    building bodies in series."""
    job = prepare_job(cfg, max_frames=max_frames)
    plan = job.plan
    first = sorted({int(plan.avatar_id[t.start]) for t in plan.tasks[:num_workers]})
    return job, {a: job.avatar_body(a) for a in first[:PREBUILT_BODIES]}


def _start_pool(kind: str, cfg: JobConfig, worker: type, address: str | None) -> Any:
    """A pool of ``cfg.num_workers`` frame workers, their set-up started."""
    if kind == "local":
        from vhgen.executor.local import LocalPool

        pool: Any = LocalPool(worker)
    else:
        from vhgen.executor.raypool import RayPool

        pool = RayPool.connect(worker, address=address, local_cpus=cfg.num_workers,
                               options=lambda res: actor_options(cfg, res))
    pool.start([(cfg,)] * cfg.num_workers)
    return pool


def config_attrs(cfg: JobConfig, scheme: LabelScheme) -> dict[str, Any]:
    """The store attributes that follow from the config alone."""
    return {
        "vhgen_version": __version__,
        "config_name": cfg.name,
        "seed": cfg.seed,
        "label_scheme": scheme.name,
        "label_names": scheme.names,
        "label_colors": scheme.palette.tolist(),
        "class_names": list(cfg.class_names),
        "sensor": cfg.sensor.to_dict(),
        "depth_units": "millimetre (uint16), 0 = no measurement",
        "frames_per_shard": cfg.frames_per_shard,
        # only where asked for: the attributes of every other config stay as they were
        **({"poses_bend": {"share": cfg.poses.bend_share,
                           "degrees": list(cfg.poses.bend_degrees)}}
           if cfg.poses.bend_share > 0 else {}),
    }


def run_job(cfg: JobConfig, out: str | Path, *, ray_address: str | None = None,
            resume: bool = False, overwrite: bool = False, max_frames: int | None = None,
            progress: bool = False, executor: str = "auto",
            worker: type[FrameWorker] = FrameWorker) -> RunSummary:
    """Generate the dataset described by ``cfg`` into the Zarr group ``out``.

    max_frames : only the plan's first N frames (same frames and seeds as the full job).
    progress : show frames done, frames/s and ETA (a bar on a terminal, log lines
        otherwise).
    executor : ``local`` (worker processes on this machine), ``ray`` (Ray actors: the
        cluster at ``ray_address`` / ``RAY_ADDRESS``, else a local Ray) or ``auto``
        (see :func:`~vhgen.pipeline.resources.choose_executor`).
    worker : the worker class (a :class:`FrameWorker` or a subclass of it, importable by
        the workers' processes).
    """
    t0 = time.perf_counter()
    out = Path(out)
    check_output(out, resume=resume, overwrite=overwrite)
    resolve_asset_dir(cfg.assets)  # missing assets: fail before any worker
    attrs = config_attrs(cfg, LabelScheme.load(cfg.labels))
    if resume and (out / "zarr.json").is_file():
        check_same_config(out, attrs)
    address = ray_address or os.environ.get("RAY_ADDRESS")
    kind = choose_executor(executor, address, cfg)

    prep = ThreadPoolExecutor(1, thread_name_prefix="vhgen-prepare")
    pool: Any = None
    t_ray = 0.0
    try:
        if kind == "local":
            # the workers start first: their set-up (interpreter, GL, kernels) is the
            # longest part and needs only the config
            pool = _start_pool(kind, cfg, worker, address)
            prepared = prep.submit(_prepare, cfg, max_frames, cfg.num_workers)
        else:
            prepared = prep.submit(_prepare, cfg, max_frames, cfg.num_workers)
            pool = _start_pool(kind, cfg, worker, address)
            t_ray = time.perf_counter() - t0
        job, bodies = prepared.result()
        plan, poses = job.plan, job.poses
        intr = cfg.sensor.intrinsics
        bent = {} if poses.bend_deg is None else {"bent_poses": {
            str(i): round(float(poses.bend_deg[i]), 3) for i in np.flatnonzero(poses.bend_deg)}}
        open_output(out, {**attrs, "rig_bones": job.rig_bones, "num_frames": plan.num_frames,
                          "motions": poses.report, **bent}, plan.num_frames, resume,
                    height=intr.height, width=intr.width,
                    frames_per_shard=cfg.frames_per_shard,
                    compression_level=cfg.compression_level,
                    arrays=cfg.arrays, codec=cfg.codec, palette=cfg.palette)
        done = completed_shards(out)
        todo = [t for t in plan.tasks if t.shard not in done]
        log.info("%d frames in %d shards (%d to do), %d poses from %d motion files, %s "
                 "workers", plan.num_frames, len(plan.tasks), len(todo), poses.num_poses,
                 len(poses.motion_files), kind)
        pool.stop(list(pool.workers)[max(1, len(todo)):])
        try:
            renderers = sorted(set(pool.setup("load", job, bodies)))
        except VhgenError as e:
            raise VhgenError(f"worker set-up: {e}") from None
        log.info("GL renderers: %s", renderers)
        t_render = time.perf_counter()
        bar = Progress(sum(t.stop - t.start for t in todo), enabled=progress)
        merger = ManifestMerger(out, [t.shard for t in plan.tasks],
                                 [t.shard for t in todo])
        results, attempts, first_frame = dispatch(pool, todo, out, bar, merger)
        bar.close()
        t_render = time.perf_counter() - t_render
        t_last = time.perf_counter()
        n_workers = len(pool.workers)
        pool.release()  # workers exit while the driver merges
        try:
            merger.finish(plan.num_frames)
            with open(out / "report.json", "w") as f:
                json.dump({"motions": poses.report, "renderers": renderers}, f, indent=1)
        except OSError as e:
            raise StoreError(os_error_line(e, out, "cannot write the manifest")) from None
    finally:
        prep.shutdown(wait=True)
        if pool is not None:
            pool.close()
    intr = cfg.sensor.intrinsics
    t_end = time.perf_counter()
    per_frame = _steady_seconds_per_frame(results)
    return RunSummary(
        frames=plan.num_frames, shards=len(plan.tasks), written=len(results),
        retries=sum(attempts.values()) - len(todo), executor=kind, store=str(out),
        poses=poses.num_poses, renderers=renderers,
        skipped=[r for r in poses.report if r["status"] != "ok"],
        dropped={k: sum(r.dropped.get(k, 0) for r in results)
                 for k in dict.fromkeys(["people", "props", *(k for r in results
                                                              for k in r.dropped)])},
        valid_fraction=float(np.mean([r.valid_pixels for r in results])
                             / (intr.width * intr.height * cfg.frames_per_shard))
        if results else 0.0,
        seconds=t_end - t0, ray_init_seconds=t_ray, render_seconds=t_render,
        first_shard_seconds=(first_frame or t_end) - t0, tail_seconds=t_end - t_last,
        steady_seconds_per_frame=per_frame,
        fixed_seconds=t_end - t0 - sum(t.stop - t.start for t in todo) * per_frame
        / max(1, n_workers),
        results=results)


def _steady_seconds_per_frame(results: list[ShardResult]) -> float:
    """Median seconds per frame of one worker over the shards it ran (render, sensor and
    write; a worker's first shard, which builds its first avatar, counts like the rest)."""
    rates = [r.seconds / r.frames for r in results if r.seconds]
    return float(np.median(rates)) if rates else 0.0
