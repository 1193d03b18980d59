"""Frames per second of a whole job on this machine, by number of workers, with the GL
renderer and the GPU's busy share: the measurement of a GPU node (issue 28).

    .venv/bin/python benchmarks/bench_gpu.py [--config cluttered_room] [--workers 1,2,4]
        [--frames 32] [--frames-per-shard N] [--motions PATH ...] [--sensor NAME]
        [--sensor-backend cpu|gl] [--backend egl|osmesa] [--repeat 1] [--no-warmup]
        [--layout-frames 1,16] [--batch-frames 0,4,16] [--gl-calls N [--row-threads 1,128]]
        [--profile N]

Each worker count runs the same job (``run_job``, the local executor: worker processes on
this machine, one GL context each) over the first ``--frames`` frames of the config's plan
(the same frames and seeds for every count) into a temporary store, deleted afterwards.
A warm-up job of one shard and one worker runs first (kernels compiled and cached, the
macro-target cache built), unreported. Per row:

* wall: the whole job, start-up and merge included; fixed: what does not grow with the
  frames (``RunSummary.fixed_seconds``: wall minus the frames at the steady rate);
* layout, batch: ``scene.layout_frames`` and ``render.batch_frames`` (frames a worker
  with the GL sensor draws and senses before reading any back; 0 reads each back before
  the next is drawn; with the CPU sensor it does not apply);
* frames/s dispatch: frames over the dispatch (the workers set up, until the last shard
  returned), so start-up, merge and shutdown excluded, the last shards' tail included;
* frames/s steady: workers x one worker's median frames/s over its shards
  (``RunSummary.steady_seconds_per_frame``): the rate while every worker is busy, without
  the work of a worker's first shard that later ones reuse (its clutter library, 1-2 s);
* GPU busy: ``nvidia-smi --query-gpu=utilization.gpu`` sampled every 0.5 s, mean and
  maximum over the samples taken during the dispatch (mean over the GPUs when there are
  several); ``-`` without ``nvidia-smi``;
* CPU busy: the share of the machine's CPU time (every core) not idle during the
  dispatch, from ``/proc/stat`` read at the same samples; ``-`` where there is none. Near
  100% with the GPU far from busy: the CPU work per frame sets the pace.

``--gl-calls N`` instead times one worker's GL calls in this process: N frames of the
config (after 16 unreported) rendered as a worker renders them (describe, draw, sensor,
record; no store), then N more with every GL call of the frame path (each compute
dispatch, by program; buffer reads, writes and clears; texture uploads; draws; read-backs;
memory barriers) between two ``glFinish``, so each row is the call's own GPU and driver
time. The first line gives ms per frame without and with the instrumentation.
``--row-threads 1,128`` repeats it with the GL sensor's row scans (shadows,
registration, the speckle filter's runs) at one invocation a row and at 128 (the GPU
layout, ``row_scan.glsl``), side by side in one run.

``--profile N`` instead profiles one worker's CPU in this process (cProfile): a
``FrameWorker`` set up as in a job of ``max(--workers)`` workers (its share of codec
threads), the first shard unreported, then whole shards (describe, draw, sense, read back,
decode, record, write the shard into a temporary store) until N frames; the first
``--layout-frames`` and ``--batch-frames`` value apply. Prints ms a frame under the
profiler and the 25 functions that take the most, by own time and with what they call.
On a GPU node this is where the CPU of a frame goes and what waits for the GPU.

Fewer shards than workers leave workers idle (a row says how many ran): on a GPU node use
enough frames for several shards per worker, e.g. ``--frames 2400 --workers 4,8,16,32``
(docs/performance.md). Here (2 cores, llvmpipe) ``--frames 32 --workers 1,2`` is a smoke
run.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from vhgen.job_config import JobConfig

SMI = ["nvidia-smi", "--query-gpu=utilization.gpu", "--format=csv,noheader,nounits"]
SAMPLE_SECONDS = 0.5


class GpuSampler:
    """``nvidia-smi``'s GPU utilisation (percent) and ``/proc/stat``'s CPU time every
    :data:`SAMPLE_SECONDS` in a thread, with the time of each sample
    (``time.perf_counter``); no GPU samples without nvidia-smi, no CPU samples without
    ``/proc/stat``."""

    def __init__(self) -> None:
        self.available = shutil.which(SMI[0]) is not None
        self.samples: list[tuple[float, float]] = []
        self.cpu: list[tuple[float, int, int]] = []  # time, busy and all jiffies
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> GpuSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()

    def _run(self) -> None:
        due = time.perf_counter()
        while not self._stop.is_set():
            jiffies = cpu_jiffies()
            if jiffies is not None:
                self.cpu.append((time.perf_counter(), *jiffies))
            busy = query_utilization() if self.available else None
            if busy is not None:
                self.samples.append((time.perf_counter(), busy))
            due += SAMPLE_SECONDS
            self._stop.wait(max(0.0, due - time.perf_counter()))

    def between(self, t0: float, t1: float) -> list[float]:
        """The samples taken in [t0, t1]."""
        return [b for t, b in self.samples if t0 <= t <= t1]

    def cpu_busy(self, t0: float, t1: float) -> float | None:
        """The share of CPU time not idle between the first and last samples in [t0, t1]
        (percent), or None with fewer than two."""
        inside = [(busy, total) for t, busy, total in self.cpu if t0 <= t <= t1]
        if len(inside) < 2 or inside[-1][1] <= inside[0][1]:
            return None
        return 100.0 * (inside[-1][0] - inside[0][0]) / (inside[-1][1] - inside[0][1])


def cpu_jiffies() -> tuple[int, int] | None:
    """(busy, all) CPU time of every core since boot from ``/proc/stat``, or None."""
    try:
        with open("/proc/stat") as f:
            fields = [int(v) for v in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return sum(fields) - idle, sum(fields)


def query_utilization() -> float | None:
    """The mean utilisation of this machine's GPUs now (percent), or None."""
    try:
        out = subprocess.run(SMI, capture_output=True, text=True, timeout=5, check=True).stdout
        values = [float(v) for v in out.split()]
    except (OSError, subprocess.SubprocessError, ValueError):
        return None
    return sum(values) / len(values) if values else None


def gpu_names() -> str:
    """nvidia-smi's GPU names, or '-'."""
    if shutil.which(SMI[0]) is None:
        return "-"
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=10, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return "-"
    return ", ".join(n.strip() for n in out.splitlines() if n.strip()) or "-"


@dataclass(frozen=True)
class Row:
    """One job: its workers (asked, and that ran), frames, times and GPU samples."""

    workers: int
    ran: int
    frames: int
    wall: float
    fixed: float
    dispatch: float
    steady_fps: float
    gpu: list[float]
    cpu: float | None
    renderers: list[str]
    layout_frames: int = 1
    batch_frames: int = 0


def run_one(cfg: JobConfig, frames: int, workers: int, sampler: GpuSampler | None) -> Row:
    """One job of ``frames`` frames with ``workers`` local workers; its row."""
    from vhgen.pipeline.driver import run_job

    c = replace(cfg, num_workers=workers)
    with tempfile.TemporaryDirectory(prefix="vhgen-bench-gpu-") as tmp:
        t0 = time.perf_counter()
        s = run_job(c, Path(tmp) / "job.zarr", max_frames=frames, executor="local")
    ran = min(workers, s.shards)
    # the dispatch window: run_job's clock starts just after t0
    t_end = t0 + s.seconds - s.tail_seconds
    gpu = sampler.between(t_end - s.render_seconds, t_end) if sampler else []
    cpu = sampler.cpu_busy(t_end - s.render_seconds, t_end) if sampler else None
    steady = ran / s.steady_seconds_per_frame if s.steady_seconds_per_frame else 0.0
    return Row(workers, ran, s.frames, s.seconds, s.fixed_seconds, s.render_seconds, steady,
               gpu, cpu, s.renderers, cfg.scene.layout_frames, cfg.batch_frames)


def load_config(args: argparse.Namespace) -> JobConfig:
    """The scene config with the command's overrides."""
    from vhgen.job_config import JobConfig
    from vhgen.sensor.sensor_config import SensorConfig

    cfg = JobConfig.load(args.config, backend=args.backend)
    if args.motions:
        cfg = replace(cfg, motions=tuple(str(Path(m).expanduser().resolve())
                                         for m in args.motions))
    if args.sensor:
        cfg = replace(cfg, sensor=SensorConfig.load(args.sensor))
    if args.sensor_backend:  # the effects on the CPU (numba) or as GL compute passes
        cfg = replace(cfg, sensor=cfg.sensor.with_backend(args.sensor_backend))
    if args.frames_per_shard:
        cfg = replace(cfg, frames_per_shard=args.frames_per_shard)
    if args.frame_step:  # more poses of each clip: a plan with more frames
        cfg = replace(cfg, poses=replace(cfg.poses, frame_step=args.frame_step))
    return cfg


def print_table(rows: list[Row], gpu_available: bool) -> None:
    """The rows as a table (one line per job)."""
    print(f"{'workers':>7s} {'layout':>6s} {'batch':>5s} {'frames':>6s} {'wall s':>7s} "
          f"{'fixed s':>7s} {'dispatch s':>10s} "
          f"{'frames/s dispatch':>17s} {'frames/s steady':>15s} {'GPU busy % mean/max':>19s} "
          f"{'CPU busy %':>10s}")
    for r in rows:
        if r.gpu:
            busy = f"{sum(r.gpu) / len(r.gpu):.0f} / {max(r.gpu):.0f}"
        else:
            busy = "no samples" if gpu_available else "-"
        ran = f"{r.workers}" if r.ran == r.workers else f"{r.workers} ({r.ran} ran)"
        print(f"{ran:>7s} {r.layout_frames:6d} {r.batch_frames:5d} {r.frames:6d} "
              f"{r.wall:7.1f} {r.fixed:7.1f} {r.dispatch:10.2f} "
              f"{r.frames / max(r.dispatch, 1e-9):17.1f} {r.steady_fps:15.1f} {busy:>19s} "
              f"{'-' if r.cpu is None else f'{r.cpu:.0f}':>10s}")


def gl_calls(cfg: JobConfig, frames: int, row_threads: int | None = None) -> None:
    """Print where one worker's GL time goes (see the module docstring); ``row_threads``:
    the GL sensor's invocations a row in its row scans (None: its own choice)."""
    from collections import defaultdict
    from collections.abc import Callable
    from typing import Any

    import moderngl

    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job

    gen = FrameGenerator(prepare_job(cfg))
    ctx = gen.ctx
    if row_threads is not None and gen.gl_sensor is not None:
        from vhgen.render.sensor_gl import GLSensorModel

        gen.gl_sensor.release()
        gen.sensor = gen.gl_sensor = GLSensorModel(ctx, cfg.sensor, row_threads)
    plan = gen.job.plan.num_frames
    for f in range(16):
        gen.render_frame(f % plan)
    t = time.perf_counter()
    for f in range(16, 16 + frames):
        gen.render_frame(f % plan)
    plain = (time.perf_counter() - t) / frames
    names = {id(prog): name.removesuffix(".comp") + ":" + str(dict(defs).get("STEP", ""))
             for (name, defs), prog in getattr(gen.sensor, "_programs", {}).items()}
    spent: dict[str, float] = defaultdict(float)
    originals: list[tuple[Any, str, Any]] = []  # put back at the end
    calls: dict[str, int] = defaultdict(int)

    def wrap(cls: Any, method: str, label: Callable[[Any], str]) -> None:
        original = getattr(cls, method)
        originals.append((cls, method, original))

        def timed(obj: Any, *a: Any, **k: Any) -> Any:
            ctx.finish()
            t0 = time.perf_counter()
            out = original(obj, *a, **k)
            ctx.finish()
            spent[label(obj)] += time.perf_counter() - t0
            calls[label(obj)] += 1
            return out

        setattr(cls, method, timed)

    wrap(moderngl.ComputeShader, "run", lambda p: "dispatch " + names.get(id(p), "?"))
    wrap(moderngl.ComputeShader, "run_indirect", lambda p: "indirect " + names.get(id(p), "?"))
    def buffer_label(method: str) -> Callable[[Any], str]:
        return lambda b: f"buffer.{method} {b.size // 1024} kB"

    for m in ("read", "clear", "write", "read_into"):
        wrap(moderngl.Buffer, m, buffer_label(m))
    wrap(moderngl.Texture, "write", lambda x: f"texture.write {x.width}x{x.height}")
    wrap(moderngl.Framebuffer, "read_into", lambda _: "framebuffer.read_into")
    wrap(moderngl.Framebuffer, "read", lambda _: "framebuffer.read")
    wrap(moderngl.VertexArray, "render", lambda _: "draw")
    wrap(moderngl.Context, "memory_barrier", lambda _: "memory_barrier")
    t = time.perf_counter()
    try:
        for f in range(16 + frames, 16 + 2 * frames):
            gen.render_frame(f % plan)
    finally:
        for cls, method, original in originals:
            setattr(cls, method, original)
    timed_frame = (time.perf_counter() - t) / frames
    threads = getattr(gen.gl_sensor, "row_threads", None)
    gen.close()
    scans = f", row scans: {threads} invocations a row" if threads else ""
    print(f"GL renderer: {gen.renderer_info}{scans}; a frame (describe, draw, sensor, "
          f"record): "
          f"{1e3 * plain:.1f} ms, {1e3 * timed_frame:.1f} ms with every GL call finished")
    print(f"{'ms/frame':>8s} {'calls/frame':>11s}  GL call")
    for k, v in sorted(spent.items(), key=lambda kv: -kv[1]):
        print(f"{1e3 * v / frames:8.3f} {calls[k] / frames:11.1f}  {k}")
    print(f"{1e3 * sum(spent.values()) / frames:8.3f} {'':11s}  every GL call")


def profile(cfg: JobConfig, frames: int, workers: int, top: int = 25) -> None:
    """Print where one worker's CPU time goes (see the module docstring)."""
    import cProfile
    import pstats

    from vhgen.pipeline.job import prepare_job
    from vhgen.pipeline.worker import FrameWorker
    from vhgen.store.zarr_store import create_store

    cfg = replace(cfg, num_workers=workers)  # the worker's share of codec threads
    job = prepare_job(cfg)
    tasks = job.plan.tasks
    worker = FrameWorker(cfg)
    renderer = worker.load(job)
    intr = cfg.sensor.intrinsics
    with tempfile.TemporaryDirectory(prefix="vhgen-bench-gpu-") as tmp:
        store = str(Path(tmp) / "job.zarr")
        create_store(store, num_frames=job.plan.num_frames, height=intr.height,
                     width=intr.width, frames_per_shard=cfg.frames_per_shard, attrs={},
                     compression_level=cfg.compression_level, arrays=cfg.arrays,
                     codec=cfg.codec, palette=cfg.palette)
        worker.run(store, tasks[0].shard, tasks[0].start, tasks[0].stop)  # unreported
        prof, done = cProfile.Profile(), 0
        t = time.perf_counter()
        for task in tasks[1:]:
            if done >= frames:
                break
            prof.enable()
            worker.run(store, task.shard, task.start, task.stop)
            prof.disable()
            done += task.stop - task.start
        wall = time.perf_counter() - t
    worker.gen.close()
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    print(f"GL renderer: {renderer}; one worker of {workers}, {done} frames after one "
          f"unreported shard: {1e3 * wall / max(done, 1):.1f} ms a frame under the "
          f"profiler (describe, draw, sensor, read back, decode, record, write the shard)")
    for key, title in ((2, "own time"), (3, "time with what it calls")):
        print(f"{'ms/frame':>8s} {'calls/frame':>11s}  function, by {title}")
        rows = sorted(stats.items(), key=lambda kv: -kv[1][key])[:top]
        for (file, line, name), st in rows:
            where = f"{Path(file).name}:{line}({name})" if line else name
            print(f"{1e3 * st[key] / max(done, 1):8.3f} {st[1] / max(done, 1):11.2f}  "
                  f"{where}")


def _ints(text: str, what: str, lo: int, hi: int) -> list[int]:
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text}: comma-separated {what}") from None
    if not values or min(values) < lo or max(values) > hi:
        raise argparse.ArgumentTypeError(f"{text}: {what} must be {lo}-{hi}")
    return values


def _counts(text: str) -> list[int]:
    return _ints(text, "worker counts", 1, 4096)


def _row_threads(text: str) -> list[int]:
    values = _ints(text, "invocations a row", 1, 256)
    if any(v & (v - 1) for v in values):
        raise argparse.ArgumentTypeError(f"{text}: invocations a row are powers of two")
    return values


def _layouts(text: str) -> list[int]:
    return _ints(text, "layout_frames values", 1, 100000)


def _batches(text: str) -> list[int]:
    return _ints(text, "batch sizes", 0, 64)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default="cluttered_room",
                    help="scene config: a shipped name or a YAML path")
    ap.add_argument("--workers", type=_counts, default=[1, 2, 4],
                    help="comma-separated worker counts, e.g. 4,8,16,32")
    ap.add_argument("--frames", type=int, default=32, help="frames of each job")
    ap.add_argument("--frames-per-shard", type=int, default=0,
                    help="override the config's output.frames_per_shard")
    ap.add_argument("--frame-step", type=int, default=0,
                    help="override the config's poses.frame_step (4: a 7,034-frame plan of "
                    "cluttered_room over the CMU corpus)")
    ap.add_argument("--motions", nargs="+", help="BVH files or folders instead of the "
                    "config's motions (e.g. ../shared/mocap/cmu)")
    ap.add_argument("--sensor", help="a sensor config instead of the scene's (e.g. ideal)")
    ap.add_argument("--sensor-backend", choices=["cpu", "gl"], default=None,
                    help="run the sensor's effects on the CPU or as GL passes (sensor.backend)")
    ap.add_argument("--backend", choices=["egl", "osmesa"], default=None)
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs of every worker count, interleaved")
    ap.add_argument("--no-warmup", action="store_true", help="skip the warm-up job")
    ap.add_argument("--layout-frames", type=_layouts, default=None,
                    help="comma-separated scene.layout_frames values, each worker count run "
                         "with each, interleaved (e.g. 1,16; default: the config's)")
    ap.add_argument("--batch-frames", type=_batches, default=None,
                    help="comma-separated render.batch_frames values (with the GL sensor), "
                         "each run with every worker count and layout, interleaved (e.g. "
                         "0,4,16; default: the config's)")
    ap.add_argument("--gl-calls", type=int, metavar="N", default=0,
                    help="time one worker's GL calls over N frames instead (no job)")
    ap.add_argument("--row-threads", type=_row_threads, metavar="LIST",
                    help="--gl-calls: once for each of these invocations a row in the GL "
                         "sensor's row scans, in turn (e.g. 1,128: one a row against the "
                         "GPU layout; default: the sensor's own choice)")
    ap.add_argument("--profile", type=int, metavar="N", default=0,
                    help="profile one worker's CPU over N frames instead (no job; "
                         "--workers: the job's worker count it takes its share for)")
    args = ap.parse_args()

    cfg = load_config(args)
    if args.gl_calls:
        for n in args.row_threads or [None]:
            gl_calls(cfg, args.gl_calls, n)
        return
    if args.profile:
        layouts, batches = args.layout_frames or [], args.batch_frames or []
        if layouts:
            cfg = replace(cfg, scene=replace(cfg.scene, layout_frames=layouts[0]))
        if batches:
            cfg = replace(cfg, batch_frames=batches[0])
        profile(cfg, args.profile, max(args.workers))
        return
    sampler_probe = shutil.which(SMI[0]) is not None
    print(f"vhgen whole job: config {cfg.name}, {args.frames} frames in shards of "
          f"{cfg.frames_per_shard}, sensor {cfg.sensor.name} ({cfg.sensor.backend}), backend "
          f"{cfg.backend}, local executor, {os.cpu_count()} CPUs, GPU {gpu_names()}")
    if not args.no_warmup:
        run_one(cfg, min(args.frames, cfg.frames_per_shard), 1, None)
    rows = []
    layouts = args.layout_frames or [cfg.scene.layout_frames]
    batches = args.batch_frames or [cfg.batch_frames]
    with GpuSampler() as sampler:
        for _ in range(args.repeat):
            for w in args.workers:
                for n in layouts:  # frames sharing a layout (docs/scenes.md)
                    for b in batches:
                        c = replace(cfg, scene=replace(cfg.scene, layout_frames=n),
                                    batch_frames=b)
                        rows.append(run_one(c, args.frames, w, sampler))
                        print(f"  {w} workers, layout_frames {n}, batch_frames {b}: "
                              f"{rows[-1].wall:.1f} s", flush=True)
    renderers = sorted({r for row in rows for r in row.renderers})
    print(f"GL renderer: {', '.join(renderers)}")
    print_table(rows, sampler_probe)


if __name__ == "__main__":
    main()
