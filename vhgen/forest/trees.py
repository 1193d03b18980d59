"""The forest as arrays, its file format (.npz + JSON metadata) and the Predictor (its
compiled kernel is :mod:`vhgen.forest.predict_kernel`).

A tree is stored sparse, breadth first: node ``i`` has a feature ``offsets[i]`` (du1, dv1,
du2, dv2 int16 pixel-metres), a threshold ``thresh[i]`` (int32 millimetres, within int16
as PCL stores it), ``left[i]`` (index of its left child, right child = left + 1, -1 for a
leaf), ``depth[i]`` and ``counts[i]`` (training samples per class at the node, class 0 =
background, k = part k). The forest concatenates its trees; ``roots[t]`` is the first node
of tree t. Prediction averages the normalised leaf histograms over trees and takes the
argmax (Shotton et al. 2011, eq. 2), ties to the lowest class; a forest whose meta says
``vote: mass`` calls a pixel background only where the background outweighs all parts
together (:class:`Predictor`).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numba
import numpy as np

from vhgen.errors import ForestError
from vhgen.forest.features import BACKGROUND_MM, FOCAL_SCALE, prepare_depth
from vhgen.forest.person_stage import PersonStage
from vhgen.forest.predict_kernel import MAX_SIDE, pack_forest, predict_batch, predict_frame

FORMAT = "vhgen-forest"
FORMAT_VERSION = 1
PERSON_STAGE = "person_stage_"


@dataclass
class Forest:
    """Trees as concatenated node arrays (see module docstring) plus metadata.

    ``meta`` holds at least ``label_names`` (K parts; classes are 0..K), ``label_scheme``,
    ``fx``/``fy`` (training focal length, px) and the training settings.
    """

    offsets: np.ndarray  # (N, 4) int16
    thresh: np.ndarray  # (N,) int32
    left: np.ndarray  # (N,) int32, -1 = leaf
    depth: np.ndarray  # (N,) int16
    counts: np.ndarray  # (N, C) int64
    roots: np.ndarray  # (T,) int64
    meta: dict = field(default_factory=dict)
    # the segmentation stage's person decision (vhgen.forest.person_stage.PersonStage),
    # when trained: arrays under PERSON_STAGE in the file
    person_stage: PersonStage | None = None

    @property
    def num_trees(self) -> int:
        return len(self.roots)

    @property
    def num_classes(self) -> int:
        return int(self.counts.shape[1])

    @property
    def labels_people(self) -> bool:
        """Whether it labels segmented people: trained ``--segmented``, or with a
        ``--segmented-share`` (one forest for the person stage and the parts)."""
        pp = self.meta.get("params", {})
        return bool(pp.get("segmented") or pp.get("segmented_share", 0.0) > 0)

    def tree_slice(self, t: int) -> slice:
        end = self.roots[t + 1] if t + 1 < len(self.roots) else len(self.left)
        return slice(int(self.roots[t]), int(end))

    def probabilities(self) -> np.ndarray:
        """(N, C) float32 normalised class histograms (all-zero rows stay zero)."""
        tot = np.maximum(self.counts.sum(axis=1, keepdims=True), 1).astype(np.float32)
        return self.counts.astype(np.float32) / tot

    def leaf_labels(self) -> np.ndarray:
        """(N,) uint8 argmax class of every node (first maximum), what one tree outputs."""
        return np.argmax(self.counts, axis=1).astype(np.uint8)

    def save(self, path: str | Path) -> Path:
        """Write ``path`` (.npz: the arrays and a JSON string ``meta``)."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz") if path.suffix else \
                path.with_suffix(".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"format": FORMAT, "format_version": FORMAT_VERSION, **self.meta}
        arrays: dict[str, Any] = {
            "offsets": self.offsets, "thresh": self.thresh, "left": self.left,
            "depth": self.depth, "counts": self.counts, "roots": self.roots,
            "meta": np.array(json.dumps(meta))}
        if self.person_stage is not None:
            arrays.update(self.person_stage.to_arrays(PERSON_STAGE))
        np.savez_compressed(path, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Forest:
        """Read a forest written by :meth:`save`; ForestError names the file if it is not one."""
        path = Path(path)
        if not path.is_file():
            raise ForestError(f"{path}: no such forest file")
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                arrays = {k: z[k] for k in ("offsets", "thresh", "left", "depth", "counts",
                                            "roots")}
                stage = {k: z[k] for k in z.files if k.startswith(PERSON_STAGE)}
        except (OSError, ValueError, KeyError) as e:
            raise ForestError(f"{path}: not a vhgen forest file ({e})") from None
        if meta.get("format") != FORMAT:
            raise ForestError(f"{path}: not a vhgen forest file (format {meta.get('format')!r})")
        person_stage = None
        if stage:
            try:
                person_stage = PersonStage.from_arrays(stage, PERSON_STAGE)
            except (KeyError, ValueError) as e:
                raise ForestError(f"{path}: its person stage cannot be read ({e})") from None
        return cls(meta=meta, person_stage=person_stage, **arrays)


@numba.njit(cache=True)
def _walk(img, x, y, scale, offsets, thresh, left, node):
    h, w = img.shape
    while left[node] >= 0:
        # same arithmetic as features._probe64 (PCL trees.cpp runThroughTree)
        u1 = min(max(int(np.float32(x + offsets[node, 0] * scale)), 0), w - 1)
        v1 = min(max(int(np.float32(y + offsets[node, 1] * scale)), 0), h - 1)
        u2 = min(max(int(np.float32(x + offsets[node, 2] * scale)), 0), w - 1)
        v2 = min(max(int(np.float32(y + offsets[node, 3] * scale)), 0), h - 1)
        f = np.int32(img[v1, u1]) - np.int32(img[v2, u2])
        node = left[node] + 1 if f > thresh[node] else left[node]
    return node


@numba.njit(cache=True)
def _tree_labels(img, offsets, thresh, left, root, labels, out):
    h, w = img.shape
    for y in range(h):
        for x in range(w):
            d0 = img[y, x]
            if d0 == BACKGROUND_MM:
                out[y, x] = 0
                continue
            leaf = _walk(img, x, y, FOCAL_SCALE / np.float64(d0), offsets, thresh, left, root)
            out[y, x] = labels[leaf]


VOTES = ("argmax", "mass")


def _checked_vote(vote: str, what: str = "vote") -> str:
    if vote not in VOTES:
        raise ForestError(f"{what} {vote!r}: must be one of {', '.join(VOTES)}")
    return vote


def forest_vote(forest: Forest) -> str:
    """How ``forest`` decides person against background: its meta ``vote`` (set by
    ``forest person-stage --vote``), else ``argmax``."""
    return _checked_vote(str(forest.meta.get("vote", "argmax")), "forest vote")


class Predictor:
    """Compiled per-pixel labelling with one forest (arrays prepared once); ``parts_only``:
    the parts of pixels known to be a person's (the leaves' background counts left out, as
    for a forest trained --segmented, which has none). ``vote`` (default: the forest's,
    :func:`forest_vote`): ``argmax``, the most probable class (background one class among
    the parts); ``mass``, a person where the parts together outweigh the background, then
    the most probable part (a pixel whose probability is spread over several parts, as a
    far person's is, is still a person's)."""

    def __init__(self, forest: Forest, parts_only: bool = False, vote: str | None = None):
        self.forest = forest
        self.vote = forest_vote(forest) if vote is None else _checked_vote(vote)
        self._sparse: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # tree_labels
        counts = forest.counts
        if parts_only and counts[:, 0].any():  # P(part | pixel of a person): no background
            counts = counts.copy()
            counts[:, 0] = 0
        self._packed = pack_forest(forest.offsets, forest.thresh, forest.left, counts,
                                   forest.roots)

    def predict(self, depth: np.ndarray, prepared: bool = False) -> np.ndarray:
        """Labels of one frame (H, W) or a batch (N, H, W) of uint16 mm depth -> uint8.

        0 = background: no measurement, or the forest says background. A single frame runs
        serially (one core); a batch runs frames in parallel over numba threads. The kernel
        is :mod:`vhgen.forest.predict_kernel`; sides up to 32767 px (else ForestError).
        """
        d = np.ascontiguousarray(depth, dtype=np.uint16) if prepared else prepare_depth(depth)
        if d.ndim not in (2, 3):
            raise ValueError(f"depth must be (H, W) or (N, H, W), got {d.shape}")
        if max(d.shape[-2:]) > MAX_SIDE:
            raise ForestError(f"depth images up to {MAX_SIDE} px a side, got {d.shape}")
        out = np.empty(d.shape, dtype=np.uint8)
        pf = self._packed
        kernel = predict_frame if d.ndim == 2 else predict_batch
        kernel(d, pf.nodes, pf.roots, pf.levels, pf.prob, out, self.vote == "mass")
        return out

    def tree_labels(self, depth: np.ndarray, tree: int) -> np.ndarray:
        """(H, W) uint8: what tree ``tree`` alone outputs (argmax of its leaf), 0 where
        there is no measurement; the per-tree labelling PCL computes before its vote."""
        if self._sparse is None:  # built on first use: most predictors never need it
            f = self.forest
            self._sparse = (np.ascontiguousarray(f.offsets, dtype=np.int64),
                            np.ascontiguousarray(f.thresh, dtype=np.int32),
                            np.ascontiguousarray(f.left, dtype=np.int64))
        d = prepare_depth(depth)
        out = np.empty(d.shape, dtype=np.uint8)
        _tree_labels(d, *self._sparse, int(self.forest.roots[tree]), self.forest.leaf_labels(),
                     out)
        return out


FOCAL_TOLERANCE_PX = 0.5  # focal lengths closer than this are the same camera


def at_focal(forest: Forest, fx: float | None, fy: float | None = None) -> Forest:
    """The forest for frames of a camera of focal lengths ``fx``, ``fy`` (px; ``fy``
    defaults to ``fx``): its probe offsets, pixel-metres of the training camera (meta
    ``fx``/``fy``), scaled by ``fx / fx_train`` across and ``fy / fy_train`` down, and
    rounded, so that every probe reaches as far on the body as in training. The forest
    itself when ``fx`` or the training focal length is unknown, or they agree within
    :data:`FOCAL_TOLERANCE_PX`."""
    tx = forest.meta.get("fx")
    if fx is None or tx is None:
        return forest
    ty = forest.meta.get("fy") or tx
    fy = fx if fy is None else fy
    if (abs(float(fx) - float(tx)) <= FOCAL_TOLERANCE_PX
            and abs(float(fy) - float(ty)) <= FOCAL_TOLERANCE_PX):
        return forest
    ratio = np.array([fx / tx, fy / ty, fx / tx, fy / ty], np.float64)
    info = np.iinfo(np.int16)
    offsets = np.clip(np.rint(forest.offsets.astype(np.float64) * ratio),
                      info.min, info.max).astype(forest.offsets.dtype)
    meta = {**forest.meta, "fx": float(fx), "fy": float(fy),
            "trained_focal": [float(tx), float(ty)]}
    return Forest(offsets, forest.thresh, forest.left, forest.depth, forest.counts,
                  forest.roots, meta, forest.person_stage)


def predictors_at_focal(forest: Forest, parts_only: bool = False
                        ) -> Callable[[float, float], Predictor]:
    """(fx, fy) -> the :class:`Predictor` of ``forest`` at that camera's focal lengths
    (:func:`at_focal`), built once per focal length; one predictor serves every camera
    within :data:`FOCAL_TOLERANCE_PX` of the training one."""
    cache: dict[tuple[float, float] | None, Predictor] = {}

    def at(fx: float, fy: float) -> Predictor:
        key = (float(fx), float(fy))
        if key not in cache:
            f = at_focal(forest, fx, fy)
            own = None if f is forest else key  # the training camera's: one predictor
            if own not in cache:
                cache[own] = Predictor(f, parts_only=parts_only)
            cache[key] = cache[own]
        return cache[key]

    return at


def truncate(forest: Forest, depth: int) -> Forest:
    """The forest cut at ``depth``: nodes at that depth become leaves (their training
    histograms kept). Level-wise growth draws the same samples and candidates per level
    whatever the depth limit, so this IS the forest trained with ``--depth depth``
    (up to the min-gain/min-samples stops, which do not depend on the limit)."""
    left = np.where(forest.depth >= depth, -1, forest.left).astype(np.int32)
    return Forest(forest.offsets, forest.thresh, left, forest.depth, forest.counts,
                  forest.roots, {**forest.meta, "truncated_depth": depth}, forest.person_stage)


def first_trees(forest: Forest, k: int) -> Forest:
    """The first ``k`` trees (trees are grown independently: same as ``--trees k``)."""
    end = forest.tree_slice(k - 1).stop
    return Forest(forest.offsets[:end], forest.thresh[:end], forest.left[:end],
                  forest.depth[:end], forest.counts[:end], forest.roots[:k],
                  {**forest.meta, "trees_used": k}, forest.person_stage)
