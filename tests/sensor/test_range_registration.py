"""The effects added for real OpenNI frames: range_dropout, registration, speckle_filter,
and dropout's range_rule switch. Synthetic depth, known answers."""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.errors import ConfigError
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.simulator import SensorModel


def _sensor(tmp_path, effects: str, baseline: float = 0.075, fx: float = 525.0):
    p = tmp_path / "s.yaml"
    p.write_text(f"name: t\nwidth: 160\nheight: 120\nfx: {fx}\nfy: {fx}\ncx: 79.5\n"
                 f"cy: 59.5\nbaseline_m: {baseline}\neffects:\n{effects}")
    return SensorConfig.load(p)


def test_range_dropout_probability_and_blobs(tmp_path):
    cfg = _sensor(tmp_path, "  - range_dropout: {z_start_m: 4.0, z_end_m: 8.0, power: 1.0,"
                            " blob_px: 1}\n")
    m = SensorModel(cfg)
    for z, p in ((3.0, 0.0), (4.0, 0.0), (5.0, 0.25), (6.0, 0.5), (7.5, 0.875), (9.0, 1.0)):
        lost = np.mean([~m.simulate(np.full((120, 160), z), np.random.default_rng(s)).valid
                        for s in range(5)])
        assert abs(lost - p) < 0.01, (z, lost)
    # blobs: one draw per 4x4 cell, so holes come in whole cells
    cfg = _sensor(tmp_path, "  - range_dropout: {z_start_m: 4.0, z_end_m: 8.0, blob_px: 4}\n")
    out = SensorModel(cfg).simulate(np.full((120, 160), 6.0), np.random.default_rng(0))
    cells = out.valid.reshape(30, 4, 40, 4)
    assert (cells.all(axis=(1, 3)) | ~cells.any(axis=(1, 3))).all()
    assert 0.1 < 1 - out.valid.mean() < 0.4  # p = 0.5^2 = 0.25
    assert out.holes["range"] == int((~out.valid).sum())
    with pytest.raises(ConfigError, match="z_start_m: must be below z_end_m"):
        _sensor(tmp_path, "  - range_dropout: {z_start_m: 5.0, z_end_m: 4.0}\n")


def test_registration_border_and_ir_occlusion(tmp_path):
    cfg = _sensor(tmp_path, "  - registration: {ir_offset_m: -0.025, left_px: 7, right_px: 5,"
                            " top_px: 4, bottom_px: 2}\n")
    z = np.full((120, 160), 3.0)
    z[:, 80:] = 1.2  # a near box on the right half: its left edge is at column 80
    out = SensorModel(cfg).simulate(z, None)
    v = out.valid
    assert not v[:, :7].any() and not v[:, -5:].any() and not v[:4].any() and not v[-2:].any()
    # the IR camera at -x cannot see the wall just right of a near box's right edge (the
    # side away from the projector's shadow): box on the left half, wall on the right
    z2 = np.full((120, 160), 3.0)
    z2[:, :80] = 1.2
    v2 = SensorModel(cfg).simulate(z2, None).valid
    width = 525.0 * 0.025 * (1 / 1.2 - 1 / 3.0)  # 6.56 px
    row = v2[60, 7:155]
    hole = np.flatnonzero(~row) + 7
    assert hole.min() == 80 and abs(len(hole) - width) <= 1, hole
    assert out.holes["registration"] == int((~v).sum())


def test_speckle_filter(tmp_path):
    cfg = _sensor(tmp_path, "  - range_gate: {z_min_m: 0.5, z_max_m: 5.0}\n"
                            "  - speckle_filter: {max_area_px: 10}\n")
    z = np.zeros((120, 160))
    z[10:50, 10:60] = 2.0   # a big surface: kept
    z[70, 70] = 2.0         # one pixel: removed
    z[80:83, 80:83] = 2.0   # 9 px: removed
    z[90:94, 90:93] = 2.0   # 12 px: kept
    z[100, 100:105] = 2.0   # 5 px in a row: removed
    z[100, 105] = 9.0       # outside the gate, so the row above holds 5 valid pixels
    out = SensorModel(cfg).simulate(z, None)
    assert out.valid[10:50, 10:60].all() and out.valid[90:94, 90:93].all()
    assert out.valid.sum() == 40 * 50 + 12
    assert out.holes["speckle"] == 1 + 9 + 5


def test_dropout_range_rule_switch(tmp_path):
    inc = np.ones((120, 160))
    z = np.full((120, 160), 7.0)  # range > 7 m: beyond BlenSor's 6.19 m for albedo 1
    on = _sensor(tmp_path, "  - dropout: {max_angle_deg: 80}\n")
    off = _sensor(tmp_path, "  - dropout: {max_angle_deg: 80, range_rule: false}\n")
    assert not SensorModel(on).simulate(z, None, incidence=inc).valid.any()
    assert SensorModel(off).simulate(z, None, incidence=inc).valid.all()


def test_presets_keep_the_old_behaviour_reachable():
    """The old presets ship under *_gate4m; the new ones reach 10 m."""
    for name in ("kinect_v1_full", "openni_525"):
        old, new = SensorConfig.load(f"{name}_gate4m"), SensorConfig.load(name)
        assert old.effect("range_gate").z_max_m == 4.0
        assert new.effect("range_gate").z_max_m == 10.0
        assert old.effect("range_dropout") is None and new.effect("range_dropout") is not None
    assert SensorConfig.load("openni_525").effect("registration") is not None
