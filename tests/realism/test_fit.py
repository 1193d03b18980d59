"""`vhgen sensor fit` recovers the settings of frames vhgen simulated with known values,
and writes a config that loads and runs. The truth keeps the base preset's values of what
the fit cannot estimate (the correlation window, lateral noise), as a real sensor would
have to for the fit to be exact."""

from __future__ import annotations

import numpy as np

from vhgen.camera import Intrinsics
from vhgen.cli import main
from vhgen.depthfile import write_pcd
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.simulator import SensorModel

INTR = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
TRUTH = """name: truth
width: 640
height: 480
fx: 525.0
fy: 525.0
cx: 319.5
cy: 239.5
baseline_m: 0.06
pattern_seed: 3
dot_density: 0.2
effects:
  - range_gate: {z_min_m: 0.5, z_max_m: 10.0}
  - projector_shadow: {method: screen_space}
  - lateral_noise: {model: icl, sigma_px: 0.5}
  - axial_noise: {model: disparity, sigma_px: 0.05}
  - correlation_window: {window: 9, frac: 0.6666667, inlier_px: 0.08, splat_radius_px: 3.1}
  - dropout: {max_angle_deg: 80, range_rule: false}
  - disparity_quantisation: {step_px: 0.1}
  - registration: {ir_offset_m: -0.02, left_px: 12, right_px: 8, top_px: 10, bottom_px: 2}
  - speckle_filter: {max_area_px: 200}
  - encode: {}
"""


def _scenes() -> list[np.ndarray]:
    """Static scenes unlike the fit's own calibration frames: boxes and posts before
    walls at several depths, a floor-like ramp."""
    out = []
    v, u = np.mgrid[0:480, 0:640]
    for k, (near, far) in enumerate(((0.9, 2.6), (1.4, 3.3), (1.1, 2.0), (2.0, 3.8))):
        z = np.full((480, 640), far) + 0.05 * np.sin(u / 90.0 + k)
        z[60:300, 100 + 20 * k:260 + 20 * k] = near
        z[80:420, 420:470] = near + 0.3
        z[360:, :] = np.minimum(z[360:, :], 1.0 + (480 - v[360:, :]) * 0.01)
        out.append(z)
    return out


def test_fit_recovers_simulated_settings(tmp_path, capsys):
    truth_file = tmp_path / "truth.yaml"
    truth_file.write_text(TRUTH)
    model = SensorModel(SensorConfig.load(truth_file))
    for k, z in enumerate(_scenes()):
        o = model.simulate(z, np.random.default_rng(k), incidence=np.full(z.shape, 0.9))
        write_pcd(tmp_path / f"f{k}.pcd", o.depth_mm, INTR)
    out = tmp_path / "fitted.yaml"
    code = main(["sensor", "fit", str(tmp_path), "-o", str(out), "--base",
                 "openni_525_gate4m"])
    text, err = capsys.readouterr()
    assert code == 0, err
    assert "kept from openni_525_gate4m" in text and "lateral_noise" in text
    fit = SensorConfig.load(out)  # loads (fit_files also ran it once)
    assert fit.intrinsics == INTR and fit.name == "fitted"
    reg = fit.effect("registration")
    assert (reg.left_px, reg.right_px, reg.top_px, reg.bottom_px) == (12, 8, 10, 2)
    assert abs(fit.baseline_m - 0.06) / 0.06 < 0.15, fit.baseline_m
    assert abs(reg.ir_offset_m + 0.02) / 0.02 < 0.25, reg.ir_offset_m
    # steps and noise in depth (what the frames show) match the truth's
    step_z = fit.effect("disparity_quantisation").step_px / fit.baseline_m
    assert abs(step_z - 0.1 / 0.06) / (0.1 / 0.06) < 0.05, step_z
    noise_z = fit.effect("axial_noise").sigma_px / fit.baseline_m
    assert abs(noise_z - 0.05 / 0.06) / (0.05 / 0.06) < 0.2, noise_z
    assert fit.effect("speckle_filter").max_area_px == 200
    # the gate: nearest depth 0.9 m, below the base's 0.8 m? no: kept; far 3.8 m < 4 m: kept
    assert fit.effect("range_gate").z_min_m == 0.8 and fit.effect("range_gate").z_max_m == 4.0
    o = SensorModel(fit).simulate(_scenes()[0], np.random.default_rng(0),
                                  incidence=np.full((480, 640), 0.9))
    assert 0.5 < o.valid.mean() < 0.95


def test_fit_errors_are_one_line(tmp_path, capsys):
    (tmp_path / "bad.pcd").write_bytes(b"junk\n")
    code = main(["sensor", "fit", str(tmp_path / "bad.pcd"), "-o", str(tmp_path / "x.yaml")])
    _, err = capsys.readouterr()
    assert code == 2
    assert err.splitlines()[0].startswith("vhgen: warning: skipped") and "bad.pcd" in err
    assert err.splitlines()[-1].startswith("vhgen: error: REAL: no readable real depth")
    assert not (tmp_path / "x.yaml").exists()
