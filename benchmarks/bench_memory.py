"""Resident memory (RSS) of every frame actor over a long run: does it stay flat?

    .venv/bin/python benchmarks/bench_memory.py --frames 20000 --workers 2 --every 1000

Runs the real job (``run_job`` with ``--executor``: local worker processes or Ray actors;
the shared CMU corpus, many avatars so actors
also switch bodies) and, from a thread of the driver, samples the RSS of each
``FrameWorker`` actor process (found among this process's descendants) whenever another
``--every`` frames have been written (counted from the manifest parts on disk). Prints
RSS per actor at each checkpoint, the growth from the first checkpoint to the last, and the
growth over the second half of the run (middle checkpoint to last). RSS steps up during
warm-up (kernels compiled, allocator pools filled, the first larger avatar body, which
the allocator keeps as its high-water mark) and must then stay flat. Goal: below 5% per
actor. The driver's own RSS is sampled beside them.

    .venv/bin/python benchmarks/bench_memory.py --merge-only --frames 100000 --every 10000

measures the one part of the driver that grows with a job, the manifest merge, without
rendering: it makes a 32-frame ``cluttered_room`` store, writes its manifest rows again
as the parts of a ``--frames`` job (frames and shards renumbered), then hands them to
``ManifestMerger`` as the driver does when shards finish, sampling the process's RSS.
Goal: flat within 100 MB however many frames.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared" / "mocap" / "cmu"

CONFIG = """
name: memory
seed: 1
motions: [{motions}]
sensor: {sensor}
poses: {{frame_step: {step}, skip_first: 1, max_per_motion: {per_motion}}}
avatars: {{count: {avatars}, tights_probability: 0.3, skirt_probability: 0.2}}
output: {{frames_per_shard: {fps}}}
render: {{backend: {backend}}}
num_workers: {workers}
"""


def _children() -> dict[int, list[int]]:
    kids: dict[int, list[int]] = {}
    for p in Path("/proc").iterdir():
        if not p.name.isdigit():
            continue
        try:
            stat = (p / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        kids.setdefault(ppid, []).append(int(p.name))
    return kids


def actor_rss_mb(root: int) -> dict[int, float]:
    """pid -> RSS in MB of the FrameWorker actors descending from ``root``."""
    kids, out, todo = _children(), {}, [root]
    while todo:
        pid = todo.pop()
        todo += kids.get(pid, [])
        try:
            cmd = (Path("/proc") / str(pid) / "cmdline").read_bytes()
            # a Ray actor names itself; a local worker runs vhgen.executor.local.serve
            if not (cmd.startswith(b"ray::FrameWorker")
                    or b"from vhgen.executor.local import serve" in cmd):
                continue
            for line in (Path("/proc") / str(pid) / "status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    out[pid] = int(line.split()[1]) / 1024
        except OSError:
            continue
    return out


def rss_mb(pid: int) -> float:
    """RSS of process ``pid`` in MB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def merge_only(args: argparse.Namespace) -> None:
    """The driver's manifest merge of a ``--frames`` job alone (see the module docstring)."""
    import pyarrow as pa

    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job
    from vhgen.store.manifest import ManifestMerger, read_manifest, write_parquet

    per = args.frames_per_shard
    with tempfile.TemporaryDirectory() as tmp:
        seed_store = Path(tmp) / "rows.zarr"
        cfg = JobConfig.load(REPO / "configs" / "scenes" / "cluttered_room.yaml")
        run_job(cfg, seed_store, max_frames=per, overwrite=True, progress=False)
        rows = read_manifest(seed_store)
        out = Path(tmp) / "merge.zarr"
        (out / "manifest").mkdir(parents=True)
        shards = -(-args.frames // per)
        t0 = time.perf_counter()
        for k in range(shards):  # the parts a job of --frames frames leaves
            n = min(per, args.frames - k * per)
            part = rows.slice(0, n)
            part = part.set_column(part.column_names.index("frame"), "frame",
                                   pa.array(range(k * per, k * per + n), pa.int64()))
            part = part.set_column(part.column_names.index("shard"), "shard",
                                   pa.array([k] * n, pa.int32()))
            write_parquet(part, out / "manifest" / f"part-{k:06d}.parquet")
        print(f"{args.frames} frames of cluttered_room manifest rows in {shards} parts "
              f"({time.perf_counter() - t0:.0f} s to write)")
        print(f"{'frames':>8} {'driver MB':>10}")
        base = rss_mb(os.getpid())
        print(f"{0:>8} {base:>10.1f}")
        series = []
        merger = ManifestMerger(out, list(range(shards)), range(shards))
        t0 = time.perf_counter()
        for k in range(shards):
            merger.add(k)
            if (k + 1) * per % args.every < per or k == shards - 1:
                series.append(rss_mb(os.getpid()))
                print(f"{min((k + 1) * per, args.frames):>8} {series[-1]:>10.1f}")
        merger.finish(args.frames)
        size = (out / "manifest.parquet").stat().st_size
        print(f"merged in {time.perf_counter() - t0:.1f} s; manifest.parquet "
              f"{size / 1e6:.1f} MB ({size / args.frames:.0f} bytes a frame); RSS growth from "
              f"the first checkpoint to the last {series[-1] - series[0]:+.1f} MB, peak "
              f"{max(series):.1f} MB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=20000, help="frames to generate (about)")
    ap.add_argument("--every", type=int, default=1000, help="checkpoint every n frames")
    ap.add_argument("--workers", type=int, default=2, help="frame actors")
    ap.add_argument("--frame-step", type=int, default=2, help="poses: every n-th source frame")
    ap.add_argument("--avatars", type=int, default=8,
                    help="avatars (more if the corpus has too few poses for --frames)")
    ap.add_argument("--sensor", default="kinect_v1_full")
    ap.add_argument("--backend", choices=["egl", "osmesa"], default="egl")
    ap.add_argument("--frames-per-shard", type=int, default=32)
    ap.add_argument("--executor", choices=["local", "ray"], default="local",
                    help="worker processes of this machine or Ray actors")
    ap.add_argument("--out", help="store path (default: a temporary folder, removed)")
    ap.add_argument("--merge-only", action="store_true",
                    help="only the driver's manifest merge of a --frames job (no rendering)")
    args = ap.parse_args()
    if args.merge_only:
        return merge_only(args)

    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job
    from vhgen.pipeline.job import prepare_job

    with tempfile.TemporaryDirectory() as tmp:
        cfg_path = Path(tmp) / "memory.yaml"

        def write(avatars: int, per_motion: int) -> JobConfig:
            cfg_path.write_text(CONFIG.format(
                motions=SHARED, sensor=args.sensor, step=args.frame_step, avatars=avatars,
                per_motion=per_motion, fps=args.frames_per_shard, backend=args.backend,
                workers=args.workers))
            return JobConfig.load(cfg_path)

        # frames = poses x avatars: cap the poses per motion file so that --avatars
        # avatars give about --frames frames; add avatars if the corpus is too small
        cfg = write(1, 0)
        poses = prepare_job(cfg).poses
        files = max(1, sum(r["status"] == "ok" for r in poses.report))
        per_motion = math.ceil(args.frames / args.avatars / files)
        cfg = write(1, per_motion)
        poses = prepare_job(cfg).poses
        cfg = write(max(args.avatars, math.ceil(args.frames / poses.num_poses)), per_motion)
        total = cfg.avatars.count * poses.num_poses
        out = Path(args.out) if args.out else Path(tmp) / "memory.zarr"
        print(f"{total} frames: {poses.num_poses} poses x {cfg.avatars.count} avatars, "
              f"{args.workers} {args.executor} workers, sensor {args.sensor}, "
              f"backend {args.backend}")

        samples: list[tuple[int, float, dict[int, float]]] = []
        done = threading.Event()
        t0 = time.perf_counter()

        def sample() -> None:
            next_mark = args.every
            parts = out / "manifest"
            while not done.is_set():
                n = len(list(parts.glob("part-*.parquet"))) * args.frames_per_shard \
                    if parts.is_dir() else 0
                if n >= next_mark:
                    samples.append((n, time.perf_counter() - t0,
                                    {0: rss_mb(os.getpid()), **actor_rss_mb(os.getpid())}))
                    next_mark = (n // args.every + 1) * args.every
                done.wait(0.5)

        th = threading.Thread(target=sample, daemon=True)
        th.start()
        try:
            summary = run_job(cfg, out, overwrite=True, executor=args.executor)
        finally:
            done.set()
            th.join()

    pids = sorted({p for _, _, r in samples for p in r})
    names = {0: "driver", **{p: f"actor {i}" for i, p in enumerate(q for q in pids if q)}}
    print(f"\n{'frames':>7} {'s':>7}  " + "  ".join(f"{names[p] + ' MB':>12}" for p in pids))
    for n, t, rss in samples:
        print(f"{n:>7} {t:>7.0f}  " + "  ".join(
            f"{rss[p]:>12.1f}" if p in rss else f"{'-':>12}" for p in pids))
    print(f"\n{summary.frames} frames in {summary.seconds:.0f} s "
          f"({summary.frames / summary.render_seconds:.1f} frames/s while rendering); "
          f"{summary.retries} retries")
    print(f"{'actor':<10} {'first MB':>9} {'mid MB':>9} {'last MB':>9} {'peak MB':>9} "
          f"{'growth %':>9} {'2nd half %':>10}")
    for p in pids:
        series = [r[p] for _, _, r in samples if p in r]
        if len(series) < 2:
            print(f"{names[p]:<10} (one sample: run longer or lower --every)")
            continue
        mid = series[len(series) // 2]
        # growth: first checkpoint to last (includes warm-up steps such as the first larger
        # avatar); 2nd half: middle checkpoint to last, the leak indicator of a long run
        print(f"{names[p]:<10} {series[0]:>9.1f} {mid:>9.1f} {series[-1]:>9.1f} "
              f"{max(series):>9.1f} {100 * (series[-1] - series[0]) / series[0]:>9.2f} "
              f"{100 * (series[-1] - mid) / mid:>10.2f}")

if __name__ == "__main__":
    main()
