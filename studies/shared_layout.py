"""What frames sharing a layout (``scene.layout_frames``) cost and change in a scene's
description: for each N, the same frames of one config described with layouts of N
frames, interleaved in one process.

    python studies/shared_layout.py [--config configs/scenes/cluttered_room.yaml]
        [--motions ../shared/mocap/cmu] [--frames 400] [--layout-frames 1,4,16]

Per N: the time to describe a frame (after one warm-up frame; bodies and the clutter
library built before timing), people per frame and those left out, clutter items and
props per frame, and the share of frames that keep their layout's static meshes as they
are (the render step then writes nothing to the GPU). Nothing is chosen here
(docs/scenes.md, "Frames that share a layout").
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main() -> None:
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.describe import FrameDescriber
    from vhgen.pipeline.job import prepare_job

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default="configs/scenes/cluttered_room.yaml")
    ap.add_argument("--motions", default=None, help="BVH folder in place of the config's")
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--layout-frames", default="1,4,16")
    args = ap.parse_args()
    cfg = JobConfig.load(args.config)
    if args.motions:
        cfg = replace(cfg, motions=(args.motions,))
    ns = [int(v) for v in args.layout_frames.split(",")]
    job = prepare_job(cfg)
    frames = min(args.frames, job.plan.num_frames)
    describers = {}
    for n in ns:
        sub = replace(job, cfg=replace(cfg, scene=replace(cfg.scene, layout_frames=n)))
        d = describers[n] = FrameDescriber(sub)
        d.describe(0)  # bodies, clutter library
    stats = {n: {"s": 0.0, "people": 0, "left": 0, "clutter": 0, "props": 0, "kept": 0}
             for n in ns}
    for f in range(frames):
        for n in ns:  # interleaved: the machine's load falls on every N alike
            d = describers[n]
            t = time.perf_counter()
            desc = d.describe(f)
            st = stats[n]
            st["s"] += time.perf_counter() - t
            st["people"] += len(desc.people)
            st["left"] += desc.dropped.get("people", 0)
            st["clutter"] += len(desc.clutter)
            st["props"] += len(desc.props)
            if n > 1:
                st["kept"] += desc.static is d.shared_layout(f // n).layout.static
    print(f"{cfg.name}: {frames} frames, motions {', '.join(cfg.motions)}")
    print("| layout_frames | describe ms a frame | people a frame | left out | clutter items "
          "| props | frames keeping the layout's meshes |")
    print("|---|---|---|---|---|---|---|")
    for n in ns:
        st = stats[n]
        kept = f"{st['kept'] / frames:.3f}" if n > 1 else "-"
        print(f"| {n} | {1000 * st['s'] / frames:.2f} | {st['people'] / frames:.3f} | "
              f"{st['left'] / frames:.3f} | {st['clutter'] / frames:.2f} | "
              f"{st['props'] / frames:.2f} | {kept} |")


if __name__ == "__main__":
    main()
