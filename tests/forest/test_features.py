"""The depth-comparison feature against a slow obvious reference of PCL's evaluator."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vhgen.forest.features import (
    BACKGROUND_MM,
    draw_offsets,
    evaluate_features,
    prepare_depth,
)


def reference_feature(img: np.ndarray, x: int, y: int, off, precision: str) -> int:
    """PCL trees.cpp runThroughTree (float64) / multi_tree.cu evaluateTree (float32), in
    plain Python: probe = trunc/floor of x + du * 1000 / d(x), clamped into the image."""
    h, w = img.shape
    d0 = int(img[y, x])

    def probe(du: int, dv: int) -> int:
        if precision == "float64":
            scale = 1000.0 / d0
            u = int(np.float32(x + du * scale))  # double -> float -> int, as the C++ casts
            v = int(np.float32(y + dv * scale))
        else:
            s32 = np.float32(1000.0) / np.float32(d0)
            u = math.floor(np.float32(x) + np.float32(du) * s32)
            v = math.floor(np.float32(y) + np.float32(dv) * s32)
        u = min(max(u, 0), w - 1)
        v = min(max(v, 0), h - 1)
        return int(img[v, u])

    return probe(off[0], off[1]) - probe(off[2], off[3])


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_features_match_reference(precision):
    rng = np.random.default_rng(7)
    h, w = 30, 40
    depth = rng.integers(500, 4000, size=(3, h, w)).astype(np.uint16)
    depth[:, :, :5] = 0  # no measurement at the left edge
    depth[0, 10:20, 10:20] = 0  # a hole
    d = prepare_depth(depth)
    valid = np.argwhere(d != BACKGROUND_MM)
    pick = valid[rng.choice(len(valid), 200, replace=False)]
    # include the image corners' neighbourhoods so probes leave the image on every side
    corners = np.array([[i, y, x] for i in range(3) for y, x in
                        [(0, 5), (0, w - 1), (h - 1, 5), (h - 1, w - 1)]])
    pick = np.concatenate([pick, corners])
    off = draw_offsets(rng, 40, max_offset=400)
    off[0] = [0, 0, 0, 0]
    off[1] = [-32768 // 2, 0, 0, 32767 // 2]  # far outside: clamped to the border
    got = evaluate_features(d, pick[:, 0], pick[:, 2], pick[:, 1], off, precision=precision)
    ref = np.array([[reference_feature(d[i], x, y, o, precision) for o in off]
                    for i, y, x in pick])
    np.testing.assert_array_equal(got, ref)
    assert (got[:, 0] == 0).all()
    # probes that land on background read 65535: feature values that large must occur
    assert (np.abs(got) > 60000).any()


def test_background_and_zero_depth_read_as_large_constant():
    depth = np.zeros((1, 5, 5), np.uint16)
    depth[0, 2, 2] = 1000
    d = prepare_depth(depth)
    assert d[0, 0, 0] == BACKGROUND_MM == 65535 and d[0, 2, 2] == 1000
    assert depth[0, 0, 0] == 0  # input not modified
    # one pixel to the right at 1 m is 1 pixel-metre: background minus self
    f = evaluate_features(d, [0], [2], [2], np.array([[1, 0, 0, 0], [0, 0, 0, 0]]))
    assert f.tolist() == [[65535 - 1000, 0]]


def test_offsets_scale_with_depth():
    """u pixel-metres move u pixels at 1 m and u/2 at 2 m (PCL scale = 1000 / depth mm)."""
    row = np.arange(100, dtype=np.uint16) * 10 + 1000
    near = np.tile(row, (3, 1))[None]
    near[0, 1, 50] = 1000  # the pixel itself at 1 m
    far = near.copy()
    far[0, 1, 50] = 2000  # now at 2 m; its neighbours as before
    f1 = evaluate_features(near, [0], [50], [1], np.array([[10, 0, 0, 0]]))
    f2 = evaluate_features(far, [0], [50], [1], np.array([[10, 0, 0, 0]]))
    assert f1[0, 0] == int(near[0, 1, 60]) - 1000
    assert f2[0, 0] == int(far[0, 1, 55]) - 2000


def test_precision_argument_checked():
    with pytest.raises(ValueError, match="precision"):
        evaluate_features(np.ones((1, 2, 2), np.uint16), [0], [0], [0],
                          np.zeros((1, 4), int), precision="float16")
