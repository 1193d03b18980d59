"""The scene description of a frame with placement compiled and with its NumPy reference.

    python benchmarks/bench_placement.py [--config cluttered_room] [--motions ../shared/mocap/cmu]
        [--frames 128] [--repeat 3] [--layout-frames N]

Describes the same ``--frames`` frames of a scene config (``FrameDescriber.describe``: the
camera, the room, the people posed and placed, props and clutter; no GL) in one process,
three ways taking turns for ``--repeat`` passes:

* ``compiled``: what vhgen runs (clutter candidates and their screening in
  :mod:`vhgen.scene.clutter.place_kernels`, people kept in view by
  :func:`vhgen.scene.placement.all_visible`, and in a shared layout by
  :func:`vhgen.scene.solids.visible_fraction_compiled`);
* ``numpy clutter``: the clutter's NumPy references (``_candidates_reference``,
  ``_first_fit_reference``), people as compiled;
* ``numpy``: every reference (people by ``visible_fraction``, as before 2026-11-29, and
  in a shared layout by ``visible_fraction_with``, as before 2026-11-30).

``--layout-frames N`` sets ``scene.layout_frames`` (frames sharing a room, props and
clutter, as a GPU node runs them: 16 there).

All three describe the same frames (checked: the same clutter, props and people placed).
A pass over the frames first fills the worker's clutter library and compiles the kernels.
Prints ms per frame of the whole description and of clutter placement (median over the
passes, and the least), and each way's ratio to ``numpy``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any


def _reference_visibility() -> Callable[..., bool]:
    """placement.all_visible as the NumPy reference computes it."""
    from vhgen.scene.placement import visible_fraction

    def all_visible(eye, discs, targets, min_visible, samples=64):  # type: ignore[no-untyped-def]
        return all(visible_fraction(eye, t, [o for o in discs if o is not t], samples)
                   >= min_visible for t in discs[:targets])
    return all_visible


@contextmanager
def _way(name: str) -> Iterator[None]:
    import vhgen.scene.background.people as bg_people
    import vhgen.scene.clutter.place as place
    import vhgen.scene.layout as layout
    from vhgen.scene.solids import visible_fraction_with

    saved = (place._candidates, place._first_fit, layout.all_visible, bg_people.all_visible,
             layout.visible_fraction_compiled)
    try:
        if name != "compiled":
            place._candidates = place._candidates_reference
            place._first_fit = place._first_fit_reference
        if name == "numpy":
            layout.all_visible = bg_people.all_visible = _reference_visibility()
            layout.visible_fraction_compiled = visible_fraction_with  # type: ignore[assignment]
        yield
    finally:
        (place._candidates, place._first_fit, layout.all_visible,
         bg_people.all_visible, layout.visible_fraction_compiled) = saved


def _layout(desc: Any) -> tuple:
    """What placement decided in a frame: people's spots, props, clutter transforms."""
    return (tuple((p.avatar_id, p.pose_index, tuple(p.placement.reshape(-1)))
                  for p in desc.people),
            tuple(repr(p.to_dict()) for p in desc.props),
            tuple(repr(c.to_dict()) for c in desc.clutter))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default="cluttered_room",
                    help="scene config: a shipped name or a YAML path")
    ap.add_argument("--motions", nargs="+", help="BVH files or folders instead of the "
                    "config's motions (e.g. ../shared/mocap/cmu)")
    ap.add_argument("--frames", type=int, default=128)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--layout-frames", type=int, default=0,
                    help="scene.layout_frames (default: the config's)")
    args = ap.parse_args()

    import vhgen.scene.layout as layout
    from vhgen.errors import VhgenError
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.describe import FrameDescriber
    from vhgen.pipeline.job import prepare_job

    try:
        cfg = JobConfig.load(args.config)
        if args.motions:
            cfg = replace(cfg, motions=tuple(str(Path(m).resolve()) for m in args.motions))
        if args.layout_frames:
            cfg = replace(cfg, scene=replace(cfg.scene, layout_frames=args.layout_frames))
        job = prepare_job(cfg)
    except VhgenError as e:
        sys.exit(f"bench_placement: {e}")
    if cfg.scene.clutter is None:
        sys.exit(f"bench_placement: {args.config} places no clutter (scene.clutter)")
    describer = FrameDescriber(job)
    frames = range(min(args.frames, job.plan.num_frames))

    spent = [0.0]
    place_clutter = layout.place_clutter

    def timed(*a: Any, **k: Any) -> Any:
        t = time.perf_counter()
        try:
            return place_clutter(*a, **k)
        finally:
            spent[0] += time.perf_counter() - t

    layout.place_clutter = timed
    ways = ("compiled", "numpy clutter", "numpy")
    layouts: dict[str, list[tuple]] = {}
    for name in ways:  # fills the clutter library, compiles, records what each places
        with _way(name):
            layouts[name] = [_layout(describer.describe(f)) for f in frames]
    same = all(layouts[w] == layouts["numpy"] for w in ways)
    times: dict[str, list[tuple[float, float]]] = {w: [] for w in ways}
    for _ in range(args.repeat):
        for name in ways:
            with _way(name):
                spent[0] = 0.0
                t = time.perf_counter()
                for f in frames:
                    describer.describe(f)
                n = len(frames)
                times[name].append((1e3 * (time.perf_counter() - t) / n, 1e3 * spent[0] / n))

    print(f"{args.config}: {len(frames)} frames, layout_frames {cfg.scene.layout_frames}, "
          f"{args.repeat} passes each, in turns; "
          f"the same layouts all three ways: {'yes' if same else 'NO'}")
    print("| placement | describe, ms/frame (median / least) | of which clutter | "
          "describe x numpy |")
    print("|---|---|---|---|")
    base = statistics.median(d for d, _ in times["numpy"])
    for name in ways:
        d = [a for a, _ in times[name]]
        c = [b for _, b in times[name]]
        print(f"| {name} | {statistics.median(d):.2f} / {min(d):.2f} | "
              f"{statistics.median(c):.2f} / {min(c):.2f} | {statistics.median(d) / base:.2f} |")
    if not same:
        sys.exit(1)


if __name__ == "__main__":
    main()
