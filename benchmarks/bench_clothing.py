"""What clothes cost: GL time per frame of a clothed person against the same person bare,
per item and for whole outfits, side by side in one run; and the CPU cost of dressing an
avatar (once per avatar).

    .venv/bin/python benchmarks/bench_clothing.py [--frames 40] [--backend egl]

One llvmpipe thread and one thread per math library, as in a worker. Every body is
uploaded once; each frame draws every body in the same pose from the same camera (a
Kinect v1 at 640x480, 2.6 m in front, 1.2 m high), interleaved in a random order, and
times the draw with its read-back (what the render step does per person): the fastest of
``--repeat`` draws, as this machine is shared. Rows: the median over frames of those GL
milliseconds, the ratio to the bare body (per frame against the bare draw of the same
frame, median over frames; target: at most 1.3; "bare, again" shows the noise), the
triangles the renderer is given (+ the share added), and the median milliseconds of
building the avatar on the CPU (shape, rig, weights, labels and the outfit). "typical" is the mean
over avatars dressed from the default wardrobe (``avatars: {outfit: {}}``).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def _mid(item: str, kind: str) -> dict:
    from vhgen.body.wardrobe import KINDS, Chance

    d: dict = {"kind": kind}
    for name, p in KINDS[item][kind].items():
        if isinstance(p, Chance):
            d["side" if name == "left" else name] = "left" if name == "left" else True
        else:
            d[name] = (p.lo + p.hi) / 2
    if item == "carried":
        d.update(as_person=False, **{"class": 5})
    return d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--backend", choices=["egl", "osmesa"], default="egl")
    ap.add_argument("--typical", type=int, default=8, help="avatars of the default wardrobe")
    ap.add_argument("--repeat", type=int, default=3,
                    help="draws per body and frame; the fastest counts (a shared machine)")
    args = ap.parse_args()
    from vhgen.executor.local import worker_env

    os.environ.update(worker_env())

    from vhgen.assets import resolve_asset_dir
    from vhgen.body.avatar import AvatarParams, build_avatar, build_body
    from vhgen.body.labels import LabelScheme
    from vhgen.body.shape import Shape
    from vhgen.body.skinning import bone_matrices
    from vhgen.body.wardrobe import KINDS, Outfit, default_outfit_config
    from vhgen.camera import look_at
    from vhgen.job_config import AvatarConfig, PosesConfig
    from vhgen.mocap.clips import BUILTIN_MOTION
    from vhgen.mocap.retarget import load_all_maps
    from vhgen.pipeline.plan import avatar_params
    from vhgen.pipeline.poses import load_poses
    from vhgen.render.context import create_context
    from vhgen.render.renderer import DepthLabelRenderer, Draw
    from vhgen.render.scene_renderer import upload_body
    from vhgen.scene.geometry import PERSON
    from vhgen.sensor.sensor_config import SensorConfig

    asset_dir = resolve_asset_dir()
    scheme = LabelScheme.load("shotton31")
    shape = Shape()
    bare = build_body(asset_dir, scheme, shape=shape)
    poses = load_poses([BUILTIN_MOTION], bare.rig, load_all_maps(), PosesConfig(frame_step=4))
    pick = np.linspace(0, poses.num_poses - 1, args.frames).astype(int)

    # "bare, again": a second upload of the bare body, the noise floor of the ratios
    outfits: list[tuple[str, dict | None]] = [("bare", None), ("bare, again", None)]
    outfits += [(f"{item} {kind}", {item: _mid(item, kind)}) for item in KINDS
                for kind in KINDS[item]]
    for name, o in outfits:  # a dress is a top and a skirt
        if name == "top dress":
            o["bottom"] = _mid("bottom", "skirt")
    outfits.append(("coat, hood, jumper, skirt, boots, long hair, backpack", {
        "top": _mid("top", "jumper"), "outer": _mid("outer", "coat"),
        "bottom": _mid("bottom", "skirt"), "shoes": _mid("shoes", "boots"),
        "hair": _mid("hair", "long"), "carried": _mid("carried", "backpack")}))
    wardrobe = AvatarConfig(count=args.typical, outfit=default_outfit_config().with_class(5))
    typical = [avatar_params(1, a, wardrobe).outfit for a in range(args.typical)]

    def build(outfit: Outfit | dict | None):
        if isinstance(outfit, dict):
            outfit = Outfit.from_dict(outfit)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            body = build_avatar(asset_dir, scheme, AvatarParams(shape, 1.0, (), outfit))
            times.append(time.perf_counter() - t0)
        return body, 1e3 * float(np.median(times))

    bodies = [(name, *build(o)) for name, o in outfits]
    bodies += [(f"typical {k}", *build(o)) for k, o in enumerate(typical)]
    ctx = create_context(args.backend)
    intr = SensorConfig.load("kinect_v1_full").intrinsics
    ren = DepthLabelRenderer(ctx, intr)
    meshes = [upload_body(ren, b) for _, b, _ in bodies]
    w2c = look_at(np.array([0.0, 1.2, 2.6]), np.array([0.0, 0.95, 0.0]))
    ms = np.zeros((len(pick), len(bodies)))
    for _ in range(2):  # warm up every program and mesh
        for m in meshes:
            ren.draw([Draw(m, w2c @ bone_matrices(bare.rig, poses.rotations[0],
                                                  poses.roots[0]), 1, PERSON)])
    for i, p in enumerate(pick):
        root = poses.roots[p] - [poses.roots[p][0], 0.0, poses.roots[p][2]]
        bones = w2c @ bone_matrices(bare.rig, poses.rotations[p], root)
        order = np.random.default_rng(i).permutation(len(meshes))  # no position bias
        for k in order:
            best = np.inf
            for _ in range(args.repeat):  # the least disturbed of a few draws
                t0 = time.perf_counter()
                ren.draw([Draw(meshes[k], bones, 1, PERSON)])
                best = min(best, time.perf_counter() - t0)
            ms[i, k] = 1e3 * best
    for m in meshes:
        m.release()
    ren.release()
    gl = np.median(ms, axis=0)
    # each frame's draw against the bare body's draw of the same frame (slow changes of
    # the machine's load cancel), median over frames
    ratio = np.median(ms / ms[:, :1], axis=0)
    tri0 = len(bodies[0][1].faces)
    print(f"vhgen clothing cost: {args.frames} frames of {BUILTIN_MOTION}, {intr.width}x"
          f"{intr.height}, {args.backend} ({ctx.info.get('GL_RENDERER', '?')}), "
          f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS')}")
    print(f"{'outfit':58s} {'GL ms':>7s} {'x bare':>7s} {'triangles':>10s} {'build ms':>9s}")
    rows = list(range(len(outfits)))
    for k in rows:
        name, body, build_ms = bodies[k]
        added = (len(body.faces) - tri0) / tri0
        print(f"{name:58s} {gl[k]:7.2f} {ratio[k]:7.2f} {len(body.faces):7d} "
              f"{'+' if added >= 0 else ''}{100 * added:3.0f}% {build_ms:8.0f}")
    t = np.arange(len(outfits), len(bodies))
    tris = np.mean([len(bodies[k][1].faces) for k in t])
    label = f"typical (default wardrobe, mean of {len(t)} avatars)"
    print(f"{label:58s} "
          f"{gl[t].mean():7.2f} {ratio[t].mean():7.2f} {tris:7.0f} "
          f"+{100 * (tris - tri0) / tri0:3.0f}% {np.mean([bodies[k][2] for k in t]):8.0f}")
    print(f"{'typical, worst avatar':58s} {gl[t][np.argmax(ratio[t])]:7.2f} "
          f"{ratio[t].max():7.2f}")


if __name__ == "__main__":
    main()
