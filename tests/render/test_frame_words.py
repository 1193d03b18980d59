"""The one-pass decoding of a frame's GL sensor words against the reference
(``sensor_output``, then ``unpack_ids``): the same arrays, hole counts and valid pixels."""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.render.frame_words import decode
from vhgen.render.sensor_gl import sensor_output
from vhgen.scene.geometry import id_bytes, unpack_ids
from vhgen.sensor.state import HOLE_CAUSES


def _words(rng, h, w, causes):
    """Made-up output words: depth 0-65535 mm with holes, any raw value, flags of the
    ``causes`` (indexes) on holes, disparity, packed ids; view ids as the renderer's
    float32."""
    n = h * w
    mm = rng.integers(0, 65536, n, dtype=np.uint32)
    mm[rng.random(n) < 0.3] = 0
    out = mm | (rng.integers(0, 2048, n, dtype=np.uint32) << 16)
    flags = np.where(mm > 0, np.uint32(1), np.uint32(0))
    holes = np.flatnonzero(mm == 0)
    if causes:
        flags[holes] = np.uint32(2) << rng.choice(np.asarray(causes, np.uint32), len(holes))
    disp = rng.random(n, dtype=np.float32)
    ids = rng.integers(0, 2**24, n, dtype=np.uint32)
    view_ids = rng.integers(0, 2**24, n, dtype=np.uint32).astype(np.float32)
    return np.concatenate([out, flags, disp.view(np.uint32), ids]), view_ids


@pytest.mark.parametrize("raw11", [True, False])
@pytest.mark.parametrize("causes", [(), (0,), (0, 3, 9), tuple(range(len(HOLE_CAUSES)))])
def test_decode_is_the_reference(raw11, causes):
    h, w = 30, 40
    words, view_ids = _words(np.random.default_rng(len(causes) + 10 * raw11), h, w, causes)
    got = decode(words, view_ids, h, w, raw11)
    q = words.reshape(4, h, w)
    ref = sensor_output(q[0], q[1], q[2].view(np.float32), q[3], np.dtype(np.uint32), raw11)
    labels, instances, classes = unpack_ids(ref.labels)
    for name, a, b in (("depth_mm", got.depth_mm, ref.depth_mm), ("labels", got.labels, labels),
                       ("instances", got.instances, instances),
                       ("classes", got.classes, classes),
                       ("view_instances", got.view_instances,
                        id_bytes(view_ids.reshape(h, w).astype(np.uint32))[..., 1])):
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert (got.raw11 is None) == (not raw11)
    if raw11:
        np.testing.assert_array_equal(got.raw11, ref.raw11)
    assert got.holes == ref.holes and list(got.holes) == list(ref.holes)
    assert got.valid_pixels == int(ref.valid.sum())
    assert set(got.holes) == {"no_hit"} | {HOLE_CAUSES[c] for c in causes}
