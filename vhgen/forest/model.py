"""The forest as arrays, its file format (.npz + JSON metadata) and the inference kernel.

A tree is stored sparse, breadth first: node ``i`` has a feature ``offsets[i]`` (du1, dv1,
du2, dv2 int16 pixel-metres), a threshold ``thresh[i]`` (int32 millimetres, within int16
as PCL stores it), ``left[i]`` (index of its left child, right child = left + 1, -1 for a
leaf), ``depth[i]`` and ``counts[i]`` (training samples per class at the node, class 0 =
background, k = part k). The forest concatenates its trees; ``roots[t]`` is the first node
of tree t. Prediction averages the normalised leaf histograms over trees and takes the
argmax (Shotton et al. 2011, eq. 2), ties to the lowest class.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np

from vhgen.errors import ForestError
from vhgen.forest.features import BACKGROUND_MM, FOCAL_SCALE, prepare_depth

FORMAT = "vhgen-forest"
FORMAT_VERSION = 1


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

    @property
    def num_trees(self) -> int:
        return len(self.roots)

    @property
    def num_classes(self) -> int:
        return int(self.counts.shape[1])

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
        np.savez_compressed(path, offsets=self.offsets, thresh=self.thresh, left=self.left,
                            depth=self.depth, counts=self.counts, roots=self.roots,
                            meta=np.array(json.dumps(meta)))
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
        except (OSError, ValueError, KeyError) as e:
            raise ForestError(f"{path}: not a vhgen forest file ({e})") from None
        if meta.get("format") != FORMAT:
            raise ForestError(f"{path}: not a vhgen forest file (format {meta.get('format')!r})")
        return cls(meta=meta, **arrays)


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


_BLOCK = 32  # pixels walked in lockstep: their dependency chains overlap in the CPU


@numba.njit(inline="always")
def _lo16(v):
    return ((v & 0xFFFF) ^ 0x8000) - 0x8000  # the low int16 of an int32, sign-extended


@numba.njit(inline="always")
def _hi16(v):
    return v >> 16  # arithmetic shift: the high int16, sign-extended


@numba.njit(cache=True)
def _predict_frame(img, nodes, roots, prob, out):
    """nodes: (N, 4) int32 rows (du1 | dv1 << 16, du2 | dv2 << 16, thresh, left): 16 bytes,
    four nodes per cache line. One tree at a time over all pixels (its nodes stay in cache),
    pixels in blocks of _BLOCK walked in lockstep: one pixel's walk is a chain of dependent
    loads (latency bound), independent pixels fill the pipeline."""
    h, w = img.shape
    c = prob.shape[1]
    nt = roots.shape[0]
    npix = 0
    for y in range(h):
        for x in range(w):
            if img[y, x] == BACKGROUND_MM:
                out[y, x] = 0
            else:
                npix += 1
    ys = np.empty(npix, np.int64)
    xs = np.empty(npix, np.int64)
    fys = np.empty(npix, np.float64)
    fxs = np.empty(npix, np.float64)
    scale = np.empty(npix, np.float64)
    k = 0
    for y in range(h):
        for x in range(w):
            if img[y, x] != BACKGROUND_MM:
                ys[k] = y
                xs[k] = x
                fys[k] = y
                fxs[k] = x
                scale[k] = FOCAL_SCALE / np.float64(img[y, x])
                k += 1
    leaf = np.empty((nt, npix), np.int64)
    for t in range(nt):
        node = leaf[t]
        for b0 in range(0, npix, _BLOCK):
            nb = min(_BLOCK, npix - b0)
            for p in range(b0, b0 + nb):
                node[p] = roots[t]
            active = nb
            while active > 0:
                active = 0
                for p in range(b0, b0 + nb):
                    n = node[p]
                    lft = nodes[n, 3]
                    if lft < 0:
                        continue
                    active += 1
                    x = fxs[p]
                    y = fys[p]
                    s = scale[p]
                    o1 = nodes[n, 0]
                    o2 = nodes[n, 1]
                    # same arithmetic as features._probe64 (PCL trees.cpp runThroughTree)
                    u1 = np.uint64(min(max(int(np.float32(x + _lo16(o1) * s)), 0), w - 1))
                    v1 = np.uint64(min(max(int(np.float32(y + _hi16(o1) * s)), 0), h - 1))
                    u2 = np.uint64(min(max(int(np.float32(x + _lo16(o2) * s)), 0), w - 1))
                    v2 = np.uint64(min(max(int(np.float32(y + _hi16(o2) * s)), 0), h - 1))
                    f = np.int32(img[v1, u1]) - np.int32(img[v2, u2])
                    node[p] = lft + 1 if f > nodes[n, 2] else lft
    acc = np.zeros(c, np.float32)
    for p in range(npix):
        acc[:] = prob[leaf[0, p]]
        for t in range(1, nt):
            for q in range(c):
                acc[q] += prob[leaf[t, p], q]
        best = 0
        for q in range(1, c):
            if acc[q] > acc[best]:
                best = q
        out[ys[p], xs[p]] = best


@numba.njit(parallel=True, cache=True)
def _predict_batch(imgs, nodes, roots, prob, out):
    for i in numba.prange(imgs.shape[0]):
        _predict_frame(imgs[i], nodes, roots, prob, out[i])


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


class Predictor:
    """Compiled per-pixel labelling with one forest (arrays prepared once)."""

    def __init__(self, forest: Forest):
        self.forest = forest
        self._offsets = np.ascontiguousarray(forest.offsets, dtype=np.int64)
        self._thresh = np.ascontiguousarray(forest.thresh, dtype=np.int32)
        self._left = np.ascontiguousarray(forest.left, dtype=np.int64)
        self._roots = np.ascontiguousarray(forest.roots, dtype=np.int64)
        self._prob = forest.probabilities()
        off = forest.offsets.astype(np.int32)
        nodes = np.empty((len(forest.left), 4), np.int32)
        nodes[:, 0] = (off[:, 0] & 0xFFFF) | (off[:, 1] << 16)
        nodes[:, 1] = (off[:, 2] & 0xFFFF) | (off[:, 3] << 16)
        nodes[:, 2] = forest.thresh
        nodes[:, 3] = forest.left
        self._nodes = nodes

    def predict(self, depth: np.ndarray, prepared: bool = False) -> np.ndarray:
        """Labels of one frame (H, W) or a batch (N, H, W) of uint16 mm depth -> uint8.

        0 = background: no measurement, or the forest says background. A single frame runs
        serially (one core); a batch runs frames in parallel over numba threads.
        """
        d = np.ascontiguousarray(depth, dtype=np.uint16) if prepared else prepare_depth(depth)
        out = np.empty(d.shape, dtype=np.uint8)
        if d.ndim == 2:
            _predict_frame(d, self._nodes, self._roots, self._prob, out)
        elif d.ndim == 3:
            _predict_batch(d, self._nodes, self._roots, self._prob, out)
        else:
            raise ValueError(f"depth must be (H, W) or (N, H, W), got {d.shape}")
        return out

    def tree_labels(self, depth: np.ndarray, tree: int) -> np.ndarray:
        """(H, W) uint8: what tree ``tree`` alone outputs (argmax of its leaf), 0 where
        there is no measurement; the per-tree labelling PCL computes before its vote."""
        d = prepare_depth(depth)
        out = np.empty(d.shape, dtype=np.uint8)
        _tree_labels(d, self._offsets, self._thresh, self._left, int(self._roots[tree]),
                     self.forest.leaf_labels(), out)
        return out


def truncate(forest: Forest, depth: int) -> Forest:
    """The forest cut at ``depth``: nodes at that depth become leaves (their training
    histograms kept). Level-wise growth draws the same samples and candidates per level
    whatever the depth limit, so this IS the forest trained with ``--depth depth``
    (up to the min-gain/min-samples stops, which do not depend on the limit)."""
    left = np.where(forest.depth >= depth, -1, forest.left).astype(np.int32)
    return Forest(forest.offsets, forest.thresh, left, forest.depth, forest.counts,
                  forest.roots, {**forest.meta, "truncated_depth": depth})


def first_trees(forest: Forest, k: int) -> Forest:
    """The first ``k`` trees (trees are grown independently: same as ``--trees k``)."""
    end = forest.tree_slice(k - 1).stop
    return Forest(forest.offsets[:end], forest.thresh[:end], forest.left[:end],
                  forest.depth[:end], forest.counts[:end], forest.roots[:k],
                  {**forest.meta, "trees_used": k})
