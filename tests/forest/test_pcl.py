"""PCL gpu/people text trees: export, read back, label exactly as our own format does."""

from __future__ import annotations

import numpy as np
import pytest

from tests.forest.conftest import two_boxes
from vhgen.errors import ForestError
from vhgen.executor import InlinePool
from vhgen.forest.pcl import (
    PCL_BACKGROUND,
    PCL_PART_NAMES,
    export_pcl,
    from_pcl_label,
    load_pcl_forest,
    pcl_tree_labels,
    read_pcl_tree,
    to_pcl_label,
)
from vhgen.forest.train import ImageShard, TrainParams, grow_forest
from vhgen.forest.trees import Predictor


def pcl25_forest(min_samples: int):
    d, lab = two_boxes(16, seed=11)
    # move the parts to pcl25 labels 5 (Rfoot) and 25 (Lchest): the k - 1 mapping shows
    lab = np.where(lab == 1, 5, np.where(lab == 2, 25, 0)).astype(np.uint8)
    # noise so that trees stop at different depths (padding is exercised)
    rng = np.random.default_rng(0)
    d = np.where(d > 0, d + rng.integers(0, 300, d.shape), 0).astype(np.uint16)
    p = TrainParams(trees=3, depth=7, pixels_per_image=250, features=40, thresholds=10,
                    seed=2, max_offset=60, min_samples=min_samples)
    f = grow_forest(InlinePool.holding([ImageShard(d, lab, range(16), p)]), 26, p,
                    {"label_scheme": "pcl25", "label_names": list(PCL_PART_NAMES), "fx": 525.0})
    return f, d


@pytest.mark.parametrize("min_samples", [2, 60])
def test_round_trip_same_labels(tmp_path, min_samples):
    forest, train_depth = pcl25_forest(min_samples)
    paths = export_pcl(forest, tmp_path / "pcl")
    assert [p.name for p in paths] == ["tree_0.txt", "tree_1.txt", "tree_2.txt"]
    test_depth, _ = two_boxes(4, seed=12)
    frames = np.concatenate([train_depth[:3], test_depth])
    frames[0, :3, :] = 0  # no-measurement rows
    ours = Predictor(forest)
    early_leaf = False
    for t, path in enumerate(paths):
        h, nodes, leaves = tree = read_pcl_tree(path)
        assert len(nodes) == 2**h - 1 and len(leaves) == 2**h
        lines = path.read_text().splitlines()
        assert len(lines) == 1 + 2**h - 1 + 2**h and len(lines[1].split()) == 5
        sl = forest.tree_slice(t)
        early_leaf |= bool(((forest.left[sl] < 0) & (forest.depth[sl] < h)).any())
        for d in frames:
            pcl = pcl_tree_labels(d, tree)
            mine = ours.tree_labels(d, t)
            np.testing.assert_array_equal(pcl, to_pcl_label(mine) * (d > 0) +
                                          PCL_BACKGROUND * (d == 0))
            assert set(np.unique(pcl[d > 0])) <= {4, 24}
    assert early_leaf  # the trees were padded
    # read back as a forest: every tree labels as ours
    back = load_pcl_forest(tmp_path / "pcl")
    assert back.num_trees == 3
    back_pred = Predictor(back)
    for t in range(3):
        for d in frames:
            np.testing.assert_array_equal(back_pred.tree_labels(d, t), ours.tree_labels(d, t))


def test_label_maps():
    assert to_pcl_label(np.array([0, 1, 25])).tolist() == [29, 0, 24]
    assert from_pcl_label(np.array([29, 0, 24, 31])).tolist() == [0, 1, 25, 0]


def test_export_needs_pcl25(tmp_path):
    forest, _ = pcl25_forest(60)
    forest.meta["label_names"] = ["x"] * 31
    forest.meta["label_scheme"] = "shotton31"
    with pytest.raises(ForestError, match="label scheme mismatch"):
        export_pcl(forest, tmp_path)


def test_truncated_pcl_file(tmp_path):
    p = tmp_path / "t.txt"
    p.write_text("3\n1 2 3 4 5\n")
    with pytest.raises(ForestError, match="t.txt: truncated"):
        read_pcl_tree(p)
