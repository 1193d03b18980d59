"""Frames per second of each pipeline stage and end to end, for the default config.

    .venv/bin/python benchmarks/bench_pipeline.py [--config configs/scenes/default.yaml]
        [--frames 60] [--backend egl] [--no-e2e]

Stages are timed side by side in one process on the same frames (this machine is shared
and noisy: compare the ratios, not the absolute numbers across runs):

* read: parse + retarget + ground + select, per source frame and per pose kept;
* skin+render: bone matrices (float64) + one draw call + readback, one process;
* sensor: gating, noise, 1/8 px quantisation, uint16 mm encoding;
* write: one Zarr shard of uint16 depth + uint8 labels (zstd) + its manifest part;
* scene comparison (``--scene``, default ``living_room`` and ``cluttered_room``): each
  scene config's frames (as configured and with one person) beside the person-only ones,
  all interleaved in one process (in memory, with the parts: layout, of which clutter
  placement; GL draw and read back; sensor; then whole shards written), and then all run
  as jobs (``run_job``, local workers, the configs' worker count), the steady time per
  frame of a worker side by side. The in-process rows use one llvmpipe thread and one
  thread for numba/BLAS, as every worker does (the workers are the parallelism); set
  ``LP_NUM_THREADS`` yourself to see more. A short run on a shared machine:
  ``--no-e2e --scene-frames 32 --scene-job-frames 0``;
* end to end: ``run_job`` through Ray with the config's workers, including Ray start-up,
  and the same without start-up (render phase only);
* real backgrounds (``--backgrounds``, a config with ``scene.backgrounds``; default
  ``docs/examples/real_room.yaml``, people in three of the shared captures): the read of
  each background file in parts (decode, floor RANSAC, free floor), the memory a job
  holds per background, and its frames interleaved with ``--scene``'s (``living_room``)
  in one process, per part (describe and placement; GL draw and composite; sensor, two
  passes over a composited frame; the rest: record), in memory and end to end (shards
  written). ``--backgrounds-only`` runs only these rows;
* fixed cost (``--startup`` runs only this): the wall time of a job with zero frames, i.e.
  the intercept ``a`` of ``T(N) = a + b N`` through two runs of the same job (same
  workers) that differ only in their number of frames, N set through ``poses.frame_step``
  (default: frame steps 8 and 2 of the default config, 60 and 240 frames); ``b`` is the
  steady time per frame. It counts Ray start, actor set-up, kernel loading, planning,
  the merge and Ray shutdown: everything that does not grow with the frames. Only
  ``JobConfig.load`` and ``run_job(cfg, out)`` are used, so the same command measures
  an older checkout (``PYTHONPATH=/path/to/old/checkout``) side by side. The in-run rows
  (this version) subtract the frames at the workers' own steady rate from one job.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default=str(REPO / "configs" / "scenes" / "default.yaml"))
    ap.add_argument("--frames", type=int, default=60, help="frames for the per-stage timings")
    ap.add_argument("--backend", choices=["egl", "osmesa"], default=None)
    ap.add_argument("--no-e2e", action="store_true", help="skip the Ray end-to-end run")
    ap.add_argument("--scene", nargs="*",
                    default=[str(REPO / "configs" / "scenes" / f"{n}.yaml")
                             for n in ("living_room", "cluttered_room")],
                    help="scene configs whose frames are timed beside --config's, all "
                         "interleaved (targets: a scene at most 1.3x a person-only frame, "
                         "cluttered_room at most 1.5x living_room); none to skip")
    ap.add_argument("--scene-frames", type=int, default=96,
                    help="frames timed per config for the scene comparison (in memory, "
                         "then end to end: the same frames)")
    ap.add_argument("--scene-job-frames", type=int, default=240,
                    help="frames of each job in the scene comparison's job runs (two "
                         "runs of each config, interleaved); 0 to skip")
    ap.add_argument("--backgrounds", default=str(REPO / "docs" / "examples" / "real_room.yaml"),
                    help="a config with scene.backgrounds whose frames are timed beside "
                         "--scene's, per part; '' to skip")
    ap.add_argument("--background-frames", type=int, default=48,
                    help="frames timed per config for the background rows")
    ap.add_argument("--backgrounds-only", action="store_true",
                    help="only the background rows")
    ap.add_argument("--startup", action="store_true", help="only the fixed-cost rows")
    ap.add_argument("--steps", type=int, nargs=2, default=(8, 2),
                    help="the two poses.frame_step values of the fixed-cost runs")
    args = ap.parse_args()
    from vhgen.executor.local import worker_env

    # one thread per library, as in a worker (read when the libraries load)
    os.environ.update(worker_env())
    if args.startup:
        from vhgen.job_config import JobConfig

        jc = JobConfig.load(args.config, backend=args.backend)
        print_rows(fixed_cost(jc, args.steps), f"vhgen fixed cost: config {jc.name}, "
                   f"backend {jc.backend}, {jc.num_workers} workers, {os.cpu_count()} CPUs")
        return

    if args.backgrounds_only:
        from vhgen.assets import resolve_asset_dir

        rows, notes = background_rows(args.backgrounds, _beside(args.scene), args.backend,
                                      args.background_frames, resolve_asset_dir(None))
        print_rows(rows, f"vhgen real backgrounds: {Path(args.backgrounds).name} beside "
                   f"{Path(_beside(args.scene)).name}, {os.cpu_count()} CPUs")
        for n in notes:
            print(n)
        return

    from vhgen.assets import resolve_asset_dir
    from vhgen.camera import sample_camera
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job
    from vhgen.sensor.simulator import SensorModel
    from vhgen.store.manifest import write_part
    from vhgen.store.zarr_store import create_store, write_shard

    cfg = JobConfig.load(args.config, backend=args.backend)
    asset_dir = resolve_asset_dir(cfg.assets)
    rows = []

    t = time.perf_counter()
    job = prepare_job(cfg, asset_dir=asset_dir)  # read, retarget, base body, plan
    t_read = time.perf_counter() - t
    poses, plan = job.poses, job.plan
    t = time.perf_counter()
    job.avatar_body(0)
    t_body = time.perf_counter() - t
    n_src = sum(r["frames"] for r in poses.report)
    rows.append(("prepare: read (per source frame)", n_src, t_read))
    rows.append(("prepare: read (per pose kept)", poses.num_poses, t_read))
    rows.append(("body build (per avatar)", 1, t_body))

    gen = FrameGenerator(job)
    n = min(args.frames, plan.num_frames)
    frames = np.arange(n) % plan.num_frames
    from vhgen.body.skinning import bone_matrices

    b = gen.describer.body(0)
    gen.renderer.set_mesh(b.vertices, b.faces, b.joints, b.weights, b.face_labels, b.num_bones)
    gen.renderer.render(np.broadcast_to(np.eye(4), (b.num_bones, 4, 4)))  # warm up
    depths = []
    t = time.perf_counter()
    for f in frames:
        p = int(plan.pose_index[f])
        cam = sample_camera(np.random.default_rng(int(plan.seeds[f])), cfg.camera)
        mats = bone_matrices(b.rig, poses.rotations[p], poses.roots[p] * np.array([0, 1, 0]))
        d, _ = gen.renderer.render(cam.world_to_camera @ mats)
        depths.append(d)
    rows.append(("skin+render (1 process)", n, time.perf_counter() - t))

    s = cfg.sensor
    model = SensorModel(s)
    if not s.needs:  # effects that need the incidence/projector depth are timed inside "frame"
        t = time.perf_counter()
        for i, d in enumerate(depths):
            model.simulate(d, np.random.default_rng(i))
        rows.append((f"sensor ({s.name})", n, time.perf_counter() - t))

    gen.render_frame(0)  # compile / load the sensor kernels once per process
    t = time.perf_counter()
    out_rows = [gen.render_frame(int(f)) for f in frames[: cfg.frames_per_shard]]
    t_full = time.perf_counter() - t
    rows.append(("frame (render+sensor+meta)", len(out_rows), t_full))
    summary: list[str] = []
    if args.scene:
        summary = _scene_rows(args.scene, args.backend, gen, args.scene_frames, rows,
                              asset_dir)
        if args.scene_job_frames > 0:
            summary += _scene_job_rows(cfg, args.scene, args.backend, args.scene_job_frames,
                                       rows)
    if args.backgrounds:
        bg_rows, bg_notes = background_rows(args.backgrounds, _beside(args.scene),
                                            args.backend, args.background_frames, asset_dir)
        rows += bg_rows
        summary += bg_notes
    with tempfile.TemporaryDirectory() as tmp:
        store = Path(tmp) / "bench.zarr"
        k = cfg.frames_per_shard
        create_store(store, num_frames=k * 4, height=s.intrinsics.height,
                     width=s.intrinsics.width, frames_per_shard=k,
                     compression_level=cfg.compression_level, attrs={})
        dep = np.stack([r.depth_mm for r in out_rows])
        lab = np.stack([r.labels for r in out_rows])
        ids = {"instances": np.stack([r.instances for r in out_rows]),
               "classes": np.stack([r.classes for r in out_rows])}
        t = time.perf_counter()
        for shard in range(4):
            write_shard(store, shard, k, dep, lab, None, extra=ids)
            meta = [replace(r.record, frame=shard * k + i, shard=shard)
                    for i, r in enumerate(out_rows)]
            write_part(store, shard, meta, len(meta[0].joints_cam) // 3)
        rows.append(("write (zarr shard + manifest)", 4 * k, time.perf_counter() - t))
        mb = sum(p.stat().st_size for p in store.rglob("*") if p.is_file()) / 1e6
    gen.close()

    if not args.no_e2e:
        from vhgen.pipeline.driver import run_job

        with tempfile.TemporaryDirectory() as tmp:
            summary = run_job(cfg, Path(tmp) / "e2e.zarr")
        rows.append((f"end to end, Ray x{cfg.num_workers} (with start-up)", summary.frames,
                     summary.seconds))
        rows.append((f"end to end, Ray x{cfg.num_workers} (render phase)", summary.frames,
                     summary.render_seconds))
        rows += fixed_cost(cfg, args.steps)

    print(f"\nvhgen pipeline benchmark: config {cfg.name}, backend {cfg.backend}, "
          f"renderer {gen.renderer_info}, {os.cpu_count()} CPUs")
    print(f"{'stage':42s} {'items':>7s} {'seconds':>9s} {'items/s':>10s} {'ms/item':>9s}")
    for name, count, sec in rows:
        print(f"{name:42s} {count:7d} {sec:9.3f} {count / max(sec, 1e-9):10.1f} "
              f"{1000 * sec / count:9.2f}")
    print(f"zarr size: {mb / (4 * cfg.frames_per_shard):.2f} MB/frame (depth, labels, "
          f"instances, classes; zstd level {cfg.compression_level or 'per array'})")
    for line in summary:
        print(line)


def _beside(scenes: list[str]) -> str:
    """The scene config the background rows are timed beside: the first of --scene, else
    living_room."""
    return scenes[0] if scenes else str(REPO / "configs" / "scenes" / "living_room.yaml")


def _cycled(job, n: int):
    """``job`` with its plan's frames repeated to ``n`` frames (same seeds, cycled)."""
    from dataclasses import replace as rep

    p = job.plan
    return rep(job, plan=rep(p, num_frames=n, avatar_id=np.resize(p.avatar_id, n),
                             pose_index=np.resize(p.pose_index, n),
                             seeds=np.resize(p.seeds, n)))


def _scene_rows(scene_paths, backend, gen, num_frames, rows, asset_dir) -> list[str]:
    """Frames of each scene config timed interleaved with the person-only generator's
    (same process, same machine state), each as configured and with exactly one person:
    rows for all of them and the ratios, first the in-memory frame (describe, render,
    sensor, record) with its parts (the layout, of which clutter placement; GL draw and
    read back; the sensor), then end to end: whole shards written to a store as a job's
    worker does (``run_task``: the frames, the Zarr shard and its manifest part). Both
    passes time the same frames (after a warm-up shard), frame i of each plan (cycled
    when a plan is shorter). A clutter library (built once per worker, then reused) is
    built before the timing and its cost is a row of its own. Returns the summary lines."""
    import vhgen.scene.layout as layout
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job
    from vhgen.scene.clutter import variant
    from vhgen.store.zarr_store import create_store

    cfgs = []
    for path in scene_paths:
        full = JobConfig.load(path, backend=backend)
        # the same room, props and clutter with exactly one person: what the scene costs
        cfgs += [full, replace(full, scene=replace(full.scene, people=(1, 1)))]
    k = min(c.frames_per_shard for c in [gen.cfg, *cfgs])
    shards = max(2, num_frames // k)
    frames = range(k, (shards + 1) * k)  # shard 0: warm-up (avatars, zarr, pyarrow)
    jobs = [gen.job] + [prepare_job(c, asset_dir=asset_dir) for c in cfgs]
    gens = [FrameGenerator(_cycled(j, (shards + 1) * k), context=gen.ctx) for j in jobs]
    names = ["person only"] + [f"{c.name}{' 1 person' if i % 2 else ''}"
                               for i, c in enumerate(cfgs)]
    for c in cfgs[::2]:
        cl = c.scene.clutter
        if cl is not None and cl.variants:
            t = time.perf_counter()
            for kind in dict.fromkeys(cl.kinds):
                for v in range(cl.variants):
                    variant(kind, cl.fill, c.seed, v)
            rows.append((f"  clutter library of {c.name} (per worker, once)", 1,
                         time.perf_counter() - t))
    for g in gens:
        # every avatar built and uploaded first: a per-avatar cost (the "body build" row),
        # not a per-frame one, which a short run would otherwise charge to a few frames
        for a in range(len(g.job.plan.avatars)):
            g.scene._resident([a])
        for f in range(k):
            g.render_frame(f)
    parts = {name: {"describe": 0.0, "clutter": 0.0, "GL": 0.0, "sensor": 0.0}
             for name in names}
    current = [names[0]]
    _time_part(layout, "place_clutter", parts, current, "clutter")
    for g in gens:
        _time_part(g.describer, "describe", parts, current, "describe")
        _time_part(g.scene, "render", parts, current, "GL")
        _time_part(g.sensor, "simulate", parts, current, "sensor")
    t_mem = dict.fromkeys(names, 0.0)
    people = dict.fromkeys(names, 0)
    for f in frames:
        for name, g in zip(names, gens, strict=True):
            current[0] = name
            t = time.perf_counter()
            out = g.render_frame(f)
            t_mem[name] += time.perf_counter() - t
            people[name] += out.record.num_people
    m = len(frames)
    parts = {name: dict(p) for name, p in parts.items()}  # the end-to-end pass adds more
    for name in names:
        rows.append((f"frame, {name} ({people[name] / m:.2f} people)", m, t_mem[name]))
        for part, sec in parts[name].items():
            if sec > 0:
                rows.append((f"  of which {part}", m, sec))
    # end to end: shards of the same frames written by each generator, interleaved
    t_e2e = dict.fromkeys(names, 0.0)
    with tempfile.TemporaryDirectory() as tmp:
        stores = []
        for j, g in enumerate(gens):
            c = g.cfg
            stores.append(str(Path(tmp) / f"s{j}.zarr"))
            create_store(stores[-1], num_frames=(shards + 1) * k,
                         height=c.sensor.intrinsics.height, width=c.sensor.intrinsics.width,
                         frames_per_shard=k, compression_level=c.compression_level,
                         attrs={}, arrays=c.arrays)
        for sh in range(shards + 1):
            for name, g, store in zip(names, gens, stores, strict=True):
                t = time.perf_counter()
                g.run_task(store, sh, sh * k, sh * k + k)
                if sh > 0:  # shard 0: warm-up
                    t_e2e[name] += time.perf_counter() - t
    for g in gens:
        g.close()
    for name in names:
        rows.append((f"end to end, {name} (shards)", m, t_e2e[name]))
    base = names[0]
    lines = []
    for name in names[1:]:
        cpu = (t_mem[name] - parts[name]["GL"]) / (t_mem[base] - parts[base]["GL"])
        lines.append(f"{name} / person only: end to end {t_e2e[name] / t_e2e[base]:.2f}x, in "
                     f"memory {t_mem[name] / t_mem[base]:.2f}x, in memory without GL "
                     f"{cpu:.2f}x")
    full = names[1::2]
    for a, b in zip(full[:-1], full[1:], strict=True):
        lines.append(f"{b} / {a}: end to end {t_e2e[b] / t_e2e[a]:.2f}x, in memory "
                     f"{t_mem[b] / t_mem[a]:.2f}x (target for cluttered_room / living_room: "
                     f"<= 1.5x)")
    return lines


def background_rows(bg_path, scene_path, backend, num_frames, asset_dir
                    ) -> tuple[list[tuple[str, int, float]], list[str]]:
    """Rows of the real-background config ``bg_path``: each background file read in parts
    (once per job), then its frames beside ``scene_path``'s, interleaved in one process
    (after a warm-up shard, frame i of each plan, cycled), per part, in memory and end
    to end (shards written as a worker writes them). Returns the rows and summary lines
    (ratios to the scene config's frame, the job's memory per background)."""
    import vhgen.pipeline.frames as frames_mod
    from vhgen.depthfile import depth_files, read_depth
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job
    from vhgen.render.context import create_context
    from vhgen.scene.background.floor import estimate_floor, free_floor
    from vhgen.store.zarr_store import create_store

    bg_cfg = JobConfig.load(bg_path, backend=backend)
    scene_cfg = JobConfig.load(scene_path, backend=backend)
    rows: list[tuple[str, int, float]] = []
    files = depth_files([b.path for b in bg_cfg.scene.backgrounds])
    t = [0.0, 0.0, 0.0]
    for f in files:
        t0 = time.perf_counter()
        frame = read_depth(f)
        t1 = time.perf_counter()
        floor = estimate_floor(frame.depth_mm, bg_cfg.sensor.intrinsics)
        t2 = time.perf_counter()
        free_floor(frame.depth_mm, bg_cfg.sensor.intrinsics, floor)
        t3 = time.perf_counter()
        t = [t[0] + t1 - t0, t[1] + t2 - t1, t[2] + t3 - t2]
    n = len(files)
    rows.append(("background read: decode (per file)", n, t[0]))
    rows.append(("background read: floor RANSAC (per file)", n, t[1]))
    rows.append(("background read: free floor (per file)", n, t[2]))

    k = min(c.frames_per_shard for c in (bg_cfg, scene_cfg))
    shards = max(2, num_frames // k)
    total = (shards + 1) * k
    jobs = [prepare_job(c, asset_dir=asset_dir) for c in (scene_cfg, bg_cfg)]
    bgs = jobs[1].backgrounds
    assert bgs is not None
    ctx = create_context(bg_cfg.backend)
    gens = [FrameGenerator(_cycled(j, total), context=ctx) for j in jobs]
    parts = [{"describe": 0.0, "render": 0.0, "sensor": 0.0} for _ in gens]

    def timed(fn, j, part):
        def call(*a, **kw):
            t0 = time.perf_counter()
            out = fn(*a, **kw)
            parts[j][part] += time.perf_counter() - t0
            return out
        return call

    for j, g in enumerate(gens):
        for a in range(len(g.job.plan.avatars)):
            g.scene._resident([a])
        for f in range(k):  # warm-up: kernels, the background textures
            g.render_frame(f)
        g.describer.describe = timed(g.describer.describe, j, "describe")
        g.scene.render = timed(g.scene.render, j, "render")
    gens[0].sensor.simulate = timed(gens[0].sensor.simulate, 0, "sensor")
    over_real = frames_mod.simulate_over_real
    frames_mod.simulate_over_real = timed(over_real, 1, "sensor")  # type: ignore[assignment]
    t_mem = [0.0, 0.0]
    people = 0
    try:
        for f in range(k, total):
            for j, g in enumerate(gens):
                t0 = time.perf_counter()
                out = g.render_frame(f)
                t_mem[j] += time.perf_counter() - t0
                people += out.record.num_people if j == 1 else 0
        mem_parts = [dict(p) for p in parts]
        t_e2e = [0.0, 0.0]
        with tempfile.TemporaryDirectory() as tmp:
            stores = []
            for j, g in enumerate(gens):
                c = g.cfg
                stores.append(str(Path(tmp) / f"b{j}.zarr"))
                create_store(stores[-1], num_frames=total, height=c.sensor.intrinsics.height,
                             width=c.sensor.intrinsics.width, frames_per_shard=k,
                             compression_level=c.compression_level, attrs={},
                             arrays=c.arrays)
            for sh in range(shards + 1):
                for j, g in enumerate(gens):
                    t0 = time.perf_counter()
                    g.run_task(stores[j], sh, sh * k, sh * k + k)
                    if sh > 0:
                        t_e2e[j] += time.perf_counter() - t0
    finally:
        frames_mod.simulate_over_real = over_real  # type: ignore[assignment]
        for g in gens:
            g.close()
        ctx.release()
    m = total - k
    names = [scene_cfg.name, f"{bg_cfg.name} ({people / m:.2f} people)"]
    for j, name in enumerate(names):
        rest = t_mem[j] - sum(mem_parts[j].values())
        rows.append((f"frame, {name} (interleaved)", m, t_mem[j]))
        rows.append(("  describe + placement", m, mem_parts[j]["describe"]))
        rows.append(("  GL draw" + (" + composite" if j else ""), m, mem_parts[j]["render"]))
        rows.append(("  sensor" + (" (2 passes + composition)" if j else ""), m,
                     mem_parts[j]["sensor"]))
        rows.append(("  record, rest", m, rest))
        rows.append((f"end to end, {name} (shards)", m, t_e2e[j]))
    per_bg = (bgs.depth_mm.nbytes + bgs.clearance.nbytes) / len(bgs) / 1e6
    notes = [f"{bg_cfg.name} frame / {scene_cfg.name} frame: {t_mem[1] / t_mem[0]:.2f}x in "
             f"memory, {t_e2e[1] / t_e2e[0]:.2f}x end to end; sensor "
             f"{mem_parts[1]['sensor'] / mem_parts[0]['sensor']:.2f}x",
             f"a job holds {per_bg:.2f} MB per background (depth uint16 + free-floor grid "
             "uint8), one array each: mapped by local workers, shared by Ray's object store"]
    return rows, notes


def _time_part(obj, attr: str, parts: dict, current: list, part: str) -> None:
    """Wrap ``obj.attr`` so that its seconds add to ``parts[current[0]][part]``."""
    fn = getattr(obj, attr)

    def timed(*a, **kw):
        t = time.perf_counter()
        try:
            return fn(*a, **kw)
        finally:
            parts[current[0]][part] += time.perf_counter() - t
    setattr(obj, attr, timed)


def _scene_job_rows(cfg, scene_paths, backend, num_frames, rows) -> list[str]:
    """Each config run as jobs (local workers, each config's worker count, its first
    ``num_frames`` frames, with ``poses.frame_step`` 2 so that the builtin motion gives
    enough of them), twice, interleaved: rows of the steady seconds per frame of one
    worker (the median over its shards: render, sensor and write, with every worker of
    the job busy) and their ratios, scene over person-only."""
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    cfgs = [cfg] + [JobConfig.load(p, backend=backend) for p in scene_paths]
    steady = [0.0] * len(cfgs)
    frames = [0] * len(cfgs)
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(2):
            for j, c in enumerate(cfgs):
                c = replace(c, poses=replace(c.poses, frame_step=min(c.poses.frame_step, 2)))
                s = run_job(c, Path(tmp) / f"job{rep}{j}.zarr", max_frames=num_frames,
                            executor="local", progress=False)
                steady[j] += s.steady_seconds_per_frame * s.frames
                frames[j] += s.frames
    lines = []
    for j, c in enumerate(cfgs):
        who = "person only" if j == 0 else c.name
        rows.append((f"job, {who}, per worker (x{c.num_workers})", frames[j], steady[j]))
        if j:
            lines.append(f"{c.name} / person only, as jobs run them (steady time per frame "
                         f"of a worker, all workers busy): "
                         f"{(steady[j] / frames[j]) / (steady[0] / frames[0]):.2f}x")
    return lines


def fixed_cost(cfg, steps, executors=("local", "ray")) -> list[tuple[str, int, float]]:
    """Rows per executor (local worker processes, Ray actors): the two timed jobs, the
    steady time per frame and the fixed cost (intercept), run one after the other."""
    import inspect

    import vhgen
    from vhgen.pipeline.driver import run_job

    where = Path(vhgen.__file__).resolve().parent.parent.name
    has_executor = "executor" in inspect.signature(run_job).parameters
    rows = []
    for ex in executors if has_executor else ("ray",):  # an older checkout: Ray only
        runs = []
        for step in steps:
            c = replace(cfg, poses=replace(cfg.poses, frame_step=step))
            kw = {"executor": ex} if has_executor else {}
            with tempfile.TemporaryDirectory() as tmp:
                t = time.perf_counter()
                summary = run_job(c, Path(tmp) / "fixed.zarr", **kw)
                runs.append((summary.frames, time.perf_counter() - t))
                rows.append((f"{ex}: fixed cost in-run, {summary.frames} frames", 1,
                             summary.fixed_seconds))
                for k in ("ray_init_seconds", "first_shard_seconds", "tail_seconds"):
                    if getattr(summary, k):
                        rows.append((f"  {k.replace('_seconds', '')}", 1, getattr(summary, k)))
        (n1, t1), (n2, t2) = runs
        per_frame = (t2 - t1) / (n2 - n1)
        rows += [(f"{ex}: job, {n1} frames ({where})", n1, t1),
                 (f"{ex}: job, {n2} frames ({where})", n2, t2),
                 (f"{ex}: steady time per frame ({where})", 1, per_frame),
                 (f"{ex}: fixed cost = T(0) ({where})", 1, t1 - n1 * per_frame)]
    return rows


def print_rows(rows, title: str) -> None:
    print(f"\n{title}")
    print(f"{'stage':42s} {'items':>7s} {'seconds':>9s} {'items/s':>10s} {'ms/item':>9s}")
    for name, count, sec in rows:
        print(f"{name:42s} {count:7d} {sec:9.3f} {count / max(sec, 1e-9):10.1f} "
              f"{1000 * sec / count:9.2f}")


if __name__ == "__main__":
    main()
