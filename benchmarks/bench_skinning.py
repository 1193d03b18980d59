"""Skinning accuracy and avatar cost.

    .venv/bin/python benchmarks/bench_skinning.py [--shared ../shared/mocap/cmu] [--step 1]

1. GPU (float32 vertex shader, read back by transform feedback) against the float64
   NumPy reference, every ``--step``-th pose of every file in the shared corpus, LBS and
   dual-quaternion skinning: the maximum vertex deviation in mm (goal: < 0.1 mm).
2. What DQS changes against LBS at twisted wrists and at shoulders (vertices labelled
   wrist / shoulder in shotton31): displacement percentiles over all poses, and the
   forearm-to-hand twist of the worst pose.
3. Cost of a new avatar: MakeHuman macro targets + rig + weights + labels (build_body),
   and its upload to the GPU.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    from vhgen.assets import resolve_asset_dir
    from vhgen.body.avatar import build_body
    from vhgen.body.labels import LabelScheme
    from vhgen.body.shape import ShapeSampler
    from vhgen.body.skinning import bone_matrices, skin_vertices, skin_vertices_dqs
    from vhgen.mocap.bvh import read_bvh
    from vhgen.mocap.clips import expand_motion_paths
    from vhgen.mocap.retarget import build_retargeter, detect_dialect, load_all_maps
    from vhgen.render.context import create_context
    from vhgen.render.renderer import DepthLabelRenderer, GPUSkinner
    from vhgen.rotations import geodesic_angle

    ap = argparse.ArgumentParser()
    ap.add_argument("--shared", default=str(REPO.parent / "shared" / "mocap" / "cmu"))
    ap.add_argument("--step", type=int, default=1, help="every n-th frame of each file")
    ap.add_argument("--backend", default="egl")
    args = ap.parse_args()

    asset_dir = resolve_asset_dir()
    scheme = LabelScheme.load("shotton31")
    body = build_body(asset_dir, scheme)
    ctx = create_context(args.backend)
    gpu = {m: GPUSkinner(ctx, body.vertices, body.joints, body.weights, body.num_bones, m)
           for m in ("lbs", "dqs")}
    ref = {"lbs": skin_vertices, "dqs": skin_vertices_dqs}
    maps = load_all_maps()
    face_vertices = {}
    for name in ("L_wrist", "R_wrist", "L_shoulder", "R_shoulder"):
        k = scheme.names.index(name) + 1
        face_vertices[name] = np.unique(body.faces[body.face_labels == k])
    wrist = np.concatenate([face_vertices["L_wrist"], face_vertices["R_wrist"]])
    shoulder = np.concatenate([face_vertices["L_shoulder"], face_vertices["R_shoulder"]])
    hand = body.rig.index("LeftHand"), body.rig.index("LeftForeArm")

    worst = {"lbs": 0.0, "dqs": 0.0}
    d_wrist, d_shoulder, twist = [], [], []
    n_poses = 0
    t0 = time.perf_counter()
    for _, path in expand_motion_paths([args.shared]):
        m = read_bvh(path)
        rt = build_retargeter(m, body.rig, detect_dialect(m, maps))
        frames = np.arange(0, m.num_frames, args.step)
        rot, root = rt.apply(m, frames=frames)
        for f in range(len(frames)):
            mats = bone_matrices(body.rig, rot[f], root[f])
            pos = {}
            for mode in ("lbs", "dqs"):
                pos[mode] = ref[mode](body.vertices, body.joints, body.weights, mats)
                dev = np.abs(gpu[mode].positions(mats) - pos[mode]).max()
                worst[mode] = max(worst[mode], float(dev))
            diff = np.linalg.norm(pos["lbs"] - pos["dqs"], axis=1)
            d_wrist.append(diff[wrist].max())
            d_shoulder.append(diff[shoulder].max())
            twist.append(geodesic_angle(rot[f, hand[1]], rot[f, hand[0]]))
            n_poses += 1
    t_all = time.perf_counter() - t0
    d_wrist, d_shoulder, twist = map(np.asarray, (d_wrist, d_shoulder, twist))

    sampler = ShapeSampler(age_years=(5, 90))
    rng = np.random.default_rng(0)
    ren = DepthLabelRenderer(ctx, __import__("vhgen").Intrinsics(640, 480, 571.26, 571.26,
                                                                 319.5, 239.5))
    t_build, t_upload = [], []
    for _ in range(10):
        shape = sampler.sample(rng)
        t = time.perf_counter()
        b = build_body(asset_dir, scheme, shape=shape)
        t_build.append(time.perf_counter() - t)
        t = time.perf_counter()
        ren.set_mesh(b.vertices, b.faces, b.joints, b.weights, b.face_labels, b.num_bones)
        t_upload.append(time.perf_counter() - t)

    print(f"\nskinning on {ctx.info['GL_RENDERER']}: {n_poses} poses of {args.shared} "
          f"(every {args.step}. frame), {len(body.vertices)} vertices, {t_all:.0f} s")
    print(f"{'measure':52s} {'value':>12s}")
    print(f"{'GPU vs float64 reference, LBS, max deviation (mm)':52s} {worst['lbs'] * 1e3:12.5f}")
    print(f"{'GPU vs float64 reference, DQS, max deviation (mm)':52s} {worst['dqs'] * 1e3:12.5f}")
    for name, d in (("wrists", d_wrist), ("shoulders", d_shoulder)):
        for q in (50, 99, 100):
            label = f"DQS vs LBS at {name}, p{q} over poses of max (mm)"
            print(f"{label:52s} {np.percentile(d, q) * 1e3:12.2f}")
    k = int(np.argmax(d_wrist))
    print(f"{'left forearm-to-hand rotation at the worst wrist (deg)':52s} "
          f"{np.rad2deg(twist[k]):12.1f}")
    print(f"{'new avatar: build_body with macro targets (ms)':52s} "
          f"{np.median(t_build) * 1e3:12.1f}")
    print(f"{'new avatar: GPU upload (ms)':52s} {np.median(t_upload) * 1e3:12.1f}")


if __name__ == "__main__":
    main()
