"""The structured-light reference and `vhgen bench fidelity`."""

import json

import numpy as np
import pytest

from vhgen.sensor.model import SensorConfig, SensorModel
from vhgen.sensor.scenes import analytic_frame, suite

F, B = 571.26, 0.075


def _ref(tmp_path, noise: bool) -> SensorModel:
    p = tmp_path / "ref.yaml"
    p.write_text("name: ref\nwidth: 320\nheight: 240\nfx: 571.26\nfy: 571.26\ncx: 159.5\n"
                 "cy: 119.5\nbaseline_m: 0.075\npattern_seed: 1\ndot_density: 0.2\neffects:\n"
                 f"  - structured_light: {{ir_noise: {'true' if noise else 'false'}}}\n")
    return SensorModel(SensorConfig.load(p))


def test_reference_recovers_plane_disparity_to_the_eighth_pixel(tmp_path):
    from vhgen.sensor.scenes import Rect

    m = _ref(tmp_path, noise=False)
    intr = m.cfg.intrinsics
    fr = analytic_frame("plane", "plane", intr, B, [Rect(2.0)])
    out = m.simulate(fr.depth, None, normals=fr.normals, projector_depth=fr.projector_depth)
    true_d = F * B / 2.0
    # away from the image border (truncated windows) and the left band the projector
    # does not reach (columns < f b / z = 21)
    inner = out.valid[10:-10, 30:-10]
    assert inner.mean() > 0.97
    err = np.abs(out.disparity[10:-10, 30:-10][inner] - true_d)
    assert np.mean(err <= 1 / 16 + 1e-9) > 0.995  # the nearest 1/8 px
    assert np.mean(err <= 3 / 16 + 1e-9) > 0.999


def test_reference_shadows_and_noise(tmp_path):
    from vhgen.sensor.scenes import Rect

    m = _ref(tmp_path, noise=True)
    intr = m.cfg.intrinsics
    fr = analytic_frame("step", "step", intr, B, [Rect(3.0), Rect(1.0, x=(0.0, np.inf))])
    out = m.simulate(fr.depth, np.random.default_rng(0), normals=fr.normals,
                     projector_depth=fr.projector_depth)
    row = out.valid[120, 60:160]
    band = np.flatnonzero(~row)
    expected = F * B * (1 - 1 / 3)
    assert abs(len(band) - expected) < 6 and band.max() + 60 >= 150  # left of the edge
    assert out.holes["matching"] > 0
    with pytest.raises(ValueError, match="projector"):
        m.simulate(fr.depth, np.random.default_rng(0), normals=fr.normals)


def test_bench_fidelity_quick(tmp_path):
    from vhgen.sensor.fidelity import bench_fidelity

    res = bench_fidelity(tmp_path, quick=True, human=False,
                         configs=("ideal", "kinect_v1_full"))
    data = json.loads((tmp_path / "fidelity.json").read_text())
    assert (tmp_path / "fidelity.png").stat().st_size > 10_000
    assert "kinect_v1_full" in (tmp_path / "table.txt").read_text()
    ideal = data["configs"]["ideal"]["summary"]
    full = data["configs"]["kinect_v1_full"]["summary"]
    ref = data["configs"][data["reference"]]["summary"]
    assert ref["valid_iou"] == 1.0 and ref["rms_raw"] == 0.0
    # the full model casts shadows and loses thin rods like the reference; ideal does not
    assert full["shadow_width_error_px"] < ideal["shadow_width_error_px"]
    assert full["rod_recall"]["2"] < 0.5 <= ideal["rod_recall"]["2"]
    assert full["ms_per_frame"] > ideal["ms_per_frame"]
    assert full["hole_iou"] > ideal["hole_iou"]
    assert res["table"].splitlines()[0].startswith("fidelity against")


def test_analytic_scenes_are_exact():
    intr = SensorConfig.load("ideal").intrinsics
    frames = suite(intr, B, quick=True)
    plane = next(f for f in frames if f.kind == "plane")
    np.testing.assert_allclose(plane.depth, 2.0)
    step = next(f for f in frames if f.kind == "step")
    assert step.depth[100, 400] == pytest.approx(1.0) and step.depth[100, 100] == 3.0
    # the projector at +b sees the foreground edge shifted left by f b / z
    cols = np.flatnonzero(step.projector_depth[100] < 2.0)
    assert abs(cols[0] - (intr.cx - F * B / 1.0)) <= 1


def test_reference_near_field_beyond_search_range_is_invalid(tmp_path):
    """At 0.5 m the disparity (85.7 px) lies past the 64 px search window: no measurement,
    as on the device ("too near"), and no NaN."""
    from vhgen.sensor.scenes import Rect

    m = _ref(tmp_path, noise=False)
    fr = analytic_frame("near", "plane", m.cfg.intrinsics, B, [Rect(0.5)])
    out = m.simulate(fr.depth, None, normals=fr.normals, projector_depth=fr.projector_depth)
    assert out.valid.mean() < 0.01 and np.isfinite(out.disparity).all()
