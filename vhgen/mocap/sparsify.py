"""Pose sparsification: keep a pose only if it differs enough from every pose kept so far.

Semantics (the seed's, after Shotton et al.): poses are visited in order; pose i is kept
iff for every kept pose k the distance D(i, k) >= threshold, where

* ``angle`` metric: D = max over joints of the geodesic angle between the two rotations
  (double-cover safe: computed from rotation matrices, never from quaternion signs);
* ``position`` metric (Shotton's): D = max over joints of the Euclidean distance between
  joint positions (relative to the root, heading removed by the caller if wanted).

Two poses are *close* iff D < threshold, i.e. every joint is within the threshold. For
rotations the test is ``trace(R_i^T R_k) > 1 + 2 cos(threshold)`` per joint (no arccos).

Speed without changing the answer: closeness implies that every coordinate of a feature
vector differs by less than a radius (a rotation-matrix entry moves by at most
2 sin(angle / 2); a position coordinate by at most the distance). So candidates come from
L-infinity ball queries on the eight highest-variance coordinates in KD-trees (scipy's cKDTree:
C, batched, threaded), and only candidates get the exact test. Kept poses live in a
logarithmic forest of static trees (Bentley-Saxe), so insertion stays O(log^2 n)
amortised. Poses are processed in batches: pairs inside a batch come from one
``query_pairs``; the batch is resolved in order and only the poses it would keep are
looked up among earlier kept poses, repeating until nothing changes. Consecutive mocap
frames mostly reject each other inside a batch, so few lookups are needed.
:func:`sparsify_naive` is the obvious loop, kept as the reference.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

ANGLE = "angle"
POSITION = "position"


@numba.njit(cache=True, nogil=True)
def _close_angle(feats, i, k, cos_thr):  # pragma: no cover
    """Pairs whose every joint satisfies trace(R_i^T R_k) > 1 + 2 cos(threshold); stops at
    the first joint that fails (most candidate pairs fail early)."""
    out = np.zeros(i.size, dtype=np.bool_)
    nj = feats.shape[1]
    for p in range(i.size):
        a = i[p]
        b = k[p]
        ok = True
        for j in range(nj):
            tr = 0.0
            for c in range(9):
                tr += feats[a, j, c] * feats[b, j, c]
            if not tr > cos_thr:
                ok = False
                break
        out[p] = ok
    return out


@numba.njit(cache=True, nogil=True)
def _close_position(feats, i, k, d2_thr):  # pragma: no cover
    """Pairs whose every joint is nearer than the threshold (squared distances)."""
    out = np.zeros(i.size, dtype=np.bool_)
    nj = feats.shape[1]
    for p in range(i.size):
        a = i[p]
        b = k[p]
        ok = True
        for j in range(nj):
            d2 = 0.0
            for c in range(3):
                e = feats[a, j, c] - feats[b, j, c]
                d2 += e * e
            if not d2 < d2_thr:
                ok = False
                break
        out[p] = ok
    return out


@dataclass(frozen=True)
class _Metric:
    features: np.ndarray  # (N, J, m) float64
    kind: str
    threshold: float

    def close(self, i: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Exact test for pairs (i[n], k[n]): True where every joint is within threshold."""
        i = np.ascontiguousarray(i, dtype=np.int64)
        k = np.ascontiguousarray(k, dtype=np.int64)
        if self.kind == ANGLE:
            return _close_angle(self.features, i, k, 1.0 + 2.0 * np.cos(self.threshold))
        return _close_position(self.features, i, k, self.threshold * self.threshold)

    @property
    def radius(self) -> float:
        """Per-coordinate bound implied by closeness (plus a hair for rounding)."""
        if self.kind == ANGLE:
            return 2.0 * np.sin(self.threshold / 2.0) + 1e-9
        return self.threshold + 1e-12


def _metric(poses: np.ndarray, threshold: float, metric: str) -> _Metric:
    poses = np.asarray(poses, dtype=np.float64)
    if metric == ANGLE:
        if poses.ndim != 4 or poses.shape[-2:] != (3, 3):
            raise ValueError(f"angle metric needs (N, J, 3, 3) rotations, got {poses.shape}")
        if not 0 < threshold < np.pi:
            raise ValueError(f"angle threshold must be in (0, pi) radians, got {threshold}")
        feats = np.ascontiguousarray(poses.reshape(poses.shape[0], poses.shape[1], 9))
    elif metric == POSITION:
        if poses.ndim != 3 or poses.shape[-1] != 3:
            raise ValueError(f"position metric needs (N, J, 3) positions, got {poses.shape}")
        if not threshold > 0:
            raise ValueError(f"position threshold must be > 0, got {threshold}")
        feats = np.ascontiguousarray(poses)
    else:
        raise ValueError(f"unknown metric {metric!r}")
    if not np.isfinite(feats).all():
        raise ValueError("poses contain NaN or inf")
    return _Metric(feats, metric, float(threshold))


def sparsify_naive(poses: np.ndarray, threshold: float, metric: str = ANGLE) -> np.ndarray:
    """The obvious greedy loop in NumPy (the reference): indices of kept poses, in order.

    Each pose is compared with every kept pose at once (einsum over joints), with the same
    closeness test as :func:`sparsify`.
    poses : (N, J, 3, 3) rotations for ``angle`` (threshold in radians), or (N, J, 3)
    positions for ``position`` (threshold in the positions' unit).
    """
    m = _metric(poses, threshold, metric)
    f = m.features
    kept = np.empty(f.shape, dtype=f.dtype)
    n = 0
    cos_thr = 1.0 + 2.0 * np.cos(m.threshold)
    d2_thr = m.threshold * m.threshold
    out = []
    for i in range(f.shape[0]):
        if n:
            if m.kind == ANGLE:
                close = np.all(np.einsum("jm,kjm->kj", f[i], kept[:n]) > cos_thr, axis=1)
            else:
                diff = kept[:n] - f[i]
                close = np.all(np.einsum("kjm,kjm->kj", diff, diff) < d2_thr, axis=1)
            if close.any():
                continue
        kept[n] = f[i]
        n += 1
        out.append(i)
    return np.asarray(out, dtype=np.int64)


class _Forest:
    """Kept poses' embeddings in static KD-trees of geometrically growing sizes."""

    def __init__(self):
        self.levels: list[tuple[Any, np.ndarray, np.ndarray]] = []  # (tree, pts, ids)

    def add(self, pts: np.ndarray, ids: np.ndarray) -> None:
        from scipy.spatial import cKDTree

        while self.levels and len(self.levels[-1][2]) <= len(ids):
            _, p, i = self.levels.pop()
            pts = np.concatenate([p, pts])
            ids = np.concatenate([i, ids])
        self.levels.append((cKDTree(pts, leafsize=64, balanced_tree=False), pts, ids))

    def candidates(self, q: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """Pairs (query row, kept id) whose embeddings are within ``radius`` (L-inf)."""
        rows, ids = [], []
        for tree, _, lid in self.levels:
            res = tree.query_ball_point(q, radius, p=np.inf, return_sorted=False, workers=-1)
            lens = np.fromiter((len(x) for x in res), dtype=np.int64, count=len(res))
            if lens.sum():
                rows.append(np.repeat(np.arange(len(q)), lens))
                ids.append(lid[np.concatenate([np.asarray(x, dtype=np.int64) for x in res])])
        if not rows:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        return np.concatenate(rows), np.concatenate(ids)


@numba.njit(cache=True, nogil=True)
def _greedy_in_batch(size, pairs, dropped):  # pragma: no cover
    """In-order greedy inside one batch: b is kept unless ``dropped[b]`` or an earlier kept
    a has (a, b) in ``pairs`` (rows (a, b), a < b, sorted by b then a)."""
    keep = ~dropped
    p = 0
    n = pairs.shape[0]
    while p < n:
        b = pairs[p, 1]
        q = p
        while q < n and pairs[q, 1] == b:
            q += 1
        if keep[b]:
            for r in range(p, q):
                if keep[pairs[r, 0]]:
                    keep[b] = False
                    break
        p = q
    return keep


def _embedding(m: _Metric, dims: int) -> np.ndarray:
    flat = m.features.reshape(m.features.shape[0], -1)
    step = max(1, len(flat) // 50_000)  # the spread of a sample picks the same columns
    spread = flat[::step].std(axis=0)
    cols = np.argsort(-spread, kind="stable")[:min(dims, flat.shape[1])]
    return np.ascontiguousarray(flat[:, cols])


def sparsify(poses: np.ndarray, threshold: float, metric: str = ANGLE, *,
             batch: int = 2048, dims: int = 8) -> np.ndarray:
    """Indices of the kept poses, identical to :func:`sparsify_naive`, much faster.

    poses : (N, J, 3, 3) float64 rotations (``angle``, threshold in radians) or (N, J, 3)
        positions (``position``). Raises ValueError on NaN/inf or a bad threshold.
    batch : poses per vectorised step; dims : embedding coordinates in the KD-trees.
    """
    from scipy.spatial import cKDTree

    m = _metric(poses, threshold, metric)
    n = m.features.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    emb = _embedding(m, dims)
    r = m.radius
    forest = _Forest()
    kept_all: list[np.ndarray] = []
    for start in range(0, n, batch):
        idx = np.arange(start, min(start + batch, n))
        # close pairs inside the batch (a < b), exact, sorted by b
        pairs = cKDTree(emb[idx], leafsize=32).query_pairs(r, p=np.inf, output_type="ndarray")
        pairs = pairs.astype(np.int64).reshape(-1, 2)
        if len(pairs):
            pairs = np.sort(pairs, axis=1)
            pairs = pairs[m.close(idx[pairs[:, 0]], idx[pairs[:, 1]])]
            pairs = pairs[np.lexsort((pairs[:, 0], pairs[:, 1]))]
        # Resolve the batch in order, treating poses found close to an earlier kept pose
        # (outside the batch) as dropped; look up only the poses this keeps; repeat until
        # no kept pose is close to the forest. At the fixpoint every kept pose is verified
        # and every dropped pose is close to a kept one: exactly the sequential greedy.
        outside = np.zeros(len(idx), bool)
        checked = np.zeros(len(idx), bool)
        while True:
            keep = _greedy_in_batch(len(idx), pairs, outside)
            ask = np.flatnonzero(keep & ~checked)
            if len(ask) == 0:
                break
            checked[ask] = True
            rows, ids = forest.candidates(emb[idx[ask]], r)
            if len(rows):
                hit = m.close(idx[ask[rows]], ids)
                outside[ask[np.unique(rows[hit])]] = True
            if not outside[ask].any():
                break
        new = idx[keep]
        if len(new):
            kept_all.append(new)
            forest.add(emb[new], new)
    return np.concatenate(kept_all) if kept_all else np.zeros(0, np.int64)


def remove_heading(root_rotations: np.ndarray) -> np.ndarray:
    """Root rotations (..., 3, 3) with the turn about world +Y removed.

    The heading is the yaw of the root's local +Z axis projected on the floor; when that
    axis is (nearly) vertical (handstands, lying poses), the local +X axis is used instead,
    so the result is defined for every rotation.
    """
    r = np.asarray(root_rotations, np.float64)
    fwd = r[..., :, 2]
    side = r[..., :, 0]
    use_side = np.hypot(fwd[..., 0], fwd[..., 2]) < 1e-6
    yaw = np.where(use_side, np.arctan2(side[..., 0], side[..., 2]) - np.pi / 2,
                   np.arctan2(fwd[..., 0], fwd[..., 2]))
    c, s = np.cos(-yaw), np.sin(-yaw)
    ry = np.zeros(r.shape)
    ry[..., 0, 0] = c
    ry[..., 0, 2] = s
    ry[..., 1, 1] = 1.0
    ry[..., 2, 0] = -s
    ry[..., 2, 2] = c
    return ry @ r
