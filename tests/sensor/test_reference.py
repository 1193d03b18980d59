"""The structured-light reference path on exact analytic scenes."""

import numpy as np
import pytest

from vhgen.quality.fidelity_scenes import analytic_frame
from vhgen.sensor.simulator import SensorConfig, SensorModel

F, B = 571.26, 0.075


def _ref(tmp_path, noise: bool) -> SensorModel:
    p = tmp_path / "ref.yaml"
    p.write_text("name: ref\nwidth: 320\nheight: 240\nfx: 571.26\nfy: 571.26\ncx: 159.5\n"
                 "cy: 119.5\nbaseline_m: 0.075\npattern_seed: 1\ndot_density: 0.2\neffects:\n"
                 f"  - structured_light: {{ir_noise: {'true' if noise else 'false'}}}\n")
    return SensorModel(SensorConfig.load(p))


def test_reference_recovers_plane_disparity_to_the_eighth_pixel(tmp_path):
    from vhgen.quality.fidelity_scenes import Rect

    m = _ref(tmp_path, noise=False)
    intr = m.cfg.intrinsics
    fr = analytic_frame("plane", "plane", intr, B, [Rect(2.0)])
    out = m.simulate(fr.depth, None, incidence=fr.incidence, projector_depth=fr.projector_depth)
    true_d = F * B / 2.0
    # away from the image border (truncated windows) and the left band the projector
    # does not reach (columns < f b / z = 21)
    inner = out.valid[10:-10, 30:-10]
    assert inner.mean() > 0.97
    err = np.abs(out.disparity[10:-10, 30:-10][inner] - true_d)
    assert np.mean(err <= 1 / 16 + 1e-9) > 0.995  # the nearest 1/8 px
    assert np.mean(err <= 3 / 16 + 1e-9) > 0.999


def test_reference_shadows_and_noise(tmp_path):
    from vhgen.quality.fidelity_scenes import Rect

    m = _ref(tmp_path, noise=True)
    intr = m.cfg.intrinsics
    fr = analytic_frame("step", "step", intr, B, [Rect(3.0), Rect(1.0, x=(0.0, np.inf))])
    out = m.simulate(fr.depth, np.random.default_rng(0), incidence=fr.incidence,
                     projector_depth=fr.projector_depth)
    row = out.valid[120, 60:160]
    band = np.flatnonzero(~row)
    expected = F * B * (1 - 1 / 3)
    assert abs(len(band) - expected) < 6 and band.max() + 60 >= 150  # left of the edge
    assert out.holes["matching"] > 0
    with pytest.raises(ValueError, match="projector"):
        m.simulate(fr.depth, np.random.default_rng(0), incidence=fr.incidence)


def test_reference_near_field_beyond_search_range_is_invalid(tmp_path):
    """At 0.5 m the disparity (85.7 px) lies past the 64 px search window: no measurement,
    as on the device ("too near"), and no NaN."""
    from vhgen.quality.fidelity_scenes import Rect

    m = _ref(tmp_path, noise=False)
    fr = analytic_frame("near", "plane", m.cfg.intrinsics, B, [Rect(0.5)])
    out = m.simulate(fr.depth, None, incidence=fr.incidence, projector_depth=fr.projector_depth)
    assert out.valid.mean() < 0.01 and np.isfinite(out.disparity).all()
