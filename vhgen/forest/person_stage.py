"""The person decision of the segmentation stage: a classifier of person candidates.

The segmentation stage (:mod:`vhgen.forest.segment`) cuts a frame into person candidates
without the forest. Which of them are people was the forest's vote alone (the share of a
candidate's pixels called a body part). At a distance the part forest calls much of a
person background (it sees a person in fewer, noisier pixels), and the vote then drops
people whose candidate is clean: on the held-out people_test frames, 58 of the 61 people
the stage lost had a clean candidate (95% theirs) that the vote rejected. The stage
trained here decides on what a candidate *is* as well as on what the forest says about
it, as ground-based people detectors keep clusters by their height and width (PCL's
``ground_based_people_detection``): :class:`PersonStage`, extremely randomized trees
(Geurts et al. 2006) over the candidate features of :meth:`Segmenter.features`
(:data:`vhgen.forest.segment.FEATURES`: sizes and shape in metres on the floor, and the
forest's vote), trained on vhgen candidates whose truth is known (a candidate is a person
when most of its pixels are a person's), float64, seeded, stored in the forest's file.

Nothing here is fitted to real frames: the trees learn from synthetic candidates, and a
candidate is a person when their mean person share (the two classes weighted to equal
total) is at least one half.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PersonStage:
    """Extremely randomized binary trees over candidate features (NaN rows: never a
    person). Arrays per node, trees concatenated: ``feature`` (-1 at a leaf),
    ``threshold``, ``left``/``right`` (absolute node ids), ``prob`` (the leaf's weighted
    person share), ``roots`` (one node id per tree). ``part_heights``: the typical height
    of each of the part forest's labels in a person, learned with the trees
    (:func:`vhgen.forest.segment.learn_part_heights`; None in a stage of before them)."""

    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    prob: np.ndarray
    roots: np.ndarray
    features: tuple[str, ...]
    part_heights: np.ndarray | None = None

    @classmethod
    def fit(cls, x: np.ndarray, y: np.ndarray, features: tuple[str, ...], *,
            trees: int = 50, min_leaf: int = 5, candidates: int = 0,
            seed: int = 0) -> PersonStage:
        """Train on rows ``x`` (N, F) float64 without NaN (columns named ``features``) and
        truths ``y`` (N,) bool;
        the two classes weighted to equal total. ``candidates``: random splits tried per
        node (default sqrt(F), Geurts et al.'s default for classification)."""
        x = np.asarray(x, np.float64)
        y = np.asarray(y, bool)
        if len(x) == 0 or y.all() or not y.any():
            raise ValueError("person stage: needs candidates of both kinds")
        w = np.where(y, 0.5 / y.sum(), 0.5 / (~y).sum())
        k = candidates or max(1, int(round(np.sqrt(x.shape[1]))))
        rng = np.random.default_rng(np.random.SeedSequence([seed, 0xC1A55]))
        nodes: dict[str, list] = {"feature": [], "threshold": [], "left": [], "right": [],
                                  "prob": []}
        roots = []
        for _ in range(trees):
            roots.append(len(nodes["feature"]))
            _grow(x, y, w, np.arange(len(x)), nodes, rng, k, min_leaf)
        return cls(np.asarray(nodes["feature"], np.int64),
                   np.asarray(nodes["threshold"], np.float64),
                   np.asarray(nodes["left"], np.int64), np.asarray(nodes["right"], np.int64),
                   np.asarray(nodes["prob"], np.float64), np.asarray(roots, np.int64),
                   tuple(features))

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        """(N,) float64: the trees' mean person share; NaN rows get 0."""
        x = np.asarray(x, np.float64)
        out = np.zeros(len(x))
        good = np.flatnonzero(~np.isnan(x).any(1))
        if len(good) == 0:
            return out
        xs = x[good]
        # every tree at once, one level per step: (rows, trees) node ids
        node = np.repeat(self.roots[None, :], len(xs), axis=0)
        rows = np.arange(len(xs))[:, None]
        while True:
            f = self.feature[node]
            inner = f >= 0
            if not inner.any():
                break
            go_left = xs[rows, np.maximum(f, 0)] < self.threshold[node]
            node = np.where(inner, np.where(go_left, self.left[node], self.right[node]),
                            node)
        prob = self.prob[node]
        total = np.zeros(len(xs))
        for t in range(prob.shape[1]):  # summed in tree order, as one tree at a time was
            total += prob[:, t]
        out[good] = total / len(self.roots)
        return out

    def to_arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """Arrays for an .npz, keys under ``prefix``."""
        return {f"{prefix}feature": self.feature, f"{prefix}threshold": self.threshold,
                f"{prefix}left": self.left, f"{prefix}right": self.right,
                f"{prefix}prob": self.prob, f"{prefix}roots": self.roots,
                f"{prefix}names": np.asarray(self.features),
                **({} if self.part_heights is None else
                   {f"{prefix}part_heights": np.asarray(self.part_heights, np.float64)})}

    @classmethod
    def from_arrays(cls, arrays: dict, prefix: str) -> PersonStage:
        """The inverse of :meth:`to_arrays`."""
        names = tuple(str(s) for s in arrays[f"{prefix}names"])
        def get(key: str) -> np.ndarray:
            return np.asarray(arrays[f"{prefix}{key}"])

        heights = arrays.get(f"{prefix}part_heights")
        return cls(get("feature"), get("threshold"), get("left"), get("right"), get("prob"),
                   get("roots"), names,
                   None if heights is None else np.asarray(heights, np.float64))


def _grow(x: np.ndarray, y: np.ndarray, w: np.ndarray, idx: np.ndarray, nodes: dict,
          rng: np.random.Generator, k: int, min_leaf: int) -> int:
    """Append the subtree of rows ``idx`` to ``nodes`` (depth first); its root's id."""
    me = len(nodes["feature"])
    for key in nodes:
        nodes[key].append(-1 if key in ("feature", "left", "right") else 0.0)
    wi, yi = w[idx], y[idx]
    total = wi.sum()
    share = float((wi * yi).sum() / total) if total > 0 else 0.0
    nodes["prob"][me] = share
    if len(idx) < 2 * min_leaf or share in (0.0, 1.0):
        return me
    xi = x[idx]
    lo, hi = xi.min(0), xi.max(0)
    usable = np.flatnonzero(hi > lo)
    if len(usable) == 0:
        return me
    best = None
    for f in rng.choice(usable, size=min(k, len(usable)), replace=False):
        t = rng.uniform(lo[f], hi[f])
        left = xi[:, f] < t
        nl = int(left.sum())
        if nl < min_leaf or len(idx) - nl < min_leaf:
            continue
        score = _gini(wi[left], yi[left]) + _gini(wi[~left], yi[~left])
        if best is None or score < best[0]:
            best = (score, int(f), float(t), left)
    if best is None:
        return me
    _, f, t, left = best
    nodes["feature"][me] = f
    nodes["threshold"][me] = t
    nodes["left"][me] = _grow(x, y, w, idx[left], nodes, rng, k, min_leaf)
    nodes["right"][me] = _grow(x, y, w, idx[~left], nodes, rng, k, min_leaf)
    return me


def _gini(w: np.ndarray, y: np.ndarray) -> float:
    """Weighted Gini impurity times the weight: the split score to minimise."""
    total = w.sum()
    if total <= 0:
        return 0.0
    p = (w * y).sum() / total
    return float(total * 2.0 * p * (1.0 - p))
