"""Train a forest from stores: in this process (default), in worker processes of this
machine, or on Ray actors, through the pools of :mod:`vhgen.executor`.

Each worker (a :class:`FrameShard`) reads a disjoint round-robin share of the frames from
the stores itself (no image passes through the caller), draws its samples and returns
per-level integer histograms; the caller sums them and picks the splits
(:mod:`vhgen.forest.train`). The sums are exact, so the same seed gives the same forest
for any number of workers and any executor.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vhgen.errors import ForestError
from vhgen.executor import InlinePool
from vhgen.executor.choice import choose_executor
from vhgen.forest.data import (
    check_compatible,
    class_names,
    cut_out_view,
    lone_things_view,
    read_classes,
    read_frames,
    select_frames,
    store_info,
)
from vhgen.forest.person_stage import PersonStage
from vhgen.forest.train import ImageShard, TrainParams, grow_forest
from vhgen.forest.trees import Forest

if TYPE_CHECKING:
    from vhgen.camera import Intrinsics
    from vhgen.forest.segment import Segmenter

log = logging.getLogger(__name__)

_CROP_STREAM = 0xC209  # the seed stream of the person stage's cropped views
_WEAK_STREAM = 0x3EA4  # the seed stream of the person stage's weaker-vote copies


class FrameShard(ImageShard):
    """An ImageShard that reads its own frames (store path, frame, global id)."""

    def __init__(self, frames: list[tuple[str, int, int]], params: TrainParams,
                 threads: int | None = None):
        if threads is not None:
            import numba

            # one CPU per worker: do not let numba spread over every core of the node
            numba.set_num_threads(max(1, min(threads, numba.get_num_threads())))
        depth, labels = read_frames(frames)
        super().__init__(depth, labels, [g for _, _, g in frames], params,
                         [str(Path(p).resolve()) for p, _, _ in frames])


def training_meta(stores: list[str], frames: list[tuple[str, int, int]]) -> dict:
    """What a forest records about its data: scheme, names, colours, focal length, stores."""
    infos = [store_info(s) for s in stores]
    ref = check_compatible(infos)
    return {"label_scheme": ref.label_scheme, "label_names": list(ref.label_names),
            "label_colors": [list(c) for c in ref.label_colors] if ref.label_colors else None,
            "fx": ref.fx, "fy": ref.fy,
            "sensors": sorted({i.sensor for i in infos}),
            "stores": [str(Path(s).resolve()) for s in stores], "frames": len(frames)}


def train_forest(stores: list[str], params: TrainParams, *, max_frames: int | None = None,
                 workers: int | None = None, address: str | None = None,
                 executor: str = "auto",
                 progress: Callable[[str], None] | None = None) -> Forest:
    """Train on the frames of ``stores`` (all, or a seeded subset of ``max_frames``).

    ``workers``/``address`` unset: one shard in this process (numba threads use the
    cores). ``workers``: that many workers holding disjoint frames, as processes of this
    machine (``executor`` ``local``, the default without ``address``) or Ray actors
    (``ray``, the default with ``address``: the cluster there, else a local Ray; default
    one actor per CPU of the cluster).
    """
    params.check()
    if max_frames is not None and max_frames < 1:
        raise ForestError(f"--max-frames {max_frames}: must be >= 1")
    infos = [store_info(s) for s in stores]
    check_compatible(infos)
    frames = select_frames(infos, max_frames, params.seed)
    meta = training_meta(stores, frames)
    num_classes = len(meta["label_names"]) + 1
    t0 = time.perf_counter()
    pool: Any
    if choose_executor(executor, address, error=ForestError) == "ray":
        from vhgen.executor.raypool import RayPool

        pool = RayPool.connect(FrameShard, address=address, local_cpus=workers or 1,
                               options={"num_cpus": 1})
        n = workers or max(1, int(pool.ray.cluster_resources().get("CPU", 1)))
    elif workers is not None:
        from vhgen.executor.local import LocalPool

        pool, n = LocalPool(FrameShard), workers
    else:
        pool, n = InlinePool(FrameShard), 1
    n = max(1, min(n, len(frames)))
    try:
        # an inline shard lets numba use every core; a pool's workers are the parallelism
        threads = None if isinstance(pool, InlinePool) else 1
        pool.start([(frames[w::n], params, threads) for w in range(n)])
        if progress is not None and n > 1:
            progress(f"{n} workers, {len(frames)} frames")
        forest = grow_forest(pool, num_classes, params, meta, progress)
    finally:
        pool.close()
    forest.meta["train_seconds"] = round(time.perf_counter() - t0, 2)
    forest.meta["workers"] = n if workers is not None or address is not None or \
        executor == "ray" else 0
    return forest


def person_stage_frames(forest: Forest, stores: list[str], count: int,
                        seed: int) -> list[tuple[str, int, int]]:
    """``count`` frames of ``stores`` (seeded) that the part forest did not train on: the
    frames of its own training stores that its selection took are left out."""
    infos = [store_info(s) for s in stores]
    check_compatible(infos)
    used: set[tuple[str, int]] = set()
    own = list(forest.meta.get("stores") or [])
    if own and any(str(Path(s).resolve()) in own for s in stores):
        if not all(Path(s).is_dir() for s in own):
            raise ForestError(f"{own[0]}: the forest's training stores are needed to leave "
                              "its training frames out of the person stage's; one is missing")
        params = forest.meta.get("params") or {}
        taken = select_frames([store_info(s) for s in own], int(forest.meta.get("frames", 0)),
                              int(params.get("seed", 0)))
        used = {(str(Path(p).resolve()), f) for p, f, _ in taken}
    rest = [t for t in select_frames(infos, None, 0)
            if (str(Path(t[0]).resolve()), t[1]) not in used]
    if not rest:
        raise ForestError(f"{stores[0]}: every frame of these stores trained the part forest; "
                          "the person stage needs others (train it with --max-frames, or "
                          "give other stores)")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x9E0913]))
    pick = np.sort(rng.permutation(len(rest))[:count])
    return [rest[i] for i in pick]


def stage_rows(seg: Segmenter, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray,
               truth: np.ndarray, without_floor: bool = True, num_labels: int = 0
               ) -> tuple[np.ndarray, ...]:
    """The person stage's training rows of one frame: the features of its candidates
    (:meth:`Segmenter.describe` with the forest's ``labels``) and whether each is a person
    (most of its pixels a person's in ``truth``); with ``num_labels`` (the forest's
    classes) also their :meth:`Segmenter.part_histograms`, from which the stage learns
    where each part lies in a person (the part features are 0 in the rows until
    :func:`with_part_features` fills them). With ``without_floor``, a frame whose
    floor was found gives each candidate twice, also described as if no floor had been
    found: the stage then learns to decide without a floor from every kind of scene, not
    only from the frames where none is found (in the recommended stores, only the real
    recordings behind ``people_real``, where the floor finder found none in 40 of 40
    frames, against 95-100% of the synthetic rooms)."""
    cand = seg.candidates(depth_mm, intr, labels)
    n = cand.count + 1
    size = np.bincount(cand.comp.reshape(-1), minlength=n)
    person = np.bincount(cand.comp.reshape(-1), weights=(truth > 0).reshape(-1),
                         minlength=n) >= 0.5 * size
    table = seg.table_of(cand.comp, cand.count, cand.points, labels, cand.keep)
    xs, ys, hs = [], [], []
    for use in (True, False) if (cand.floor is not None and without_floor) else (True,):
        x = seg.describe(cand, depth_mm, intr, labels, use_floor=use, table=table)
        ok = ~np.isnan(x).any(1)
        xs.append(x[ok])
        ys.append(person[ok])
        if num_labels:
            hs.append(seg.part_histograms(cand, labels, num_labels, use_floor=use)[ok])
    if num_labels:
        return np.concatenate(xs), np.concatenate(ys), np.concatenate(hs)
    return np.concatenate(xs), np.concatenate(ys)


def with_weaker_vote(x: np.ndarray, y: np.ndarray, low: float, seed: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``x`` of :func:`stage_rows` (truths ``y``) followed by a copy of each whose
    ``body`` is multiplied by a uniform draw in [``low``, 1]: what the stage learns when
    it should also find people whose vote is weaker."""
    from vhgen.forest.segment import FEATURES

    if not 0.0 < low < 1.0:
        raise ValueError(f"weaker_vote {low}: a factor in (0, 1)")
    weak = x.copy()
    rng = np.random.default_rng(np.random.SeedSequence([seed, _WEAK_STREAM]))
    weak[:, FEATURES.index("body")] *= rng.uniform(low, 1.0, len(x))
    return np.concatenate([x, weak]), np.concatenate([y, y])


def with_part_features(x: np.ndarray, y: np.ndarray, hist: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``x`` of :func:`stage_rows` with their part features filled from their
    histograms ``hist``, and the parts' typical heights learned from the rows that are
    people (``y``): (x, part_heights)."""
    from vhgen.forest.segment import PART_COLUMNS, learn_part_heights, part_features

    heights = learn_part_heights(hist, y)
    x = np.array(x, np.float64)
    x[:, PART_COLUMNS] = part_features(hist, heights)
    return x, heights


def cropped_view(depth_mm: np.ndarray, truth: np.ndarray, rng: np.random.Generator
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A frame as a camera closer to its people, or turned, sees it: only a window of it
    measured (the top 40-80% of its rows, 50-100% of its columns at a random place; the
    rest reads as no measurement), so people are cut off at the window's edges, their legs
    and the floor out of view. Returns the depth and truth of the view."""
    h, w = depth_mm.shape
    rows = int(round(h * rng.uniform(0.4, 0.8)))
    cols = int(round(w * rng.uniform(0.5, 1.0)))
    left = int(rng.integers(0, w - cols + 1))
    keep = np.zeros((h, w), bool)
    keep[:rows, left:left + cols] = True
    return np.where(keep, depth_mm, 0).astype(depth_mm.dtype), np.where(keep, truth, 0)


def train_person_stage(forest: Forest, stores: list[str], *, frames: int = 400,
                       trees: int = 200, seed: int = 0, without_floor: bool = True,
                       cropped: bool = True, cut_out: bool = False, part_order: bool = False,
                       weaker_vote: float | None = None,
                       progress: Callable[[str], None] | None = None) -> PersonStage:
    """The person stage of the segmentation stage (:mod:`vhgen.forest.person_stage`) for
    ``forest``: the segmentation stage's candidates on ``frames`` frames of ``stores`` the
    forest did not train on, with the forest's labels, each a person when most of its
    pixels are a person's in the store's labels; ``without_floor`` as in
    :func:`stage_rows`. ``trees``: 200: 50 trees' mean moved with their seed (on the
    held-out people_test frames, people found 0.953-0.959 and pixel precision
    0.957-0.961 over seeds 0-2), 200 trees' moves less. ``cropped``: every
    frame also gives the candidates of a :func:`cropped_view` of it (seeded by ``seed``
    and the frame's place in the selection), labelled by the forest on that view: the
    recommended scenes frame every person whole, and a real camera cuts off the people
    close to it. ``cut_out`` (opt-in): every frame also gives the candidates of its
    :func:`cut_out_view` (its people alone), labelled by the forest on that view: frames
    whose background a user's pipeline (background subtraction, the sensor's middleware)
    removed before the forest sees them; and of its :func:`lone_things_view` (its
    free-standing things alone, none a person), so that a thing with nothing around it is
    not a person for being alone. Such a stage finds more of those people
    (docs/forest.md). ``part_order`` (opt-in): the stage also reads where the forest's
    parts lie in a candidate (:data:`vhgen.forest.segment.PART_FEATURES`), with each
    part's typical height in a person learned from these candidates and kept in the
    stage: more of the far people found and fewer things called people, fewer of a line
    of people side by side (docs/forest.md). ``weaker_vote`` (opt-in, in (0, 1)): every
    row is also given a second time with its ``body`` (the share of the candidate the
    forest calls a body part) times a uniform draw in [weaker_vote, 1] (seeded by
    ``seed``), so that the stage also learns people whose vote is weaker, as real
    people's is than vhgen people's (docs/forest.md)."""
    from vhgen.forest.segment import FEATURES, PART_FEATURES, Segmenter
    from vhgen.forest.trees import predictors_at_focal

    chosen = person_stage_frames(forest, stores, frames, seed)
    infos = {s: store_info(s) for s in {p for p, _, _ in chosen}}
    names = {s: class_names(s) for s in infos} if cut_out else {}
    # the forest's probes follow each store's focal length, as forest eval's do
    at = predictors_at_focal(forest)
    by_store = {p: at(v.fx, v.fy) for p, v in infos.items()}

    def predict(d: np.ndarray, part: list[tuple[str, int, int]]) -> np.ndarray:
        if len({id(by_store[p]) for p, _, _ in part}) == 1:
            return by_store[part[0][0]].predict(d)
        return np.stack([by_store[p].predict(d[k]) for k, (p, _, _) in enumerate(part)])

    seg = Segmenter()
    xs, ys, hs = [], [], []
    t0 = time.perf_counter()
    for s in range(0, len(chosen), 16):
        part = chosen[s:s + 16]
        depth, truth = read_frames(part)
        labels = predict(depth, part)
        views = [(depth, labels, truth)]
        if cropped:
            cut = [cropped_view(depth[i], truth[i], np.random.default_rng(
                np.random.SeedSequence([seed, _CROP_STREAM, s + i]))) for i in range(len(part))]
            vdepth = np.stack([d for d, _ in cut])
            views.append((vdepth, predict(vdepth, part), np.stack([t for _, t in cut])))
        if cut_out:
            classes = read_classes(part, depth.shape)
            odepth = cut_out_view(depth, truth, classes)
            views.append((odepth, predict(odepth, part), truth))
            # and its things alone, none a person: a thing with nothing around it is
            # not a person for being alone
            tdepth = np.stack([lone_things_view(depth[i], truth[i], classes[i],
                                                names[path])
                               for i, (path, _, _) in enumerate(part)])
            views.append((tdepth, predict(tdepth, part), np.zeros_like(truth)))
        for vd, vl, vt in views:
            for i, (path, _, _) in enumerate(part):
                rows = stage_rows(seg, vd[i], infos[path].intrinsics, vl[i], vt[i],
                                  without_floor, forest.num_classes if part_order else 0)
                xs.append(rows[0])
                ys.append(rows[1])
                if part_order:
                    hs.append(rows[2].astype(np.float32))
        if progress is not None:
            progress(f"person stage: candidates of {min(s + 16, len(chosen))}/{len(chosen)} "
                     "frames")
    x_all, y_all = np.concatenate(xs), np.concatenate(ys)
    if y_all.all() or not y_all.any():
        raise ForestError(f"{stores[0]}: the person stage needs candidates that are people "
                          f"and candidates that are not; {len(chosen)} frames gave "
                          f"{int(y_all.sum())} people among {len(y_all)} candidates")
    heights = None
    if part_order:
        x_all, heights = with_part_features(x_all, y_all, np.concatenate(hs))
    if weaker_vote is not None:
        x_all, y_all = with_weaker_vote(x_all, y_all, weaker_vote, seed)
    kept = FEATURES if part_order else tuple(f for f in FEATURES if f not in PART_FEATURES)
    stage = replace(PersonStage.fit(x_all[:, [FEATURES.index(f) for f in kept]], y_all, kept,
                                    trees=trees, seed=seed), part_heights=heights)
    log.info("person stage: %d candidates (%d people) of %d frames, %.1f s", len(y_all),
             int(y_all.sum()), len(chosen), time.perf_counter() - t0)
    return stage
