"""PCL gpu/people tree text format: export our trees, read PCL trees back, label like PCL.

Format (pcl/gpu/people/include/pcl/gpu/people/tree.h, ``loadTree`` in src/trees.cpp)::

    TreeHeight
    du1 dv1 du2 dv2 thresh      <- 2^h - 1 node lines, complete binary tree, breadth first
    ...
    label                       <- 2^h leaf lines
    ...

Node ``i`` has children ``2i+1`` (test false) and ``2i+2`` (test ``d1 - d2 > thresh``);
leaves are indexed ``nid - (2^h - 1)``. Offsets are int16 pixel-metres and thresholds int16
millimetres (``Attrib``), read with scale = 1000 / depth mm (``trees::focal``). Leaf labels are
PCL ``part_t`` (label_common.h): our ``pcl25`` label k is PCL part k - 1, background is 29.

A tree that stopped early is padded to the complete height: under a leaf every node is
``0 0 0 0 0`` (f = d(x) - d(x) = 0, never > 0, always left) and every leaf below it carries
its label, so the padded tree labels every pixel as the sparse one does.
"""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np

from vhgen.errors import ForestError
from vhgen.forest.features import BACKGROUND_MM, FOCAL_SCALE, prepare_depth
from vhgen.forest.trees import Forest

PCL_BACKGROUND = 29  # label_common.h: Background = 29
PCL_NUM_PARTS = 25
PCL_PART_NAMES = ("Lfoot", "Lleg", "Lknee", "Lthigh", "Rfoot", "Rleg", "Rknee", "Rthigh",
                  "Rhips", "Lhips", "Neck", "Rarm", "Relbow", "Rforearm", "Rhand", "Larm",
                  "Lelbow", "Lforearm", "Lhand", "FaceLB", "FaceRB", "FaceLT", "FaceRT",
                  "Rchest", "Lchest")


def to_pcl_label(classes: np.ndarray) -> np.ndarray:
    """Our pcl25 classes (0 = background, k = part k) -> PCL part_t (k - 1; 29 background)."""
    c = np.asarray(classes, dtype=np.int64)
    return np.where(c == 0, PCL_BACKGROUND, c - 1).astype(np.uint8)


def from_pcl_label(labels: np.ndarray) -> np.ndarray:
    """PCL part_t -> our pcl25 classes; anything that is not a part (29, 31...) -> 0."""
    lab = np.asarray(labels, dtype=np.int64)
    return np.where(lab < PCL_NUM_PARTS, lab + 1, 0).astype(np.uint8)


def complete_tree(forest: Forest, tree: int) -> tuple[int, np.ndarray, np.ndarray]:
    """One tree as PCL's complete arrays: (height, nodes (2^h-1, 5) int16, leaves (2^h,)
    our class per leaf), padded under early leaves as the module docstring says."""
    sl = forest.tree_slice(tree)
    left = forest.left[sl].astype(np.int64)
    left = np.where(left >= 0, left - sl.start, -1)
    offsets, thresh = forest.offsets[sl], forest.thresh[sl]
    labels = forest.leaf_labels()[sl]
    height = max(int(forest.depth[sl].max()), 1)
    if height > 24:
        raise ForestError(f"tree {tree} has depth {height}; PCL's complete format would need "
                          f"2^{height} lines")
    node_rows = []
    cur = np.zeros(1, np.int64)  # our node at each complete position of this level
    for _ in range(height):
        internal = left[cur] >= 0
        rows = np.zeros((len(cur), 5), np.int64)
        rows[internal, :4] = offsets[cur[internal]]
        rows[internal, 4] = thresh[cur[internal]]
        node_rows.append(rows)
        nxt = np.empty(2 * len(cur), np.int64)
        nxt[0::2] = np.where(internal, left[cur], cur)
        nxt[1::2] = np.where(internal, left[cur] + 1, cur)
        cur = nxt
    nodes = np.concatenate(node_rows)
    if np.abs(nodes).max(initial=0) > 32767:
        raise ForestError(f"tree {tree}: a value does not fit PCL's int16 Attrib")
    return height, nodes.astype(np.int16), labels[cur]


def check_pcl_scheme(forest: Forest) -> None:
    """PCL's leaves are its 25 parts: the forest must be trained on the pcl25 scheme."""
    names = tuple(forest.meta.get("label_names", ()))
    if names != PCL_PART_NAMES:
        raise ForestError(f"label scheme mismatch: PCL export needs a forest trained on "
                          f"`labels: pcl25` frames, this one has scheme "
                          f"{forest.meta.get('label_scheme')!r} ({len(names)} parts)")


def export_pcl(forest: Forest, out_dir: str | Path) -> list[Path]:
    """Write ``tree_<t>.txt`` per tree in PCL's text format; returns the paths."""
    check_pcl_scheme(forest)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for t in range(forest.num_trees):
        height, nodes, leaves = complete_tree(forest, t)
        lines = [str(height)]
        lines += [" ".join(map(str, r)) for r in nodes.tolist()]
        lines += [str(v) for v in to_pcl_label(leaves).tolist()]
        path = out / f"tree_{t}.txt"
        path.write_text("\n".join(lines) + "\n")
        paths.append(path)
    return paths


def read_pcl_tree(path: str | Path) -> tuple[int, np.ndarray, np.ndarray]:
    """Parse one PCL tree file -> (height, nodes (2^h-1, 5) int64, leaves (2^h,) PCL labels).

    Whitespace-separated integers as ``loadTree`` reads them with ``operator>>``.
    """
    path = Path(path)
    try:
        tokens = np.array(path.read_text().split(), dtype=np.int64)
    except (OSError, ValueError) as e:
        raise ForestError(f"{path}: not a PCL tree file ({e})") from None
    if len(tokens) == 0:
        raise ForestError(f"{path}: empty PCL tree file")
    h = int(tokens[0])
    if not 1 <= h <= 30:
        raise ForestError(f"{path}: tree height {h} out of range")
    n_nodes, n_leaves = (1 << h) - 1, 1 << h
    if len(tokens) < 1 + 5 * n_nodes + n_leaves:
        raise ForestError(f"{path}: truncated: height {h} needs {n_nodes} node lines and "
                          f"{n_leaves} leaves")
    nodes = tokens[1:1 + 5 * n_nodes].reshape(n_nodes, 5)
    leaves = tokens[1 + 5 * n_nodes:1 + 5 * n_nodes + n_leaves]
    return h, nodes, leaves


@numba.njit(cache=True)
def _run_through_tree(height, nodes, leaves, dmap, lmap, nolabel):
    # pcl::gpu::people::trees::runThroughTree (src/trees.cpp), statement by statement
    h, w = dmap.shape
    num_nodes = (1 << height) - 1
    for y in range(h):
        for x in range(w):
            depth = dmap[y, x]
            if depth == BACKGROUND_MM:
                lmap[y, x] = nolabel
                continue
            scale = FOCAL_SCALE / np.float64(depth)
            nid = 0
            for _ in range(height):
                u1 = min(max(int(np.float32(x + nodes[nid, 0] * scale)), 0), w - 1)
                v1 = min(max(int(np.float32(y + nodes[nid, 1] * scale)), 0), h - 1)
                u2 = min(max(int(np.float32(x + nodes[nid, 2] * scale)), 0), w - 1)
                v2 = min(max(int(np.float32(y + nodes[nid, 3] * scale)), 0), h - 1)
                delta = np.int32(dmap[v1, u1]) - np.int32(dmap[v2, u2])
                nid = nid * 2 + 2 if delta > nodes[nid, 4] else nid * 2 + 1
            lmap[y, x] = leaves[nid - num_nodes]


def pcl_tree_labels(depth: np.ndarray, tree: tuple[int, np.ndarray, np.ndarray]) -> np.ndarray:
    """Run one PCL-format tree on a (H, W) uint16 mm depth image (0 = no measurement) ->
    (H, W) uint8 PCL part labels, 29 (Background) where there is no measurement."""
    height, nodes, leaves = tree
    d = prepare_depth(depth)
    out = np.empty(d.shape, np.uint8)
    _run_through_tree(int(height), np.ascontiguousarray(nodes, np.int64),
                      np.ascontiguousarray(leaves, np.int64), d, out, PCL_BACKGROUND)
    return out


def pcl_tree_files(path: str | Path) -> list[Path]:
    """The tree files of a PCL export directory (tree_*.txt, else *.txt), sorted."""
    p = Path(path)
    if p.is_file():
        return [p]
    files = sorted(p.glob("tree_*.txt")) or sorted(p.glob("*.txt"))
    if not files:
        raise ForestError(f"{p}: no PCL tree files (*.txt)")
    return files


def load_pcl_forest(path: str | Path, fx: float | None = None) -> Forest:
    """PCL tree files (a directory or one file) as a :class:`Forest` in the pcl25 scheme.

    Each complete tree becomes our sparse layout with one-hot leaf histograms, so it labels
    every pixel as PCL's ``runThroughTree`` does; the forest averages trees as ours do.
    ``fx``: the focal length the trees were trained for (PCL files do not record it).
    """
    parts = []
    n = 0
    roots = []
    for f in pcl_tree_files(path):
        h, nodes, leaves = read_pcl_tree(f)
        nn = len(nodes)
        idx = np.arange(nn + len(leaves))
        left = np.where(idx < nn, 2 * idx + 1 + n, -1)
        depth = np.floor(np.log2(idx + 1)).astype(np.int16)
        offsets = np.zeros((len(idx), 4), np.int16)
        offsets[:nn] = nodes[:, :4]
        thresh = np.zeros(len(idx), np.int32)
        thresh[:nn] = nodes[:, 4]
        counts = np.zeros((len(idx), PCL_NUM_PARTS + 1), np.int64)
        counts[np.arange(nn, len(idx)), from_pcl_label(leaves)] = 1
        counts[:nn, 0] = 0
        parts.append((offsets, thresh, left.astype(np.int32), depth, counts))
        roots.append(n)
        n += len(idx)
    cat = [np.concatenate([p[i] for p in parts]) for i in range(5)]
    meta = {"label_scheme": "pcl25", "label_names": list(PCL_PART_NAMES), "fx": fx, "fy": fx,
            "source": f"PCL tree files {Path(path)}"}
    return Forest(offsets=cat[0], thresh=cat[1], left=cat[2], depth=cat[3], counts=cat[4],
                  roots=np.asarray(roots, np.int64), meta=meta)
