"""``vhgen forest ...``: train, eval, label, export (registered by vhgen.cli).

The learning-curve study is ``python studies/forest_curves.py`` (it generates frames).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

from vhgen import cliargs as A
from vhgen.errors import ConfigError, ForestError


def _warn(msg: str) -> None:
    print(f"vhgen: warning: {msg}", file=sys.stderr)


def _note(msg: str) -> None:
    print(f"vhgen: note: {msg}", file=sys.stderr)


def _progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def load_any_forest(path: str) -> Any:
    """A vhgen forest file, or a PCL tree file / directory of them (their training focal
    length unknown: PCL's files do not record it)."""
    from vhgen.forest.pcl import load_pcl_forest
    from vhgen.forest.trees import Forest

    p = Path(path)
    if p.is_dir() or p.suffix == ".txt":
        return load_pcl_forest(p)
    forest = Forest.load(p)
    stage = forest.person_stage
    if stage is not None:
        from vhgen.forest.segment import FEATURES

        unknown = [f for f in stage.features if f not in FEATURES]
        if unknown:
            _warn(f"{p}: its person stage reads candidate features this version does not "
                  f"compute ({', '.join(unknown)}); --segment decides by the forest's vote "
                  "(train the stage again: forest person-stage)")
            forest.person_stage = None
    return forest


def check_focal(forest: Any, fx: float | None, where: str) -> None:
    """Say (once per call) when the frames' focal length differs from the training one:
    the forest's probes are then scaled to it (:func:`vhgen.forest.trees.at_focal`)."""
    from vhgen.forest.trees import FOCAL_TOLERANCE_PX

    train_fx = forest.meta.get("fx")
    if fx is None or train_fx is None:
        return
    if abs(float(train_fx) - float(fx)) > FOCAL_TOLERANCE_PX:
        _note(f"{where}: focal length fx={fx:g} px, the forest's training fx="
              f"{float(train_fx):g} px: its probes are scaled by {float(fx) / float(train_fx):.3f} "
              "(offsets are pixel-metres of the training camera)")


def note_unknown_focal(forest: Any, path: str, more: int = 0) -> None:
    """Say that a frame records no focal length and is read as the training camera's."""
    train_fx = forest.meta.get("fx")
    if train_fx is None:
        return
    others = f" (and {more} more frames)" if more else ""
    _note(f"{path}{others}: no focal length recorded; read as the forest's training camera "
          f"(fx={float(train_fx):g} px): give the camera's with --fx")


def _params(args: argparse.Namespace) -> Any:
    from vhgen.forest.train import TrainParams

    return TrainParams(trees=args.trees, depth=args.depth,
                       pixels_per_image=args.pixels_per_image, features=args.features,
                       thresholds=args.thresholds, seed=args.seed,
                       min_samples=args.min_samples, min_gain=args.min_gain,
                       max_offset=args.max_offset, threshold_range=args.threshold_range,
                       hist_budget_mb=args.hist_budget_mb,
                       background_share=args.background_share,
                       segmented=args.segmented, segmented_share=args.segmented_share,
                       segmented_stores=_segmented_stores(args))


def _segmented_stores(args: argparse.Namespace) -> tuple[str, ...]:
    given = {str(Path(s).resolve()) for s in args.stores}
    out = []
    for s in args.segmented_stores or ():
        if str(Path(s).resolve()) not in given:
            raise ForestError(f"--segmented-stores {s}: not one of the training stores")
        out.append(str(Path(s).resolve()))
    return tuple(out)


def _cmd_train(args: argparse.Namespace) -> int:
    from vhgen.forest.from_stores import train_forest

    params = _params(args)
    params.check()
    if args.workers is not None and args.workers < 1:
        raise ForestError(f"--workers {args.workers}: must be >= 1")
    forest = train_forest(args.stores, params, max_frames=args.max_frames,
                          workers=args.workers, address=args.address,
                          executor=args.executor, progress=None if args.quiet else _progress)
    if args.person_frames:
        _add_person_stage(forest, args.stores, args.person_frames, args.seed, args.quiet)
    path = forest.save(args.out)
    nodes = [t["nodes"] for t in forest.meta["trees"]]
    print(f"wrote {path}: {forest.num_trees} trees ({', '.join(map(str, nodes))} nodes), "
          f"{forest.meta['frames']} frames, {forest.meta['train_seconds']:.1f} s")
    return 0


def _cmd_eval(args: argparse.Namespace) -> int:
    if not (args.stores or args.real or args.nobody or args.people_only):
        raise ForestError("forest eval: give test stores, --real, --nobody or --people-only "
                          "frames")
    if args.masks is not None and not args.real:
        raise ForestError(f"--masks {args.masks}: person masks are for --real frames; none "
                          "given")
    if args.min_body_fraction is not None and not args.segment:
        raise ForestError(f"--min-body-fraction {args.min_body_fraction:g}: a setting of "
                          "--segment, which is not given")
    if args.cut_out and not args.stores:
        raise ForestError("--cut-out: a setting of the test stores, none given")
    forest = load_any_forest(args.forest)
    out: dict[str, Any] = {"forest": str(args.forest)}
    if args.stores:
        out.update(_eval_stores(forest, args))
    if args.real or args.nobody or args.people_only:
        out["real"] = _eval_real(forest, args)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


def _eval_real(forest: Any, args: argparse.Namespace) -> dict:
    from vhgen.forest.realeval import evaluate_real, load_real_frames, table

    frames = load_real_frames(args.real, args.nobody, args.masks, warn=_warn,
                              people_only=args.people_only)
    label = labeller(forest, args.segment, args.fx, args.min_body_fraction,
                     load_parts(args.parts, forest, args.segment))
    told = set()
    for f in frames:
        fx = f.frame.intrinsics.fx if f.frame.intrinsics is not None else args.fx
        if fx is not None and fx not in told:
            told.add(fx)
            check_focal(forest, fx, f.frame.path)
    unknown = [f.frame.path for f in frames if f.frame.intrinsics is None]
    if unknown and args.fx is None:
        note_unknown_focal(forest, unknown[0], len(unknown) - 1)
    res = evaluate_real(label, frames, out_dir=args.out, colors=forest.meta.get("label_colors"),
                        num_classes=forest.num_classes)
    res["segment"] = bool(args.segment)
    print(table(res))
    if args.out:
        print(f"wrote {args.out}/real_sheet.png")
    return res


def _eval_stores(forest: Any, args: argparse.Namespace) -> dict:
    from vhgen.forest.data import check_compatible, store_info
    from vhgen.forest.evaluate import evaluate, table
    from vhgen.forest.persons import table as persons_table
    from vhgen.forest.trees import at_focal

    infos = [store_info(s) for s in args.stores]
    ref = check_compatible(infos, "test")
    names = list(forest.meta.get("label_names", []))
    if list(ref.label_names) != names:
        raise ForestError(f"{ref.path}: label scheme mismatch: store has "
                          f"{ref.label_scheme!r} ({len(ref.label_names)} parts), the forest "
                          f"was trained on {forest.meta.get('label_scheme')!r} "
                          f"({len(names)} parts)")
    check_focal(forest, ref.fx, ref.path)
    forest = at_focal(forest, ref.fx, ref.fy)
    mask, how = None, "forest labels > 0"
    parts = load_parts(args.parts, forest, args.segment)
    if parts is not None and parts is not forest:
        parts = at_focal(parts, ref.fx, ref.fy)
    if args.segment:
        lab = labeller(forest, True, None, args.min_body_fraction, parts)
        how = called_by(forest, args.min_body_fraction, parts)

        def mask(depth: Any, labels: Any, info: Any) -> Any:
            return lab.people(depth, info.intrinsics, labels)[1]  # instances: false counted

    res = evaluate(forest, infos, max_frames=args.max_frames, out_dir=args.out,
                   person_mask=mask, called_by=how, parts=parts, cut_out=args.cut_out)
    print(table(res))
    print(persons_table(res["people"]))
    if res["frames_per_second"]:
        print(f"inference: {res['frames_per_second']:.1f} frames/s over {res['frames']} "
              "frames (all threads)")
    if args.out:
        print(f"wrote {args.out}/confusion.png, {args.out}/contact_sheet.png")
    return {**res, "stores": args.stores}


def read_label_input(path: str) -> Any:
    """A depth image for ``forest label`` (PCD or 16-bit mm PNG, through
    :func:`vhgen.depthfile.read_depth`) -> DepthFrame; ForestError when it is larger than
    forest inference takes. A malformed file is its DepthFileError (one line)."""
    from vhgen.depthfile import read_depth
    from vhgen.forest.predict_kernel import MAX_SIDE

    frame = read_depth(path)
    h, w = frame.depth_mm.shape
    if max(h, w) > MAX_SIDE:
        raise ForestError(f"{path}: {w}x{h} px; forest inference takes images up to "
                          f"{MAX_SIDE} px a side")
    return frame


def frame_intrinsics(frame: Any, forest: Any, fx: float | None = None) -> Any:
    """The intrinsics of a real frame: recovered from its cloud, else a pinhole centred
    on the image with ``fx`` (default: the forest's training focal length)."""
    from vhgen.camera import Intrinsics

    if frame.intrinsics is not None:
        return frame.intrinsics
    f = float(fx if fx is not None else forest.meta.get("fx") or 525.0)
    h, w = frame.depth_mm.shape
    return Intrinsics(w, h, f, f, (w - 1) / 2, (h - 1) / 2)


def segmenter(min_body_fraction: float | None = None) -> Any:
    """The segmentation stage with its defaults (``min_body_fraction`` if given)."""
    from vhgen.forest.segment import Segmenter

    return (Segmenter() if min_body_fraction is None
            else Segmenter(min_body_fraction=min_body_fraction))


def person_stage_of(forest: Any, min_body_fraction: float | None) -> Any:
    """The forest's trained person stage, unless ``--min-body-fraction`` asks for the
    forest's vote (or it has none)."""
    return None if min_body_fraction is not None else getattr(forest, "person_stage", None)


def called_by(forest: Any, min_body_fraction: float | None, parts: Any = None) -> str:
    """How ``--segment`` decides who is a person, for the reports."""
    seg = segmenter(min_body_fraction)
    how = ("the forest's person stage" if person_stage_of(forest, min_body_fraction)
           is not None else f"min_body_fraction {seg.min_body_fraction:g}")
    return f"--segment ({how}{', parts by --parts' if parts is not None else ''})"


def load_parts(path: str | None, forest: Any = None, segment: bool = False) -> Any:
    """The ``--parts`` forest (trained --segmented), or None; without ``--parts``, with
    ``--segment``, the ``forest`` itself when it was trained with a --segmented-share."""
    if path is None:
        one = forest is not None and forest.meta.get("params", {}).get("segmented_share", 0) > 0
        return forest if segment and one else None
    from vhgen.forest.trees import Forest

    parts = Forest.load(path)
    if not parts.labels_people:
        raise ForestError(f"--parts {path}: not a --segmented forest (it labels the pixels "
                          "the person stage keeps; train it with forest train --segmented)")
    return parts


class Labeller:
    """frame -> labels (and person instances): the forest, then (``segment``) the
    segmentation stage of :mod:`vhgen.forest.segment` deciding with the forest's person
    stage, or with its vote at ``min_body_fraction``; with ``parts`` (a forest trained
    --segmented, or the forest itself when trained with a --segmented-share) the people's
    parts are that forest's on the people alone."""

    def __init__(self, forest: Any, segment: bool, fx: float | None = None,
                 min_body_fraction: float | None = None, parts: Any = None):
        from vhgen.forest.trees import predictors_at_focal

        if parts is not None and not segment:
            raise ForestError("--parts: needs --segment (it labels the people the "
                              "segmentation stage finds)")
        self.forest, self.segment, self.fx = forest, segment, fx
        # the forests' predictors at each frame camera's focal length
        self.predictor = predictors_at_focal(forest)
        self.parts = predictors_at_focal(parts, parts_only=True) if parts is not None else None
        self.seg = segmenter(min_body_fraction)
        self.stage = person_stage_of(forest, min_body_fraction)

    def people(self, depth_mm: Any, intr: Any, labels: Any = None) -> tuple[Any, Any]:
        """(labels (H, W) uint8 after every stage, instances (H, W) uint8 or None); the
        forests' probes follow the focal length of ``intr``."""
        import numpy as np

        depth = np.asarray(depth_mm)
        if labels is None:
            labels = self.predictor(intr.fx, intr.fy).predict(depth)
        if not self.segment:
            return labels, None
        inst = self.seg.instances(depth, intr, labels, self.stage)
        if self.parts is not None:
            return self.parts(intr.fx, intr.fy).predict(np.where(inst > 0, depth, 0)), inst
        return self.seg.apply(depth, intr, labels, self.stage, people=inst), inst

    def __call__(self, frame: Any) -> Any:
        return self.people(frame.depth_mm, frame_intrinsics(frame, self.forest, self.fx))[0]


def labeller(forest: Any, segment: bool, fx: float | None = None,
             min_body_fraction: float | None = None, parts: Any = None) -> Labeller:
    """frame -> (H, W) uint8 labels (see :class:`Labeller`)."""
    return Labeller(forest, segment, fx, min_body_fraction, parts)


def _cmd_label(args: argparse.Namespace) -> int:
    from PIL import Image

    from vhgen.forest.evaluate import palette_for

    forest = load_any_forest(args.forest)
    frame = read_label_input(args.depth)
    fx = args.fx if args.fx is not None else (
        frame.intrinsics.fx if frame.intrinsics is not None else None)
    if args.instances and not args.segment:
        raise ConfigError(None, "--instances", "needs --segment (the people are the "
                          "segmentation stage's)")
    lab = labeller(forest, args.segment, fx, args.min_body_fraction,
                   load_parts(args.parts, forest, args.segment))
    check_focal(forest, fx, args.depth)
    if fx is None:
        note_unknown_focal(forest, args.depth)
    intr = frame_intrinsics(frame, forest, fx)
    if args.fx is not None and frame.intrinsics is not None:  # --fx over the cloud's
        intr = dataclasses.replace(intr, fx=float(args.fx), fy=float(args.fx))
    labels, inst = lab.people(frame.depth_mm, intr)
    if args.instances:
        ipath = Path(args.instances)
        ipath.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(inst, mode="L").save(ipath)
        print(f"wrote {ipath}: {int(inst.max())} people (pixel value = person, 0 = none, "
              "numbered left to right)")
    img = Image.fromarray(labels, mode="P")
    pal = palette_for(forest.meta.get("label_colors"), forest.num_classes)
    img.putpalette(pal.ravel().tolist())
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    img.save(out)
    print(f"wrote {out}: {labels.shape[1]}x{labels.shape[0]} labels (pixel value = class, "
          f"0 = background), {int((labels > 0).sum())} body pixels")
    return 0


def _add_person_stage(forest: Any, stores: list[str], frames: int, seed: int,
                      quiet: bool, cut_out: bool = False, vote: str = "argmax",
                      part_order: bool = False, weaker_vote: float | None = None) -> None:
    from vhgen.forest.from_stores import train_person_stage

    if forest.meta.get("params", {}).get("segmented"):
        raise ForestError("--person-frames: a --segmented forest sees only people; train "
                          "the person stage with the forest that finds them")
    # the stage learns from the labels of this vote, so the file keeps it: every later
    # Predictor of the forest (eval, label) labels the same way (argmax: no key, as before)
    if vote == "argmax":
        forest.meta.pop("vote", None)
    else:
        forest.meta["vote"] = vote
    stage = train_person_stage(forest, stores, frames=frames, seed=seed, cut_out=cut_out,
                               part_order=part_order, weaker_vote=weaker_vote,
                               progress=None if quiet else _progress)
    forest.person_stage = stage
    forest.meta["person_stage"] = {"stores": [str(Path(s).resolve()) for s in stores],
                                   "frames": frames, "seed": seed, "trees": len(stage.roots),
                                   "cut_out": cut_out, "vote": vote,
                                   "part_order": part_order, "weaker_vote": weaker_vote}


def _cmd_person_stage(args: argparse.Namespace) -> int:
    from vhgen.forest.trees import Forest

    forest = Forest.load(args.forest)
    _add_person_stage(forest, args.stores, args.frames, args.seed, args.quiet,
                      args.cut_out, args.vote, args.part_order, args.weaker_vote)
    path = forest.save(args.out or args.forest)
    print(f"wrote {path}: the forest with a person stage of "
          f"{forest.meta['person_stage']['trees']} trees from {args.frames} frames")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from vhgen.forest.pcl import export_pcl
    from vhgen.forest.trees import Forest

    forest = Forest.load(args.forest)
    paths = export_pcl(forest, args.output)
    fx = forest.meta.get("fx")
    print(f"wrote {len(paths)} PCL tree files to {args.output} (trained at fx={fx} px; PCL's "
          "people app reads OpenNI depth registered to RGB, f=525 px)")
    if forest.meta.get("vote", "argmax") != "argmax":
        _warn(f"{args.forest}: its labels are decided by --vote {forest.meta['vote']}; PCL's "
              "trees vote by the most probable class, so PCL labels differently")
    return 0


def _body_fraction_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--min-body-fraction", type=A.float_range(0, 1),
                   help="--segment: decide by the forest's vote instead of its person stage "
                        "(forest train --person-frames): a cluster is a person when the "
                        "forest calls at least this share of it a body part (0.5 for forests "
                        "trained with --background-share 0.5; 0.8 for forests without; the "
                        "default for a forest without a person stage is 0.5)")
    p.add_argument("--parts", type=A.existing_file(".npz"),
                   help="--segment: the people's parts from this forest (trained "
                        "--segmented) on the people alone")


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register ``forest`` and its subcommands on the top-level subparsers."""
    fp = subparsers.add_parser("forest", help="train/evaluate/export body-part forests")
    fsub = fp.add_subparsers(dest="forest_cmd", required=True)

    t = fsub.add_parser("train", help="train a forest on one or more stores")
    t.add_argument("stores", nargs="+", type=A.text("store"),
                   help="dataset stores (vhgen generate output)")
    t.add_argument("--out", required=True, type=A.output_path(".npz"), help="forest file (.npz)")
    t.add_argument("--trees", type=A.int_range(1, 1000), default=3,
                   help="number of trees (default 3)")
    t.add_argument("--depth", type=A.int_range(1, 64), default=20,
                   help="maximum tree depth (default 20)")
    t.add_argument("--pixels-per-image", type=A.int_range(1), default=2000,
                   help="training pixels per image, balanced over parts (default 2000)")
    t.add_argument("--background-share", type=A.float_range(0, 1, hi_open=True), default=0.0,
                   help="share of each image's training pixels drawn from the background "
                        "(default 0: the background is one class among the parts present)")
    t.add_argument("--features", type=A.int_range(1), default=2000,
                   help="candidate offset pairs per node (default 2000)")
    t.add_argument("--thresholds", type=A.int_range(1), default=50,
                   help="candidate thresholds per feature (default 50)")
    t.add_argument("--seed", type=A.int_range(0, 2**63 - 1), default=0,
                   help="seed of sampling and candidates")
    t.add_argument("--min-samples", type=A.int_range(1), default=32,
                   help="a node with fewer samples becomes a leaf (default 32)")
    t.add_argument("--min-gain", type=A.float_range(0), default=1e-3,
                   help="a node whose best information gain (bits) is lower becomes a leaf")
    t.add_argument("--max-offset", type=A.int_range(1), default=130,
                   help="largest probe offset, pixel-metres (default 130)")
    t.add_argument("--threshold-range", type=A.int_range(1), default=1000,
                   help="thresholds drawn in [-R, R] mm (default 1000)")
    t.add_argument("--max-frames", type=A.int_range(1), help="a seeded random subset of the frames")
    t.add_argument("--workers", type=A.int_range(1, 4096),
                   help="workers holding disjoint image sets (default: one, in process)")
    t.add_argument("--executor", choices=("auto", "local", "ray"), default="auto",
                   help="where the workers run: local processes (auto without --address) "
                        "or Ray actors (auto with --address; without it, a local Ray)")
    t.add_argument("--address", type=A.text("address"),
                   help="existing Ray cluster (e.g. auto or ray://host:10001)")
    t.add_argument("--hist-budget-mb", type=A.int_range(1), default=256,
                   help="histogram memory per chunk of nodes and worker (default 256)")
    t.add_argument("--segmented", action="store_true",
                   help="the parts of segmented people (Shotton's setting): every pixel "
                        "that is not a person reads as no measurement; label with it "
                        "through --segment --parts")
    t.add_argument("--segmented-share", type=A.float_range(0, 1), default=0.0,
                   help="one forest for the person stage and the parts: this share of the "
                        "frames is seen segmented, the rest whole (default 0)")
    t.add_argument("--segmented-stores", nargs="+", metavar="STORE", type=A.text("store"),
                   help="training stores whose frames are always seen segmented (with "
                        "--segmented-share: stores too crowded to learn the background from)")
    t.add_argument("--person-frames", type=A.int_range(0), default=0,
                   help="then train the segmentation stage's person stage on the candidates "
                        "of this many frames the forest did not train on (default 0: none; "
                        "forest person-stage adds one later)")
    t.add_argument("--quiet", action="store_true", help="no per-level progress")
    t.set_defaults(func=_cmd_train)

    ps = fsub.add_parser("person-stage", help="train the segmentation stage's person "
                                              "decision for a forest and store it in its file")
    ps.add_argument("forest", type=A.existing_file(".npz"), help="forest .npz")
    ps.add_argument("stores", nargs="+", type=A.text("store"),
                    help="stores whose frames give the candidates (frames the forest trained "
                         "on are left out)")
    ps.add_argument("--frames", type=A.int_range(1), default=400,
                    help="frames to take candidates from (default 400)")
    ps.add_argument("--seed", type=A.int_range(0, 2**63 - 1), default=0,
                    help="seed of the frames and the trees")
    ps.add_argument("--out", type=A.output_path(".npz"),
                    help="write the forest with its stage here (default: in place)")
    ps.add_argument("--cut-out", action="store_true",
                    help="learn also from each frame with its background removed (its people "
                         "alone) and from its free-standing things alone (no person), for "
                         "frames a background subtraction feeds the forest: finds more of "
                         "those people")
    ps.add_argument("--part-order", action="store_true",
                    help="the stage also reads where the forest's parts lie in a candidate "
                         "(head over chest over legs): finds more far people and calls "
                         "fewer things people, finds fewer of a line of people side by side")
    ps.add_argument("--weaker-vote", type=A.float_range(0, 1, lo_open=True, hi_open=True),
                    metavar="LOW",
                    help="also learn from every candidate with the forest's vote on it (the "
                         "share called a body part) times a random factor in [LOW, 1], so "
                         "that people the forest calls less of a body part, as real people, "
                         "are still found (off by default; docs/forest.md)")
    ps.add_argument("--vote", choices=("argmax", "mass"), default="argmax",
                    help="how the forest's labels, which the stage learns from and decides "
                         "on, call a pixel a person's: 'argmax' (default), the most probable "
                         "class; 'mass', the parts together outweigh the background (then the "
                         "most probable part). Kept in the file: eval and label use it")
    ps.add_argument("--quiet", action="store_true", help="no progress")
    ps.set_defaults(func=_cmd_person_stage)

    e = fsub.add_parser("eval", help="accuracy of a forest on labelled stores and on real "
                                     "frames (person/background)")
    e.add_argument("forest", type=A.text("forest"), help="forest .npz (or a PCL tree directory)")
    e.add_argument("stores", nargs="*", type=A.text("store"), help="test stores")
    e.add_argument("--real", nargs="+", default=[], type=A.existing_path(),
                   metavar="PATH", help="real frames with people (PCD or 16-bit mm PNG; "
                   "files or folders), each with a person mask (see --masks)")
    e.add_argument("--nobody", nargs="+", default=[], type=A.existing_path(),
                   metavar="PATH", help="real frames with nobody in them (every pixel is "
                   "background)")
    e.add_argument("--people-only", nargs="+", default=[], type=A.existing_path(),
                   metavar="PATH", help="real frames whose background the source removed "
                   "(e.g. ../shared/real/skeltrack): every measured pixel is a person (the "
                   "mask is depth > 0); scored on person recall alone")
    e.add_argument("--segment", action="store_true",
                   help="the segmentation stage after the forest (as forest label "
                        "--segment): real frames are scored on its labels, stores' person "
                        "scores on its person mask (their part scores stay the forest's)")
    _body_fraction_arg(e)
    e.add_argument("--masks", type=A.existing_path(),
                   help="folder of person masks, <frame name>.png (8-bit, 0 = not a person); "
                        "default: <frame name>.mask.png beside each frame")
    e.add_argument("--json", type=A.output_path(".json"), help="write the scores here")
    e.add_argument("--out", type=A.output_path(),
                   help="folder for confusion.png and contact_sheet.png (stores) and "
                        "real_sheet.png (real frames)")
    e.add_argument("--max-frames", type=A.int_range(1), help="a seeded random subset of the frames")
    e.add_argument("--cut-out", action="store_true",
                   help="score the stores' frames with their background removed, their people "
                        "alone measured (as a pipeline with background subtraction feeds the "
                        "forest; the synthetic counterpart of --people-only)")
    e.add_argument("--fx", type=A.float_range(0, lo_open=True),
                   help="focal length (px) of the camera of the --real/--nobody/--people-only "
                        "frames that do not record one (16-bit PNG; a PCD's is recovered; "
                        "default: the forest's training one): the forest's probes are scaled "
                        "to it (PCL tree files record no training focal length: theirs never "
                        "are)")
    e.set_defaults(func=_cmd_eval)

    lb = fsub.add_parser("label", help="label a depth image (organized PCD or 16-bit mm PNG)")
    lb.add_argument("forest", type=A.text("forest"), help="forest .npz (or a PCL tree directory)")
    lb.add_argument("depth", type=A.existing_file(".png", ".pcd"),
                    help="organized PCD cloud (ascii, binary or binary_compressed; NaN = no "
                         "measurement; its focal length is recovered) or 16-bit PNG, "
                         "millimetres, 0 = no measurement")
    lb.add_argument("-o", "--output", required=True, type=A.output_path(".png"),
                    help="label PNG (palette; value = class)")
    lb.add_argument("--fx", type=A.float_range(0, lo_open=True),
                    help="focal length of the depth camera (px; default: a PCD's recovered "
                         "one, else the forest's training one): the forest's probes are "
                         "scaled to it")
    lb.add_argument("--segment", action="store_true",
                    help="remove floor and walls, cluster the rest, and keep body parts "
                         "only in candidates the person stage (or the forest's vote) "
                         "calls a person; see docs/forest.md")
    lb.add_argument("--instances", type=A.output_path(".png"),
                    help="with --segment: also write an 8-bit PNG of the people found, "
                         "pixel value k = the k-th person from the left, 0 = none")
    _body_fraction_arg(lb)
    lb.set_defaults(func=_cmd_label)

    x = fsub.add_parser("export", help="write the forest in another format")
    x.add_argument("forest", type=A.existing_file(".npz"), help="forest .npz")
    x.add_argument("--format", choices=["pcl"], default="pcl",
                   help="pcl: one PCL gpu/people text tree per file")
    x.add_argument("-o", "--output", required=True, type=A.output_path(), help="output folder")
    x.set_defaults(func=_cmd_export)

    return fp
