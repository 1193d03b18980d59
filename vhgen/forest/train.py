"""Level-wise forest training from class histograms (where the shards run: from_stores.py).

One tree grows one level at a time over ALL its training samples, the way GPU and
distributed forest trainers do it:

1. every image shard draws its samples: per image up to ``pixels_per_image`` pixels with a
   measurement, balanced over the classes present (seeded by seed, tree and global image id);
2. per level the driver draws, for every frontier node, ``features`` candidate offset pairs
   and ``thresholds`` thresholds each (seeded by seed, tree, level);
3. every shard fills, for each (node, feature, threshold bin, class), how many of its
   samples fall there (:func:`_histograms`, numba, parallel over node x feature), in
   chunks of nodes that fit a memory budget; the driver sums the integer counts of all
   shards, so the forest does not depend on how images are split over workers;
4. the driver picks the best split of each node by information gain (:func:`_best_splits`)
   and every shard routes its samples to the children.

A node becomes a leaf at ``depth``, below ``min_samples``, when pure, or when its best gain is
below ``min_gain`` (bits). Class 0 is background (only pixels with a measurement but no
body label are background samples); pixels without a measurement are never samples.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numba
import numpy as np

from vhgen.forest.features import BACKGROUND_MM, draw_offsets, feature_at, prepare_depth
from vhgen.forest.trees import Forest

log = logging.getLogger(__name__)

_SAMPLE_STREAM = 0x5A3B1E
_SEGMENT_STREAM = 0x5E6D
_FEATURE_STREAM = 0xFEA7


@dataclass(frozen=True)
class TrainParams:
    """Training settings; defaults follow Shotton et al. 2011 (3 trees, depth 20, 2000 pixels
    per image, 2000 candidate features x 50 thresholds per node)."""

    trees: int = 3
    depth: int = 20
    pixels_per_image: int = 2000
    features: int = 2000
    thresholds: int = 50
    seed: int = 0
    min_samples: int = 32  # a node with fewer samples is a leaf
    min_gain: float = 1e-3  # bits; a node whose best split gains less is a leaf
    max_offset: int = 130  # pixel-metres (Shotton's best probe range, 129 px m)
    threshold_range: int = 1000  # mm; thresholds uniform in [-range, range]
    hist_budget_mb: int = 256  # histogram memory per chunk of nodes and shard
    # share of each image's samples drawn from the background (class 0); 0: background is
    # one class among those present, like every part (Shotton's balance)
    background_share: float = 0.0
    # Shotton's setting: the parts of segmented people. Every pixel that is not a person
    # (label 0) reads as no measurement (BACKGROUND_MM) and no sample is drawn there; such
    # a forest labels the pixels a person stage kept (vhgen.forest.segment), nothing else
    segmented: bool = False
    # one forest for both stages: this share of the frames (each drawn by its own seeded
    # stream) is seen segmented as above, the rest whole (with background_share); the
    # person stage then reads its vote on whole frames and it labels segmented people
    segmented_share: float = 0.0
    # stores (resolved paths) whose frames are always seen segmented, whatever the share
    segmented_stores: tuple[str, ...] = ()

    def segmented_frame(self, global_id: int, store: str | None = None) -> bool:
        """Whether frame ``global_id`` (of ``store``) is seen segmented."""
        if self.segmented or self.segmented_share >= 1.0 or store in self.segmented_stores:
            return True
        if self.segmented_share <= 0.0:
            return False
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, _SEGMENT_STREAM,
                                                            int(global_id)]))
        return bool(rng.random() < self.segmented_share)

    def check(self) -> None:
        """Raise ForestError naming the flag of the first bad value."""
        from vhgen.errors import ForestError

        limits = {"trees": (1, 64), "depth": (1, 30), "pixels_per_image": (1, 10**6),
                  "features": (1, 10**5), "thresholds": (1, 10**4), "min_samples": (1, 10**9),
                  "max_offset": (1, 32767), "threshold_range": (1, 32767),
                  "hist_budget_mb": (1, 10**6)}
        for name, (lo, hi) in limits.items():
            v = getattr(self, name)
            if not lo <= v <= hi:
                raise ForestError(f"--{name.replace('_', '-')} {v}: must be in [{lo}, {hi}]")
        if self.min_gain < 0:
            raise ForestError(f"--min-gain {self.min_gain}: must be >= 0")
        if not 0.0 <= self.background_share < 1.0:
            raise ForestError(f"--background-share {self.background_share}: must be in "
                              "[0, 1)")
        if not 0.0 <= self.segmented_share <= 1.0:
            raise ForestError(f"--segmented-share {self.segmented_share}: must be in [0, 1]")
        if self.segmented and self.segmented_share > 0:
            raise ForestError("--segmented-share: --segmented sees every frame segmented")
        if self.segmented and self.background_share > 0:
            raise ForestError(f"--background-share {self.background_share}: a --segmented "
                              "forest sees no background")


# ----------------------------------------------------------------------------- kernels


_GROUP = 16  # candidates evaluated together per sample: the sample's image patch stays hot


@numba.njit(parallel=True, cache=True)
def _histograms(depths, s_img, s_x, s_y, s_lab, starts, chunk_nodes, offsets, thresh,
                classmap, hoff, out):
    """out[hoff[b] + (j*(T+1) + bin)*C_b + classmap[b, label]] += 1 for every sample of
    frontier node chunk_nodes[b] and candidate j; bin = #thresholds < f (right for k < bin).

    Tasks are (node, group of _GROUP candidates), so no two threads write the same counts;
    within a task samples are the outer loop (the probes of one sample hit one image patch,
    fetched once for all candidates of the group instead of once per candidate)."""
    nb, nf, nt = thresh.shape
    ng = (nf + _GROUP - 1) // _GROUP
    for task in numba.prange(nb * ng):
        b = task // ng
        j0 = (task - b * ng) * _GROUP
        j1 = min(j0 + _GROUP, nf)
        a = chunk_nodes[b]
        cb = (hoff[b + 1] - hoff[b]) // (nf * (nt + 1))
        for s in range(starts[a], starts[a + 1]):
            im = depths[s_img[s]]
            x = s_x[s]
            y = s_y[s]
            c = classmap[b, s_lab[s]]
            for j in range(j0, j1):
                f = feature_at(im, x, y, offsets[b, j, 0], offsets[b, j, 1], offsets[b, j, 2],
                               offsets[b, j, 3])
                lo = 0
                hi = nt
                while lo < hi:
                    mid = (lo + hi) >> 1
                    if thresh[b, j, mid] < f:
                        lo = mid + 1
                    else:
                        hi = mid
                out[hoff[b] + (j * (nt + 1) + lo) * cb + c] += 1


@numba.njit(inline="always")
def _entropy(c, n):
    if n <= 0:
        return 0.0
    h = 0.0
    for k in range(c.shape[0]):
        if c[k] > 0:
            p = c[k] / n
            h -= p * np.log2(p)
    return h


@numba.njit(parallel=True, cache=True)
def _best_splits(hist, hoff, ncls, parent, nf, nt, best_j, best_k, best_gain, best_left):
    """Per node b: the (feature j, threshold k) of largest information gain (first maximum
    in j, k order), with the left (f <= thresh) class counts in local class order."""
    for b in numba.prange(ncls.shape[0]):
        cb = ncls[b]
        pc = parent[b, :cb].astype(np.float64)
        n = pc.sum()
        hp = _entropy(pc, n)
        left = np.zeros(cb, dtype=np.float64)
        best = -1.0
        bj = -1
        bk = -1
        for j in range(nf):
            left[:] = 0.0
            nl = 0.0
            base = hoff[b] + j * (nt + 1) * cb
            for k in range(nt):
                for c in range(cb):
                    v = hist[base + k * cb + c]
                    left[c] += v
                    nl += v
                nr = n - nl
                if nl == 0.0 or nr == 0.0:
                    continue
                hl = _entropy(left, nl)
                hr = 0.0
                for c in range(cb):
                    r = pc[c] - left[c]
                    if r > 0:
                        p = r / nr
                        hr -= p * np.log2(p)
                g = hp - (nl * hl + nr * hr) / n
                if g > best:
                    best = g
                    bj = j
                    bk = k
        best_j[b] = bj
        best_k[b] = bk
        best_gain[b] = best
        if bj >= 0:
            base = hoff[b] + bj * (nt + 1) * cb
            for c in range(cb):
                acc = 0
                for k in range(bk + 1):
                    acc += hist[base + k * cb + c]
                best_left[b, c] = acc


@numba.njit(cache=True)
def _route(depths, s_img, s_x, s_y, s_node, split_off, split_thr, child):
    for s in range(s_node.shape[0]):
        a = s_node[s]
        if a < 0:
            continue
        c = child[a]
        if c < 0:
            s_node[s] = -1
            continue
        f = feature_at(depths[s_img[s]], s_x[s], s_y[s], split_off[a, 0], split_off[a, 1],
                     split_off[a, 2], split_off[a, 3])
        s_node[s] = c + 1 if f > split_thr[a] else c


# ----------------------------------------------------------------------------- shards


def sample_pixels(labels: np.ndarray, valid: np.ndarray, n: int,
                  rng: np.random.Generator, background_share: float = 0.0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``n`` pixels of one image, balanced over the classes present.

    labels : (H, W) uint8 class per pixel; valid : (H, W) bool, pixels with a measurement.
    Each class present gets ``n // #classes`` pixels (all of them if it has fewer), drawn
    without replacement; with ``background_share`` > 0 and background and parts both
    present, the background (class 0) gets ``round(n * background_share)`` and the parts
    share the rest equally. Returns flat pixel indices (int64) and their classes (uint8).
    """
    lab = labels.ravel()
    ok = np.flatnonzero(valid.ravel())
    if len(ok) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.uint8)
    cls = lab[ok]
    present = np.unique(cls)
    quota = max(1, n // len(present))
    quotas = dict.fromkeys(present.tolist(), quota)
    if background_share > 0 and len(present) > 1 and present[0] == 0:
        quotas[0] = max(1, round(n * background_share))
        for c in present[1:].tolist():
            quotas[c] = max(1, (n - quotas[0]) // (len(present) - 1))
    picks = []
    for c in present:
        idx = ok[cls == c]
        quota = quotas[int(c)]
        if len(idx) > quota:
            idx = np.sort(rng.choice(idx, size=quota, replace=False))
        picks.append(idx)
    flat = np.concatenate(picks)
    return flat, lab[flat]


class ImageShard:
    """A set of training images and their samples for the tree being grown.

    depth : (M, H, W) uint16 mm; labels : (M, H, W) uint8 (0 = background, k = part k);
    global_ids : (M,) global frame ids (seed streams). The workers of a pool
    (:mod:`vhgen.executor`) are of this class.
    """

    def __init__(self, depth: np.ndarray, labels: np.ndarray, global_ids: Sequence[int],
                 params: TrainParams, stores: Sequence[str] | None = None):
        self.labels = np.ascontiguousarray(labels, dtype=np.uint8)
        self.ids = np.asarray(global_ids, dtype=np.int64)
        where = stores if stores is not None else [None] * len(self.ids)
        self.segmented = np.array([params.segmented_frame(g, s)
                                   for g, s in zip(self.ids, where, strict=True)], bool)
        self.depth = prepare_depth(np.where(self.segmented[:, None, None]
                                            & (self.labels == 0), 0, depth))
        self.params = params
        self.num_classes = 0

    def start_tree(self, tree: int, num_classes: int) -> np.ndarray:
        """Draw this tree's samples; returns their class counts (C,) int64."""
        p = self.params
        h, w = self.depth.shape[1:]
        imgs, xs, ys, labs = [], [], [], []
        for m in range(len(self.ids)):
            rng = np.random.default_rng(np.random.SeedSequence(
                [p.seed, _SAMPLE_STREAM, tree, int(self.ids[m])]))
            flat, lab = sample_pixels(self.labels[m], self.depth[m] != BACKGROUND_MM,
                                      p.pixels_per_image, rng,
                                      0.0 if self.segmented[m] else p.background_share)
            imgs.append(np.full(len(flat), m, np.int32))
            ys.append((flat // w).astype(np.int32))
            xs.append((flat % w).astype(np.int32))
            labs.append(lab)

        def cat(parts: list[np.ndarray], dt: type) -> np.ndarray:
            return np.concatenate(parts).astype(dt) if parts else np.zeros(0, dt)

        self.s_img, self.s_x, self.s_y = cat(imgs, np.int32), cat(xs, np.int32), cat(ys, np.int32)
        self.s_lab = cat(labs, np.uint8)
        if len(self.s_lab) and int(self.s_lab.max()) >= num_classes:
            from vhgen.errors import ForestError

            raise ForestError(f"label {int(self.s_lab.max())} in the training images is "
                              f"outside the scheme's {num_classes - 1} parts")
        self.s_node = np.zeros(len(self.s_lab), np.int32)
        self.num_classes = num_classes
        self._sorted_level = -1
        return np.bincount(self.s_lab, minlength=num_classes).astype(np.int64)

    def _sort(self, num_frontier: int) -> None:
        keep = self.s_node >= 0
        order = np.flatnonzero(keep)[np.argsort(self.s_node[keep], kind="stable")]
        for name in ("s_img", "s_x", "s_y", "s_lab", "s_node"):
            setattr(self, name, getattr(self, name)[order])
        self.starts = np.zeros(num_frontier + 1, np.int64)
        np.cumsum(np.bincount(self.s_node, minlength=num_frontier), out=self.starts[1:])

    def histograms(self, level: int, num_frontier: int, chunk_nodes: np.ndarray,
                   offsets: np.ndarray, thresh: np.ndarray, classmap: np.ndarray,
                   hoff: np.ndarray) -> np.ndarray:
        """Flat int32 counts for a chunk of frontier nodes (layout in :func:`_histograms`)."""
        if self._sorted_level != level:
            self._sort(num_frontier)
            self._sorted_level = level
        out = np.zeros(int(hoff[-1]), dtype=np.int32)
        _histograms(self.depth, self.s_img, self.s_x, self.s_y, self.s_lab, self.starts,
                    chunk_nodes, offsets, thresh, classmap, hoff, out)
        return out

    def route(self, split_off: np.ndarray, split_thr: np.ndarray, child: np.ndarray) -> int:
        """Move every sample to its child's frontier index (-1: its node is a leaf)."""
        _route(self.depth, self.s_img, self.s_x, self.s_y, self.s_node, split_off,
               split_thr, child)
        return int((self.s_node >= 0).sum())


class ShardPool(Protocol):
    """Calls a method on every shard and returns the results in shard order."""

    def map(self, method: str, *args: Any) -> list[Any]: ...


# ----------------------------------------------------------------------------- driver


def _chunks(sizes: np.ndarray, budget_bytes: int) -> list[np.ndarray]:
    """Consecutive index ranges whose int32 histogram sizes fit the budget (>= 1 node)."""
    out: list[np.ndarray] = []
    cur: list[int] = []
    acc = 0
    for i, s in enumerate(sizes):
        if cur and acc + 4 * s > budget_bytes:
            out.append(np.asarray(cur))
            cur, acc = [], 0
        cur.append(i)
        acc += 4 * s
    if cur:
        out.append(np.asarray(cur))
    return out


def grow_tree(pool: ShardPool, tree: int, num_classes: int, params: TrainParams,
              progress: Callable[[str], None] | None = None) -> tuple[dict, list[dict]]:
    """Grow one tree over the shards of ``pool``; returns its node arrays and per-level stats."""
    p = params
    root_counts = np.sum(pool.map("start_tree", tree, num_classes), axis=0)
    if root_counts.sum() == 0:
        from vhgen.errors import ForestError

        raise ForestError("no training pixels: no frame has a pixel with a measurement")
    offsets: list[np.ndarray] = [np.zeros(4, np.int16)]
    thresh: list[int] = [0]
    left: list[int] = [-1]
    depth: list[int] = [0]
    counts: list[np.ndarray] = [root_counts]
    frontier = [0]  # node ids of this level, in frontier order
    stats = []
    level = 0
    while frontier:
        t0 = time.perf_counter()
        fc = np.stack([counts[n] for n in frontier])  # (A, C)
        n_samples = int(fc.sum())
        splittable = [a for a, n in enumerate(frontier)
                      if level < p.depth and fc[a].sum() >= p.min_samples
                      and np.count_nonzero(fc[a]) > 1]
        rng = np.random.default_rng(np.random.SeedSequence(
            [p.seed, _FEATURE_STREAM, tree, level]))
        ncls_all = np.array([np.count_nonzero(fc[a]) for a in splittable], np.int64)
        sizes = ncls_all * p.features * (p.thresholds + 1)
        split_gain = np.zeros(len(splittable))
        split_left = np.zeros((len(splittable), num_classes), np.int64)
        split_off_c = np.zeros((len(splittable), 4), np.int64)
        split_thr_c = np.zeros(len(splittable), np.int32)
        found = np.zeros(len(splittable), bool)
        for chunk in _chunks(sizes, p.hist_budget_mb * 2**20):
            # candidates drawn chunk by chunk from one stream in node order: the same
            # draws whatever the chunking, without holding a whole level's candidates
            nodes = np.asarray([splittable[i] for i in chunk], np.int64)
            cand_off = np.empty((len(chunk), p.features, 4), np.int64)
            cand_thr = np.empty((len(chunk), p.features, p.thresholds), np.int32)
            for b in range(len(chunk)):
                cand_off[b] = draw_offsets(rng, p.features, p.max_offset)
                cand_thr[b] = np.sort(rng.integers(-p.threshold_range, p.threshold_range + 1,
                                                   size=(p.features, p.thresholds)), axis=1)
            classmap = np.zeros((len(chunk), num_classes), np.int64)
            parent = np.zeros((len(chunk), num_classes), np.int64)
            present = []
            for b, a in enumerate(nodes):
                cls = np.flatnonzero(fc[a])
                present.append(cls)
                classmap[b, cls] = np.arange(len(cls))
                parent[b, :len(cls)] = fc[a][cls]
            hoff = np.zeros(len(chunk) + 1, np.int64)
            np.cumsum(sizes[chunk], out=hoff[1:])
            hist = np.zeros(int(hoff[-1]), np.int64)
            for h in pool.map("histograms", level, len(frontier), nodes, cand_off, cand_thr,
                              classmap, hoff):
                hist += h
            bj = np.empty(len(chunk), np.int64)
            bk = np.empty(len(chunk), np.int64)
            bg = np.empty(len(chunk))
            bl = np.zeros((len(chunk), num_classes), np.int64)
            _best_splits(hist, hoff, ncls_all[chunk], parent, p.features, p.thresholds,
                         bj, bk, bg, bl)
            for b, i in enumerate(chunk):
                if bj[b] < 0:
                    continue
                found[i] = True
                split_gain[i] = bg[b]
                split_left[i, present[b]] = bl[b, :len(present[b])]
                split_off_c[i] = cand_off[b, bj[b]]
                split_thr_c[i] = cand_thr[b, bj[b], bk[b]]
        # children in frontier order; samples of leaves leave the training set
        child = np.full(len(frontier), -1, np.int32)
        split_off = np.zeros((len(frontier), 4), np.int64)
        split_thr = np.zeros(len(frontier), np.int32)
        new_frontier = []
        for i, a in enumerate(splittable):
            if not found[i] or split_gain[i] < max(p.min_gain, 1e-12):
                continue
            node = frontier[a]
            off = split_off_c[i]
            thr = int(split_thr_c[i])
            offsets[node], thresh[node] = off.astype(np.int16), thr
            left[node] = len(left)
            lc = split_left[i]
            for cnt in (lc, fc[a] - lc):
                offsets.append(np.zeros(4, np.int16))
                thresh.append(0)
                left.append(-1)
                depth.append(level + 1)
                counts.append(cnt)
                new_frontier.append(len(left) - 1)
            child[a] = len(new_frontier) - 2
            split_off[a], split_thr[a] = off, thr
        remaining = sum(pool.map("route", split_off, split_thr, child))
        secs = time.perf_counter() - t0
        stats.append({"level": level, "nodes": len(frontier), "split": int((child >= 0).sum()),
                      "samples": n_samples, "seconds": round(secs, 3)})
        if progress is not None:
            progress(f"tree {tree + 1}/{p.trees} level {level:2d}: {len(frontier):6d} nodes, "
                     f"{int((child >= 0).sum()):6d} split, {n_samples:9d} samples, "
                     f"{secs:7.2f} s")
        if remaining != sum(int(counts[n].sum()) for n in new_frontier):
            raise RuntimeError("sample routing disagrees with the split histograms")
        frontier = new_frontier
        level += 1
    arrays = {"offsets": np.stack(offsets).astype(np.int16),
              "thresh": np.asarray(thresh, np.int32), "left": np.asarray(left, np.int32),
              "depth": np.asarray(depth, np.int16), "counts": np.stack(counts).astype(np.int64)}
    return arrays, stats


def grow_forest(pool: ShardPool, num_classes: int, params: TrainParams, meta: dict,
                progress: Callable[[str], None] | None = None) -> Forest:
    """All trees of a forest over one shard pool; per-level/per-tree times go into meta."""
    params.check()
    parts, roots, tree_stats = [], [], []
    n = 0
    for t in range(params.trees):
        t0 = time.perf_counter()
        arrays, stats = grow_tree(pool, t, num_classes, params, progress)
        arrays["left"] = np.where(arrays["left"] >= 0, arrays["left"] + n, -1).astype(np.int32)
        roots.append(n)
        n += len(arrays["left"])
        parts.append(arrays)
        tree_stats.append({"tree": t, "seconds": round(time.perf_counter() - t0, 3),
                           "nodes": len(arrays["left"]),
                           "depth": int(arrays["depth"].max()), "levels": stats})
    cat = {k: np.concatenate([a[k] for a in parts]) for k in parts[0]}
    meta = {**meta, "params": asdict(params), "trees": tree_stats}
    return Forest(cat["offsets"], cat["thresh"], cat["left"], cat["depth"], cat["counts"],
                  np.asarray(roots, np.int64), meta)
