"""Sparsification: the indexed greedy against the naive greedy loop, side by side.

    .venv/bin/python benchmarks/bench_sparsify.py [--shared ../shared/mocap/cmu]
        [--synthetic 1000000] [--naive-sample 20000]

1. The whole shared corpus (retargeted onto the MakeHuman rig, heading removed, fingers
   excluded: what `vhgen corpus build` sparsifies) at 5 and 10 degrees, and the position
   metric at 5 cm: both algorithms, identical kept sets asserted, speed ratio.
2. A synthetic corpus of N poses x 31 joints (1000-frame clips at 120 fps; every joint a
   sum of three sinusoids with random amplitude up to 60 deg and 0.1-1.5 Hz) at 5 degrees:
   the indexed greedy on all of it; the naive loop on the first ``--naive-sample`` poses
   (it is quadratic), where equality is asserted too.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def shared_features(shared: Path):
    from vhgen.assets import resolve_asset_dir
    from vhgen.body.skinning import posed_heads
    from vhgen.mocap import corpus
    from vhgen.mocap.clips import expand_motion_paths
    from vhgen.mocap.retarget import world_rotations
    from vhgen.mocap.sparsify import remove_heading

    corpus._init_worker(str(resolve_asset_dir()), None, None)
    rig = corpus._WORKER["rig"]
    t = time.perf_counter()
    res = [corpus._process_file(n, str(p), 1) for n, p in expand_motion_paths([str(shared)])]
    t_read = time.perf_counter() - t
    local = np.concatenate([loc for _, loc in res if loc is not None])
    keep = [k for k, b in enumerate(rig.names) if b not in corpus.DEFAULT_EXCLUDE]
    feats = local.copy()
    feats[:, 0] = remove_heading(feats[:, 0])
    world = world_rotations(rig, local)
    world = (remove_heading(world[:, 0]) @ np.swapaxes(world[:, 0], -1, -2))[:, None] @ world
    pos = posed_heads(rig, world, np.zeros((len(world), 3)))
    return feats[:, keep], pos[:, keep], len(res), t_read


def synthetic(n: int, joints: int = 31, clip: int = 1000, seed: int = 0) -> np.ndarray:
    from vhgen.rotations import euler_to_matrix

    rng = np.random.default_rng(seed)
    out = np.empty((n, joints, 3, 3))
    t = np.arange(clip) / 120.0
    for s in range(0, n, clip):
        k = min(clip, n - s)
        amp = np.deg2rad(rng.uniform(0, 60, size=(3, joints, 3))) / 3
        freq = rng.uniform(0.1, 1.5, size=(3, joints, 3))
        phase = rng.uniform(0, 2 * np.pi, size=(3, joints, 3))
        ang = np.zeros((k, joints, 3))
        for h in range(3):
            ang += amp[h] * np.sin(2 * np.pi * freq[h] * t[:k, None, None] + phase[h])
        out[s:s + k] = euler_to_matrix(ang, "ZYX")
    return out


def timed(fn, *a, **kw):
    t = time.perf_counter()
    r = fn(*a, **kw)
    return r, time.perf_counter() - t


def main() -> None:
    from vhgen.mocap.sparsify import sparsify, sparsify_naive

    ap = argparse.ArgumentParser()
    ap.add_argument("--shared", default=str(REPO.parent / "shared" / "mocap" / "cmu"))
    ap.add_argument("--synthetic", type=int, default=1_000_000)
    ap.add_argument("--naive-sample", type=int, default=20_000)
    args = ap.parse_args()

    rows = []
    # the exact tests are compiled (numba): load them once, outside every timing
    _, t_jit = timed(sparsify, synthetic(50, joints=3), np.deg2rad(5))
    _, t_jit2 = timed(sparsify, np.zeros((5, 3, 3)), 0.05, "position")
    print(f"one-time kernel compile/load: {t_jit + t_jit2:.2f} s")
    rot, pos, nfiles, t_read = shared_features(Path(args.shared))
    print(f"shared corpus: {nfiles} files, {len(rot)} poses, {rot.shape[1]} joints; "
          f"parse+FK+retarget {t_read:.2f} s on one core")
    cases = [("shared, angle 5 deg", rot, np.deg2rad(5), "angle"),
             ("shared, angle 10 deg", rot, np.deg2rad(10), "angle"),
             ("shared, position 5 cm", pos, 0.05, "position")]
    for name, x, th, metric in cases:
        fast, tf = timed(sparsify, x, th, metric)
        naive, tn = timed(sparsify_naive, x, th, metric)
        assert np.array_equal(fast, naive), name
        rows.append((name, len(x), len(fast), tf, tn))

    syn, t_gen = timed(synthetic, args.synthetic)
    m = min(args.naive_sample, len(syn))
    fast, tf = timed(sparsify, syn[:m], np.deg2rad(5))
    naive, tn = timed(sparsify_naive, syn[:m], np.deg2rad(5))
    assert np.array_equal(fast, naive)
    rows.append((f"synthetic first {m}, 5 deg", m, len(fast), tf, tn))
    fast, tf = timed(sparsify, syn, np.deg2rad(5))
    rows.append((f"synthetic {len(syn)}, 5 deg", len(syn), len(fast), tf, float("nan")))

    print(f"\n{'case':32s} {'poses':>9s} {'kept':>8s} {'indexed s':>10s} {'naive s':>9s} "
          f"{'speed-up':>9s}")
    for name, n, k, tf, tn in rows:
        print(f"{name:32s} {n:9d} {k:8d} {tf:10.2f} {tn:9.2f} {tn / tf:9.1f}x")
    print("identical kept sets asserted wherever the naive loop ran")


if __name__ == "__main__":
    main()
