"""The sensor over a real background (vhgen.sensor.composite): synthetic frames with known
answers. A "real" frame (a wall with holes, measured once by the sensor) and a synthetic
box in front of it: real pixels out of the box's reach keep their bytes, the box's
projector shadow falls on the real wall with the width f b (1/z_near - 1/z_far), and a
sensor that changes nothing but the box leaves every real pixel as it was."""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.sensor.composite import REAL_HOLE, reach_px, real_depth_m, simulate_over_real
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.sensor_kernels import encode_raw11
from vhgen.sensor.simulator import SensorModel

REAL_ID = 5 << 16  # packed ids of a real pixel: class 5, label 0, instance 0
BOX_ID = 7 | 1 << 8 | 4 << 16  # a person's: part 7, instance 1, class person


def _real(model: SensorModel, z_m: float = 3.0) -> np.ndarray:
    """A wall at ``z_m`` with a few holes, sensed once: the "real" frame (uint16 mm)."""
    h, w = model.cfg.intrinsics.height, model.cfg.intrinsics.width
    z = np.full((h, w), z_m)
    z[100:140, 500:540] = 0.0  # a black object: no return
    out = model.simulate(z, np.random.default_rng(99),
                         incidence=np.ones((h, w), np.float32))
    return out.depth_mm


def _composite(real_mm: np.ndarray, box: tuple[slice, slice], z_box: float):
    depth = real_depth_m(real_mm)
    ids = np.full(real_mm.shape, REAL_ID, np.uint32)
    depth[box] = z_box
    ids[box] = BOX_ID
    return depth, ids


@pytest.mark.parametrize("sensor", ["openni_525", "kinect_v1_full"])
def test_real_pixels_out_of_reach_keep_their_bytes(sensor):
    model = SensorModel(SensorConfig.load(sensor))
    real = _real(model)
    box = (slice(180, 330), slice(250, 330))
    depth, ids = _composite(real, box, 1.5)
    inc = np.ones(real.shape, np.float32)
    out = simulate_over_real(model, depth, np.random.default_rng(1), real_mm=real,
                             labels=ids, real_label=REAL_ID, incidence=inc)
    rows, cols = reach_px(model, 1.5)
    far = np.ones(real.shape, bool)
    far[180 - rows:330 + rows, 250 - cols:330 + cols] = False
    assert (out.depth_mm[far] == real[far]).all()
    assert (out.labels[far] == REAL_ID).all()
    # the box itself is sensed (holes and all) like any synthetic surface (its edges
    # measure the wall where the correlation window picks the wall's dots)
    inside = out.labels == BOX_ID
    assert inside.sum() > 0.8 * 150 * 80
    core = out.valid[190:320, 260:320]
    assert core.mean() > 0.95
    assert np.abs(out.depth_mm[190:320, 260:320][core].astype(float) - 1500).max() < 60
    # holes by cause add up to the pixels without a measurement
    assert sum(out.holes.values()) == int((~out.valid).sum())
    # no island the sensor's speckle filter would remove (openni_525: 200 px; the real
    # frame has none either)
    from scipy import ndimage

    lab, n = ndimage.label(out.valid)
    if sensor == "openni_525":
        assert np.bincount(lab.ravel())[1:].min() > 200
    assert out.holes[REAL_HOLE] >= 40 * 40
    # raw11 is the encoding of the composed disparity: real pixels from their real depth
    fb = model.cfg.intrinsics.fx * model.cfg.baseline_m
    if out.raw11 is not None:
        keep = far & (real > 0)
        d = np.zeros(real.shape)
        d[keep] = fb * 1000.0 / real[keep]
        ref = encode_raw11(d, keep, model.cfg.encoding.d_off)
        assert (out.raw11[keep] == ref[keep]).all()


def _bands(valid: np.ndarray, rows: slice, left: int, right: int) -> tuple[float, float]:
    """Median count per row of holes within 20 px left of column ``left`` and right of
    column ``right``, over ``rows``."""
    v = ~valid[rows]
    return (float(np.median(v[:, left - 20:left].sum(1))),
            float(np.median(v[:, right + 1:right + 21].sum(1))))


@pytest.mark.parametrize("sensor", ["openni_525", "kinect_v1_full"])
def test_shadow_of_a_synthetic_box_falls_on_the_real_wall_as_in_a_room(sensor):
    """The holes beside a synthetic box before a real wall are those the sensor makes
    beside the same box before a synthetic wall: the projector's shadow (f b (1/1.5 -
    1/3) = 8.75 px at openni_525's 5 cm, partly covered by the box's splats), the IR
    camera's band and the window's edge."""
    model = SensorModel(SensorConfig.load(sensor))
    real = _real(model)
    box = (slice(180, 330), slice(250, 330))
    inc = np.ones(real.shape, np.float32)
    depth, ids = _composite(real, box, 1.5)
    out = simulate_over_real(model, depth, np.random.default_rng(2), real_mm=real,
                             labels=ids, real_label=REAL_ID, incidence=inc)
    room = np.full(real.shape, 3.0)
    room[box] = 1.5
    plain = model.simulate(room, np.random.default_rng(2), incidence=inc)
    rows = slice(200, 310)
    composite_bands = _bands(out.valid, rows, 250, 329)
    room_bands = _bands(plain.valid, rows, 250, 329)
    assert np.allclose(composite_bands, room_bands, atol=1.0), (composite_bands, room_bands)
    assert sum(room_bands) >= 3  # there are bands to compare
    lost = (out.labels == REAL_ID) & ~out.valid & (real > 0)  # holes the box made
    assert lost.sum() > 2 * 110


def test_nothing_but_the_synthetic_pixels_changes_without_effects(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("name: t\nwidth: 640\nheight: 480\nfx: 525\nfy: 525\ncx: 319.5\n"
                 "cy: 239.5\nbaseline_m: 0.05\neffects:\n  - range_gate: {z_min_m: 0.5, "
                 "z_max_m: 10}\n  - encode: {raw11: true}\n")
    model = SensorModel(SensorConfig.load(p))
    real = _real(SensorModel(SensorConfig.load("openni_525")))
    box = (slice(10, 200), slice(20, 90))
    depth, ids = _composite(real, box, 2.0)
    out = simulate_over_real(model, depth, None, real_mm=real, labels=ids,
                             real_label=REAL_ID)
    expect = real.copy()
    expect[box] = 2000
    assert (out.depth_mm == expect).all()
    assert (out.labels == ids).all()


def test_every_person_hidden_gives_the_real_frame():
    model = SensorModel(SensorConfig.load("openni_525"))
    real = _real(model)
    ids = np.full(real.shape, REAL_ID, np.uint32)
    out = simulate_over_real(model, real_depth_m(real), np.random.default_rng(3),
                             real_mm=real, labels=ids, real_label=REAL_ID,
                             incidence=np.ones(real.shape, np.float32))
    assert (out.depth_mm == real).all() and (out.valid == (real > 0)).all()
    assert out.holes == {REAL_HOLE: int((real == 0).sum())}


def test_same_draws_same_bytes():
    model = SensorModel(SensorConfig.load("openni_525"))
    real = _real(model)
    depth, ids = _composite(real, (slice(100, 300), slice(100, 200)), 1.2)
    inc = np.ones(real.shape, np.float32)
    a, b = (simulate_over_real(model, depth, np.random.default_rng(5), real_mm=real,
                               labels=ids, real_label=REAL_ID, incidence=inc)
            for _ in range(2))
    assert (a.depth_mm == b.depth_mm).all() and (a.raw11 == b.raw11).all()
    assert (a.labels == b.labels).all() and a.holes == b.holes
