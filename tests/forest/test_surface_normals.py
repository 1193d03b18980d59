"""Surface normals of a candidate (vhgen.geom.normals): what the person stage reads of a
candidate's shape, checked on surfaces whose normals are known, near and far, with the
sensor's quantisation steps."""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.geom.normals import patch_normals, surface_shares

FX = 575.8
UP = np.array([0.0, -1.0, 0.0])  # the camera's up, level camera


def _points(z: np.ndarray) -> np.ndarray:
    h, w = z.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([(u - w / 2) / FX * z, (v - h / 2) / FX * z, z], -1)


def _quantised(z: np.ndarray) -> np.ndarray:
    """Depth rounded to the real sensor's steps (2.9 mm per m^2, docs/realism.md)."""
    step = 0.0029 * z * z
    return np.round(z / step) * step


@pytest.mark.parametrize("z0", [1.0, 2.5, 4.5])
def test_a_wall_facing_the_camera_is_flat_and_upright_at_any_distance(z0):
    z = _quantised(np.full((240, 240), z0))
    n = patch_normals(_points(z), np.ones(z.shape, bool), FX)
    assert len(n) > 1000 and np.isfinite(n).all()
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert (n[:, 2] < 0).all()  # towards the camera
    smooth, flat, upright, level = surface_shares(n, UP, z.size)
    assert flat > 0.95 and upright > 0.95 and level == 0.0
    assert 0.5 < smooth <= 1.0


def test_a_floor_is_level_and_a_slanted_plane_neither():
    h, w = 200, 300
    v, _ = np.mgrid[0:h, 0:w].astype(np.float64)
    # the floor 1.2 m below a level camera, seen in the lower half: y = 1.2, z = fy*1.2/(v-c)
    ys = v + 10.0  # rows below the horizon
    floor = 1.2 * FX / ys
    n = patch_normals(_points(floor) * [1, 0, 1] + [0, 1.2, 0], floor < 6.0, FX)
    smooth, flat, upright, level = surface_shares(n, UP, h * w)
    assert level > 0.95 and upright == 0.0 and flat > 0.95
    # a plane turned 45 deg about the camera's x axis: neither level nor upright
    z = 2.0 + 0.0 * v
    p = _points(z)
    p[..., 2] += p[..., 1]  # z = 2 + y: normal (0, 1, -1)/sqrt 2
    n = patch_normals(p, np.ones((h, w), bool), FX)
    _, flat, upright, level = surface_shares(n, UP, h * w)
    assert flat > 0.95 and upright < 0.05 and level < 0.05


def test_a_rounded_body_is_less_flat_than_a_board():
    h, w = 300, 240
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    x = (u - w / 2) / FX * 2.0
    r = 0.16  # a torso's half depth
    inside = np.abs(x) < 0.95 * r
    z = _quantised(2.2 - np.sqrt(np.clip(r * r - x * x, 0.0, None)))
    n = patch_normals(_points(z), inside, FX)
    _, flat_body, upright, _ = surface_shares(n, UP, int(inside.sum()))
    board = _quantised(np.full((h, w), 2.0))
    _, flat_board, _, _ = surface_shares(patch_normals(_points(board), inside, FX), UP,
                                         int(inside.sum()))
    assert upright > 0.95  # a vertical cylinder faces sideways everywhere
    assert flat_body < 0.8 < 0.95 < flat_board


def test_thin_and_tiny_patches_have_no_normals_and_no_nan():
    z = np.full((100, 100), 3.0)
    pole = np.zeros(z.shape, bool)
    pole[:, 50:53] = True  # 3 px: 4.7 cm at 3 m, thinner than the 5 cm patch
    n = patch_normals(_points(z), pole, FX)
    assert n.shape == (0, 3)
    assert surface_shares(n, UP, int(pole.sum())) == (0.0, 0.0, 0.0, 0.0)
    assert patch_normals(_points(z), np.zeros(z.shape, bool), FX).shape == (0, 3)
    one = np.zeros(z.shape, bool)
    one[10, 10] = True
    assert patch_normals(_points(z), one, FX).shape == (0, 3)


def test_candidates_get_surface_columns_and_a_stage_of_before_reads_its_own(tmp_path):
    """A room's candidates (flat-fronted boxes here) get their surface shares; a stage
    trained before the surface features, saved and loaded, decides on its own columns
    only, exactly as it did."""
    from tests.forest.test_person_stage import INTR, candidates, room
    from vhgen.forest.person_stage import PersonStage
    from vhgen.forest.segment import FEATURES, PART_FEATURES, SURFACE_FEATURES, Segmenter
    from vhgen.forest.trees import Forest

    x, y = candidates(range(8), vote=0.6)
    before = tuple(f for f in FEATURES if f not in SURFACE_FEATURES + PART_FEATURES)
    cols = [FEATURES.index(f) for f in before]
    old = PersonStage.fit(x[:, cols], y, before, trees=4, seed=1)
    f = Forest(np.zeros((1, 4), np.int16), np.zeros(1, np.int32), np.full(1, -1, np.int32),
               np.zeros(1, np.int16), np.ones((1, 3), np.int64), np.zeros(1, np.int64),
               {"label_names": ["a", "b"]}, old)
    back = Forest.load(f.save(tmp_path / "old.npz")).person_stage
    assert back is not None and back.features == before
    depth, labels, _ = room(5)
    seg = Segmenter(min_pixels=50)
    _, person = seg.people(depth, INTR, labels, back)
    _, feats = seg.features(depth, INTR, labels)
    rows = feats[~np.isnan(feats).any(1)]
    surface = rows[:, [FEATURES.index(s) for s in SURFACE_FEATURES]]
    assert len(rows) >= 2 and ((surface >= 0) & (surface <= 1)).all()
    # the boxes' fronts face the camera: measured, flat and upright
    assert (surface[:, 0] > 0.2).all() and (surface[:, 2] > 0.5).all()
    np.testing.assert_array_equal(
        person, seg.stage_calls(feats, back.predict_proba(feats[:, cols])))
