"""The driver: read and retarget motions once, plan, shard tasks to GL workers.

Workers are Ray actors (a cluster, ``--address``; GPU workers) or processes of this
machine (:mod:`vhgen.pipeline.local`, the default for a local job: a local Ray costs
seconds to start); the same :class:`~vhgen.pipeline.worker.FrameWorker` runs in both and
the same dispatch loop drives them. Only metadata travels back to the driver; every worker
writes its own shards. A task is retried (on a new worker if the process died); because
frames are deterministic and a shard is rewritten whole, a retry never duplicates or loses
a frame, and the final manifest merge checks that every frame appears exactly once.

Start-up is overlapped: the workers start (and Ray, for a Ray job) while a thread reads
and retargets the motions; they set up their GL context and warm their compiled kernels
while the driver plans and writes the store's metadata; the poses reach them afterwards.
A write that fails (disk full, read-only output) stops the dispatch, lets the shards in
flight finish, and raises one line; every finished shard stays, ``--resume`` completes.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import signal
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from vhgen import __version__
from vhgen.assets import resolve_asset_dir
from vhgen.body.labels import LabelScheme
from vhgen.body.model import build_avatar, build_body
from vhgen.config import JobConfig
from vhgen.errors import StoreError, VhgenError
from vhgen.mocap.retarget import RetargetMap, load_all_maps
from vhgen.pipeline.plan import Plan, make_plan
from vhgen.pipeline.poses import PoseSet, load_poses
from vhgen.pipeline.progress import Progress
from vhgen.pipeline.resources import actor_options, choose_executor
from vhgen.pipeline.worker import FrameWorker
from vhgen.store.manifest import ManifestMerger
from vhgen.store.zarr_store import clean_partials, completed_shards, create_store, read_attrs

log = logging.getLogger(__name__)

MAX_ATTEMPTS = 3  # retries of one shard after its worker died
PREBUILT_BODIES = 2  # avatar bodies the driver builds for the workers' first shards
_POLL_SECONDS = 0.5  # the dispatch loop wakes at least this often (see _CtrlC)
_RESUME_KEYS = ("seed", "num_frames", "frames_per_shard", "label_names", "sensor",
                "class_names")


@dataclass
class _Prepared:
    """The driver's share of the start-up, computed while Ray starts."""

    asset_dir: Path
    scheme: LabelScheme
    rig_bones: list[str]
    poses: PoseSet
    plan: Plan
    base_hip_drop: float
    bodies: dict  # avatar id -> Body, the avatars of the first shards (workers start there)


def _prepare(cfg: JobConfig, max_frames: int | None) -> _Prepared:
    asset_dir = resolve_asset_dir(cfg.assets)
    scheme = LabelScheme.load(cfg.labels)
    rmap = load_all_maps() if cfg.retarget == "auto" else RetargetMap.load(cfg.retarget)
    base = build_body(asset_dir, scheme)
    poses = load_poses(cfg.motions, base.rig, rmap, cfg.poses)
    plan = make_plan(cfg.seed, poses.num_poses, cfg.avatars, cfg.frames_per_shard)
    if max_frames is not None and max_frames < plan.num_frames:
        plan = _truncate(plan, max_frames)
    # the driver is idle while the workers set up: it builds the bodies their first
    # shards start with (a worker would spend about 0.25 s on its first one); a few only,
    # so that a wide cluster job does not wait on the driver building bodies in series
    first = sorted({int(plan.avatar_id[t.start]) for t in plan.tasks[:cfg.num_workers]})
    bodies = {a: build_avatar(asset_dir, scheme, plan.avatars[a])
              for a in first[:PREBUILT_BODIES]}
    return _Prepared(asset_dir, scheme, list(base.rig.names), poses, plan, base.hip_drop,
                     bodies)


def _truncate(plan: Plan, n: int) -> Plan:
    """The first ``n`` frames of a plan (the same frames, seeds and shards as the full job)."""
    tasks = [replace(t, stop=min(t.stop, n)) for t in plan.tasks if t.start < n]
    return replace(plan, num_frames=n, avatar_id=plan.avatar_id[:n],
                   pose_index=plan.pose_index[:n], seeds=plan.seeds[:n], tasks=tasks)


def check_output(out: Path, *, resume: bool, overwrite: bool) -> None:
    """Refuse, before any work, an output that cannot be written or must not be replaced."""
    if out.exists():
        if not out.is_dir():
            raise StoreError(f"{out}: exists and is not a folder")
        is_store = (out / "zarr.json").is_file()
        if not (resume or overwrite):
            raise StoreError(f"{out}: exists; pass --resume to finish it or --overwrite to "
                             "replace it")
        if not is_store and any(out.iterdir()):
            # creating the store deletes the folder's contents: only ever a store we wrote
            raise StoreError(f"{out}: a folder that is not a vhgen store and not empty; "
                             "choose another --out")
        target = out
    else:
        target = out.parent
        while not target.exists() and target != target.parent:
            target = target.parent
    if not os.access(target, os.W_OK | os.X_OK):
        why = "read-only file system" if _read_only(target) else "permission denied"
        raise StoreError(f"{out}: cannot write output ({target}: {why})")


def _read_only(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _os_error_line(e: OSError, out: Path, what: str) -> str:
    name = errno.errorcode.get(e.errno or 0, "")
    hint = {errno.ENOSPC: "free space", errno.EDQUOT: "raise the quota",
            errno.EROFS: "make the output writable", errno.EACCES: "fix the permissions"}
    return (f"{out}: {what}: {e.strerror or e} ({name}{': ' + e.filename if e.filename else ''})"
            f"; finished shards are kept: {hint.get(e.errno or 0, 'fix the cause')}, then "
            "rerun with --resume")


def _ray_env(local: bool) -> None:
    """Environment for Ray, set before it starts (the workers of a local Ray inherit it),
    and Ray's notices that do not concern a vhgen user hidden (shown with --verbose)."""
    if local:
        # a new local Ray turns token authentication on and warns about it unless the
        # mode is set: keep it on, explicitly, which is what silences the warning
        os.environ.setdefault("RAY_AUTH_MODE", "token")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if not logging.getLogger("vhgen").isEnabledFor(logging.DEBUG):
        # joining a cluster with a token in ~/.ray warns the same way (Ray's own module
        # logger: only its warnings about the authentication mode are hidden)
        logging.getLogger("ray._private.authentication.authentication_token_setup").setLevel(
            logging.ERROR)


def _ray_init(num_workers: int, address: str | None) -> bool:
    import ray

    if ray.is_initialized():
        return False
    level = logging.INFO if logging.getLogger("vhgen").isEnabledFor(logging.DEBUG) \
        else logging.ERROR
    if address:
        ray.init(address=address, logging_level=level)
    else:
        ray.init(num_cpus=num_workers, include_dashboard=False, logging_level=level,
                 log_to_driver=True)
    return True


def _shutdown_local_ray(ray) -> None:
    """ray.shutdown() of the Ray this driver started, without its 1 s stall.

    Ray stops its processes one by one, each given up to 1 s to exit after SIGTERM; the
    autoscaler monitor of a local head always uses the whole second (measured: 1.01 s of
    a 1.25 s shutdown). It holds no state of ours, so it is killed first. Ray's private
    node handle is used defensively: if it changes, this is a plain ray.shutdown().
    """
    try:
        node = ray._private.worker._global_node
        for info in node.all_processes.get("monitor", []):
            info.process.kill()
    except (AttributeError, KeyError, OSError):
        pass
    ray.shutdown()


def run_job(cfg: JobConfig, out: str | Path, *, ray_address: str | None = None,
            resume: bool = False, overwrite: bool = False, max_frames: int | None = None,
            progress: bool = False, executor: str = "auto", faults: dict | None = None
            ) -> dict:
    """Generate the dataset described by ``cfg`` into the Zarr group ``out``.

    max_frames : only the plan's first N frames (same frames and seeds as the full job).
    progress : show frames done, frames/s and ETA (a bar on a terminal, log lines
        otherwise).
    executor : ``local`` (worker processes on this machine), ``ray`` (Ray actors: the
        cluster at ``ray_address`` / ``RAY_ADDRESS``, else a local Ray) or ``auto``
        (see :func:`~vhgen.pipeline.resources.choose_executor`).
    faults : fault injection for tests (see :class:`FrameWorker`).
    Returns a summary dict (frames, shards, seconds, renderer, skipped motion files,
    ``executor``) with the timings: ``ray_init_seconds`` (0 without Ray),
    ``first_shard_seconds`` (start to the first shard written), ``tail_seconds`` (last
    shard to return), ``steady_seconds_per_frame`` (one worker) and ``fixed_seconds``
    (wall time minus the frames at the steady rate).
    """
    t0 = time.perf_counter()
    out = Path(out)
    check_output(out, resume=resume, overwrite=overwrite)
    asset_dir = resolve_asset_dir(cfg.assets)  # missing assets: fail before any worker
    if resume and (out / "zarr.json").is_file():
        _check_same_config(out, _config_attrs(cfg, LabelScheme.load(cfg.labels)))
    address = ray_address or os.environ.get("RAY_ADDRESS")
    kind = choose_executor(executor, address, cfg)
    faults = dict(faults or {})
    marker_dir = out.parent / f".{out.name}.faults"
    if "die_once" in faults:
        marker_dir.mkdir(parents=True, exist_ok=True)
        faults["die_once"] = (str(marker_dir), set(faults["die_once"]))

    prep = ThreadPoolExecutor(1, thread_name_prefix="vhgen-prepare")
    pool: Any = None
    t_ray = 0.0
    try:
        if kind == "local":
            from vhgen.pipeline.local import LocalPool

            # the workers start first: their set-up (interpreter, GL, kernels) is the
            # longest part and needs only the config
            pool = LocalPool(cfg, str(asset_dir), faults)
            pool.start(cfg.num_workers)
            prepared = prep.submit(_prepare, cfg, max_frames)
        else:
            prepared = prep.submit(_prepare, cfg, max_frames)
            pool = _RayPool.connect(cfg, str(asset_dir), faults, address)
            t_ray = time.perf_counter() - t0
            pool.start(cfg.num_workers)
        p = prepared.result()
        plan, poses = p.plan, p.poses
        _open_store(cfg, out, p, resume)
        done = completed_shards(out)
        todo = [t for t in plan.tasks if t.shard not in done]
        log.info("%d frames in %d shards (%d to do), %d poses from %d motion files, %s "
                 "workers", plan.num_frames, len(plan.tasks), len(todo), poses.num_poses,
                 len(poses.motion_files), kind)
        pool.stop(list(pool.workers)[max(1, len(todo)):])
        pose_meta = {"motion_id": poses.motion_id, "source_frame": poses.source_frame,
                     "motion_files": poses.motion_files, "motion_sha1": poses.motion_sha1}
        plan_arrays = {"avatar_id": plan.avatar_id, "pose_index": plan.pose_index,
                       "seeds": plan.seeds}
        try:
            renderers = sorted(set(pool.load(poses.rotations, poses.roots, pose_meta,
                                             plan_arrays, plan.avatars, p.bodies,
                                             p.base_hip_drop)))
        except VhgenError as e:
            raise VhgenError(f"worker set-up: {e}") from None
        log.info("GL renderers: %s", renderers)
        t_render = time.perf_counter()
        bar = Progress(sum(t.stop - t.start for t in todo), enabled=progress)
        merger = ManifestMerger(out)
        results, attempts, first_frame = _dispatch(pool, todo, out, bar, merger)
        bar.close()
        t_render = time.perf_counter() - t_render
        t_last = time.perf_counter()
        n_workers = len(pool.workers)
        pool.release()  # workers exit while the driver merges
        if "die_once" in faults:
            import shutil

            shutil.rmtree(marker_dir, ignore_errors=True)
        try:
            merger.finish(plan.num_frames)
            with open(out / "report.json", "w") as f:
                json.dump({"motions": poses.report, "renderers": renderers}, f, indent=1)
        except OSError as e:
            raise StoreError(_os_error_line(e, out, "cannot write the manifest")) from None
    finally:
        prep.shutdown(wait=True)
        if pool is not None:
            pool.close()
    skipped = [r for r in poses.report if r["status"] != "ok"]
    intr = cfg.sensor.intrinsics
    t_end = time.perf_counter()
    per_frame = _steady_seconds_per_frame(results)
    return {"frames": plan.num_frames, "shards": len(plan.tasks), "written": len(results),
            "executor": kind,
            "seconds": t_end - t0, "read_seconds": t_ray, "ray_init_seconds": t_ray,
            "render_seconds": t_render, "renderers": renderers, "skipped": skipped,
            "first_shard_seconds": (first_frame or t_end) - t0, "tail_seconds": t_end - t_last,
            "steady_seconds_per_frame": per_frame,
            # everything that does not grow with the frames: the job's wall time minus the
            # frames at the steady rate of its workers
            "fixed_seconds": t_end - t0 - sum(t.stop - t.start for t in todo) * per_frame
            / max(1, n_workers),
            "store": str(out), "poses": poses.num_poses,
            "retries": sum(attempts.values()) - len(todo),
            # scene objects that found no place after bounded retries (manifest: scene)
            "dropped": {k: sum(r.get("dropped", {}).get(k, 0) for r in results)
                        for k in ("people", "props")},
            "valid_fraction": float(np.mean([r["valid_pixels"] for r in results]) /
                                    (intr.width * intr.height * cfg.frames_per_shard))
            if results else 0.0}


class _RayPool:
    """Ray actors behind the interface of :class:`~vhgen.pipeline.local.LocalPool`.

    Actors are not restarted by Ray: the driver replaces a dead actor itself and
    resubmits its shard, so a restart never depends on constructor arguments."""

    def __init__(self, ray: Any, started: bool, cfg: JobConfig, asset_dir: str,
                 faults: dict):
        self.ray = ray
        self.started = started  # this driver started the (local) Ray
        opts = actor_options(cfg, ray.cluster_resources() if started else None)
        self.actor_cls = ray.remote(**opts, max_restarts=0, max_task_retries=0)(FrameWorker)
        self.args = (cfg, asset_dir, faults)
        self.workers: dict[int, Any] = {}
        self.pending: dict[Any, tuple[int, Any]] = {}
        self._next_id = 0
        self._load_args: tuple | None = None

    @classmethod
    def connect(cls, cfg: JobConfig, asset_dir: str, faults: dict,
                address: str | None) -> _RayPool:
        _ray_env(local=not address)
        import ray

        started = _ray_init(cfg.num_workers, address)
        try:
            return cls(ray, started, cfg, asset_dir, faults)
        except BaseException:
            if started:
                _shutdown_local_ray(ray)
            raise

    def start(self, n: int) -> list[int]:
        return [self._new() for _ in range(n)]

    def _new(self) -> int:
        wid = self._next_id
        self._next_id += 1
        self.workers[wid] = self.actor_cls.remote(*self.args)
        return wid

    def load(self, rotations: Any, roots: Any, pose_meta: dict, plan_arrays: dict,
             avatars: list, bodies: dict, base_hip_drop: float) -> list[str]:
        ray = self.ray
        # in the object store once; top-level refs reach every actor as (zero-copy) values
        refs = [ray.put(x) for x in (rotations, roots, pose_meta, plan_arrays, bodies)]
        self._load_args = (*refs[:4], avatars, refs[4], base_hip_drop)
        try:
            return ray.get([a.load.remote(*self._load_args) for a in self.workers.values()])
        except ray.exceptions.RayTaskError as e:
            if isinstance(getattr(e, "cause", None), VhgenError):
                raise e.cause from None
            raise

    def stop(self, wids: list[int]) -> None:
        for wid in wids:
            self.ray.kill(self.workers.pop(wid))

    def release(self) -> None:
        """Let the actors go (the job is done); Ray itself is stopped by close()."""
        for a in self.workers.values():
            self.ray.kill(a)
        self.workers.clear()

    def close(self) -> None:
        self.release()
        if self.started:
            self.started = False
            _shutdown_local_ray(self.ray)

    def replace(self, wid: int) -> int:
        """A new actor in place of the dead one ``wid``, its load queued; returns at once
        (a run submitted to it fails as ``died`` if it dies loading)."""
        self.workers.pop(wid, None)
        new = self._new()
        if self._load_args is not None:  # queued before any run() on the same actor
            self.workers[new].load.remote(*self._load_args)
        return new

    def submit(self, wid: int, task: Any, *args: Any) -> None:
        self.pending[self.workers[wid].run.remote(*args)] = (wid, task)

    def wait(self, timeout: float | None = None) -> list[tuple[int, Any, str, Any]]:
        ray = self.ray
        if not self.pending:
            return []
        ready, _ = ray.wait(list(self.pending), num_returns=1, timeout=timeout)
        out = []
        for ref in ready:
            wid, task = self.pending.pop(ref)
            try:
                out.append((wid, task, "ok", ray.get(ref)))
            except ray.exceptions.RayActorError:
                # the process died (OOM kill, segfault, node loss)
                out.append((wid, task, "died", None))
            except ray.exceptions.RayTaskError as e:
                cause = getattr(e, "cause", None)
                # a user-facing cause is answered by the dispatch; anything else is a bug
                # whose Ray error keeps the worker's traceback
                out.append((wid, task, "error",
                            cause if isinstance(cause, (OSError, VhgenError)) else e))
        return out


def _steady_seconds_per_frame(results: list[dict]) -> float:
    """Median seconds per frame of one worker over the shards it ran (render, sensor and
    write; a worker's first shard, which builds its first avatar, counts like the rest)."""
    rates = [r["seconds"] / r["frames"] for r in results if r.get("seconds")]
    return float(np.median(rates)) if rates else 0.0


def _open_store(cfg: JobConfig, out: Path, p: _Prepared, resume: bool) -> None:
    """Create the store, or check that the one to resume was made by the same config."""
    plan = p.plan
    intr = cfg.sensor.intrinsics
    attrs = {**_config_attrs(cfg, p.scheme), "rig_bones": p.rig_bones,
             "num_frames": plan.num_frames, "motions": p.poses.report}
    try:
        if resume and (out / "zarr.json").is_file():
            _check_same_config(out, attrs)
            n_clean = clean_partials(out)
            if n_clean:
                log.warning("removed %d partial files left by a killed writer", n_clean)
        else:
            create_store(out, num_frames=plan.num_frames, height=intr.height, width=intr.width,
                         frames_per_shard=cfg.frames_per_shard,
                         compression_level=cfg.compression_level, attrs=attrs,
                         overwrite=True, raw11=cfg.sensor.encoding.raw11)
    except OSError as e:
        raise StoreError(_os_error_line(e, out, "cannot create the store")) from None


def _config_attrs(cfg: JobConfig, scheme: LabelScheme) -> dict:
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
    }


def _check_same_config(out: Path, attrs: dict) -> None:
    """Refuse to resume a store made by another config (the keys present in ``attrs``)."""
    old = read_attrs(out)
    for k in _RESUME_KEYS:
        if k in attrs and json.dumps(old.get(k), sort_keys=True) != json.dumps(
                attrs[k], sort_keys=True):
            raise StoreError(f"{out}: made by another config ({k!r} differs: store "
                             f"{_short(old.get(k))}, config {_short(attrs[k])}); "
                             "cannot resume it (use another --out or --overwrite)")


def _short(v: Any) -> str:
    s = json.dumps(v, sort_keys=True)
    return s if len(s) <= 40 else s[:37] + "..."


class _CtrlC:
    """Ctrl-C during the dispatch, noticed within :data:`_POLL_SECONDS` however it lands.

    Python runs signal handlers in the main thread only, between bytecodes: a SIGINT that
    the kernel hands to another thread (pyarrow's, zarr's) leaves the main thread asleep
    in its wait, and a KeyboardInterrupt raised inside a finaliser or callback is printed
    and dropped. The handler here also records the interrupt, and the dispatch loop,
    which wakes at least every :data:`_POLL_SECONDS`, raises it again if it was lost.
    Installed only over Python's own handler, from the main thread (elsewhere, or when
    SIGINT is ignored or handled by the caller, a no-op)."""

    def __init__(self) -> None:
        self.hit = False
        self.previous: Any = None

    def __enter__(self) -> _CtrlC:
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            self.previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def _handler(self, signum: int, frame: Any) -> None:
        self.hit = True
        raise KeyboardInterrupt

    def check(self) -> None:
        if self.hit:
            raise KeyboardInterrupt

    def __exit__(self, *exc: object) -> None:
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)


def _dispatch(pool: Any, todo: list, out: Path, bar: Progress, merger: ManifestMerger
              ) -> tuple[list[dict], dict[int, int], float | None]:
    """Run every task on the pool's workers (one in flight per worker), handing each
    finished shard's manifest part to ``merger``. A worker that died is replaced and its
    shard redone whole (the replacement sets up while the others go on; dying in its
    set-up counts as one more attempt on the shard). On a write failure, stop
    dispatching, let the tasks in flight finish, then raise one line."""
    queue = list(todo)
    attempts = {t.shard: 0 for t in todo}
    results: list[dict] = []
    idle = list(pool.workers)
    in_flight = 0
    first_frame: float | None = None
    error: VhgenError | None = None

    def fill() -> None:  # one task to every idle worker
        nonlocal in_flight
        while queue and idle and error is None:
            wid = idle.pop()
            task = queue.pop(0)
            attempts[task.shard] += 1
            pool.submit(wid, task, str(out), task.shard, task.start, task.stop)
            in_flight += 1

    fill()
    with _CtrlC() as ctrl_c:
        while in_flight:
            finished = []
            done = pool.wait(timeout=_POLL_SECONDS)
            ctrl_c.check()
            for wid, task, kind, value in done:
                in_flight -= 1
                if kind == "ok":
                    results.append(value)
                    idle.append(wid)
                    finished.append(task.shard)
                    bar.update(task.stop - task.start)
                    first_frame = first_frame or time.perf_counter()
                elif kind == "died":
                    # frames are deterministic: redoing the whole shard duplicates nothing
                    if attempts[task.shard] > MAX_ATTEMPTS:
                        error = error or VhgenError(
                            f"shard {task.shard} (frames {task.start}-{task.stop}): worker died "
                            f"{MAX_ATTEMPTS + 1} times; rerun with --resume")
                        continue
                    log.warning("worker died on shard %d (attempt %d), retrying on a new worker",
                                task.shard, attempts[task.shard])
                    queue.insert(0, task)
                    idle.append(pool.replace(wid))
                else:
                    idle.append(wid)
                    if isinstance(value, OSError):
                        err: VhgenError = StoreError(_os_error_line(
                            value, out, f"cannot write shard {task.shard}"))
                    elif isinstance(value, VhgenError):
                        err = VhgenError(f"shard {task.shard}: {value}")
                    else:
                        raise value  # a bug: keep the worker's traceback
                    error = error or err
            fill()  # the workers first, then the driver's own reading
            for shard in finished:
                merger.add(shard)
    if error is not None:
        raise error
    return results, attempts, first_frame
