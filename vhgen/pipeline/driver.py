"""The Ray driver: read and retarget motions once, plan, shard tasks to GL actors.

Only metadata travels back to the driver; every actor writes its own shards. A task is
retried (on a restarted actor if the process died); because frames are deterministic and
a shard is rewritten whole, a retry never duplicates or loses a frame, and the final
manifest merge checks that every frame appears exactly once.
"""

from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from vhgen import __version__
from vhgen.assets import resolve_asset_dir
from vhgen.body.labels import LabelScheme
from vhgen.body.model import build_body
from vhgen.config import JobConfig
from vhgen.errors import StoreError, VhgenError
from vhgen.mocap.retarget import RetargetMap, load_all_maps
from vhgen.pipeline.plan import make_plan
from vhgen.pipeline.poses import load_poses
from vhgen.pipeline.resources import actor_options
from vhgen.store.manifest import merge_parts
from vhgen.store.zarr_store import clean_partials, completed_shards, create_store, read_attrs

log = logging.getLogger(__name__)

MAX_ATTEMPTS = 3  # retries of one shard after its worker died


class FrameWorker:
    """Ray actor body: one GL context per actor, one shard per call."""

    def __init__(self, cfg, asset_dir, shared_refs, avatars, fail_once=None):
        import ray

        from vhgen.pipeline.frames import FrameGenerator
        from vhgen.pipeline.resources import worker_context

        # the big arrays arrive as nested refs (zero-copy from the object store); passing
        # them as top-level arguments would tie actor restarts to their lifetime
        rotations, roots, pose_meta, plan_arrays = ray.get(list(shared_refs))
        self.gen = FrameGenerator(cfg, asset_dir, rotations, roots, pose_meta, plan_arrays,
                                  avatars, context=worker_context(
                                      cfg, os.environ.get("CUDA_VISIBLE_DEVICES")))
        self.fail_once = fail_once  # (marker folder, shards) for fault-injection tests

    def renderer(self) -> str:
        return self.gen.renderer_info

    def run(self, store, shard, start, stop):
        if self.fail_once is not None and shard in self.fail_once[1]:
            # die as a killed process would, the first time this shard is attempted
            marker = Path(self.fail_once[0]) / f"failed-{shard}"
            if not marker.exists():
                marker.touch()
                os._exit(1)
        return self.gen.run_task(store, shard, start, stop)


def _ray_init(num_workers: int, address: str | None):
    import ray

    if ray.is_initialized():
        return False
    address = address or os.environ.get("RAY_ADDRESS")
    if address:
        ray.init(address=address, logging_level=logging.WARNING)
    else:
        ray.init(num_cpus=num_workers, include_dashboard=False, logging_level=logging.WARNING,
                 log_to_driver=True)
    return True


def run_job(cfg: JobConfig, out: str | Path, *, ray_address: str | None = None,
            resume: bool = False, overwrite: bool = False, fail_once_shards=None) -> dict:
    """Generate the dataset described by ``cfg`` into the Zarr group ``out``.

    Returns a summary dict (frames, shards, seconds, renderer, skipped motion files).
    ``fail_once_shards`` (tests only): shards whose first attempt kills its worker.
    """
    import ray

    t0 = time.perf_counter()
    out = Path(out)
    asset_dir = resolve_asset_dir(cfg.assets)
    scheme = LabelScheme.load(cfg.labels)
    rmap = load_all_maps() if cfg.retarget == "auto" else RetargetMap.load(cfg.retarget)
    base = build_body(asset_dir, scheme)
    poses = load_poses(cfg.motions, base.rig, rmap, cfg.poses)
    plan = make_plan(cfg.seed, poses.num_poses, cfg.avatars, cfg.frames_per_shard)
    t_read = time.perf_counter() - t0
    intr = cfg.sensor.intrinsics
    attrs = {
        "vhgen_version": __version__,
        "config_name": cfg.name,
        "seed": cfg.seed,
        "label_scheme": scheme.name,
        "label_names": scheme.names,
        "label_colors": scheme.palette.tolist(),
        "rig_bones": base.rig.names,
        "sensor": cfg.sensor.to_dict(),
        "depth_units": "millimetre (uint16), 0 = no measurement",
        "frames_per_shard": cfg.frames_per_shard,
        "num_frames": plan.num_frames,
        "motions": poses.report,
    }
    if resume and (out / "zarr.json").is_file():
        old = read_attrs(out)
        for k in ("seed", "num_frames", "frames_per_shard", "label_names", "sensor"):
            if json.dumps(old.get(k), sort_keys=True) != json.dumps(attrs[k], sort_keys=True):
                raise StoreError(f"{out}: cannot resume, {k!r} differs from this config")
        n_clean = clean_partials(out)
        if n_clean:
            log.warning("removed %d partial files left by a killed writer", n_clean)
    else:
        create_store(out, num_frames=plan.num_frames, height=intr.height, width=intr.width,
                     frames_per_shard=cfg.frames_per_shard,
                     compression_level=cfg.compression_level, attrs=attrs, overwrite=overwrite,
                     raw11=cfg.sensor.encoding.raw11)
    done = completed_shards(out)
    todo = [t for t in plan.tasks if t.shard not in done]
    log.info("%d frames in %d shards (%d to do), %d poses from %d motion files", plan.num_frames,
             len(plan.tasks), len(todo), poses.num_poses, len(poses.motion_files))

    started = _ray_init(cfg.num_workers, ray_address)
    try:
        pose_meta = {"motion_id": poses.motion_id, "source_frame": poses.source_frame,
                     "motion_files": poses.motion_files, "motion_sha1": poses.motion_sha1}
        plan_arrays = {"avatar_id": plan.avatar_id, "pose_index": plan.pose_index,
                       "seeds": plan.seeds}
        refs = [ray.put(x) for x in (poses.rotations, poses.roots, pose_meta, plan_arrays)]
        # Actors are not restarted by Ray: the driver replaces a dead actor itself and
        # resubmits its shard, so a restart never depends on constructor arguments.
        opts = actor_options(cfg, ray.cluster_resources() if started else None)
        actor_cls = ray.remote(**opts, max_restarts=0, max_task_retries=0)(FrameWorker)
        n_actors = max(1, min(cfg.num_workers, len(todo)))
        fail_once = None
        if fail_once_shards:
            (out / "_faults").mkdir(exist_ok=True)
            fail_once = (str(out / "_faults"), set(fail_once_shards))

        def new_actor():
            return actor_cls.options(runtime_env={"env_vars": {"LP_NUM_THREADS": "1"}}).remote(
                cfg, str(asset_dir), refs, plan.avatars, fail_once)

        actors = [new_actor() for _ in range(n_actors)]
        renderers = sorted(set(ray.get([a.renderer.remote() for a in actors])))
        log.info("GL renderers: %s", renderers)
        t_render = time.perf_counter()
        pending: dict[Any, tuple[Any, Any]] = {}
        queue = list(todo)
        attempts = {t.shard: 0 for t in todo}
        results = []
        idle = list(actors)
        while queue or pending:
            while queue and idle:
                actor = idle.pop()
                task = queue.pop(0)
                attempts[task.shard] += 1
                ref = actor.run.remote(str(out), task.shard, task.start, task.stop)
                pending[ref] = (actor, task)
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                actor, task = pending.pop(ref)
                try:
                    results.append(ray.get(ref))
                    idle.append(actor)
                except ray.exceptions.RayActorError as e:
                    # the process died (OOM kill, segfault, node loss): replace the actor,
                    # redo the whole shard; frames are deterministic, so nothing duplicates
                    if attempts[task.shard] > MAX_ATTEMPTS:
                        raise VhgenError(f"shard {task.shard} (frames {task.start}-"
                                         f"{task.stop}): worker died {MAX_ATTEMPTS + 1} times; "
                                         f"last: {e}. Rerun with --resume.") from e
                    log.warning("worker died on shard %d (attempt %d), retrying on a new "
                                "worker", task.shard, attempts[task.shard])
                    queue.insert(0, task)
                    idle.append(new_actor())
                except ray.exceptions.RayTaskError as e:
                    raise VhgenError(f"shard {task.shard} (frames {task.start}-{task.stop}) "
                                     f"failed: {e}. Fix the cause, then rerun with --resume "
                                     "to finish the remaining shards.") from e
        t_render = time.perf_counter() - t_render
        for a in idle:
            ray.kill(a)
    finally:
        if started:
            ray.shutdown()
    if fail_once_shards:
        import shutil

        shutil.rmtree(out / "_faults", ignore_errors=True)
    merge_parts(out, plan.num_frames)
    with open(out / "report.json", "w") as f:
        json.dump({"motions": poses.report, "renderers": renderers}, f, indent=1)
    skipped = [r for r in poses.report if r["status"] != "ok"]
    return {"frames": plan.num_frames, "shards": len(plan.tasks), "written": len(results),
            "seconds": time.perf_counter() - t0, "read_seconds": t_read,
            "render_seconds": t_render, "renderers": renderers, "skipped": skipped,
            "store": str(out), "poses": poses.num_poses,
            "retries": sum(attempts.values()) - len(todo),
            # scene objects that found no place after bounded retries (manifest: scene)
            "dropped": {k: sum(r.get("dropped", {}).get(k, 0) for r in results)
                        for k in ("people", "props")},
            "valid_fraction": float(np.mean([r["valid_pixels"] for r in results]) /
                                    (intr.width * intr.height * cfg.frames_per_shard))
            if results else 0.0}
