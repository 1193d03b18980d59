"""Sensor effects on synthetic frames whose truth is known, and the hard cases."""

import numpy as np
import pytest

from vhgen.camera import pixel_rays
from vhgen.sensor.effects import AxialNoise
from vhgen.sensor.simulator import SensorConfig, SensorModel
from vhgen.sensor.stages import AxialNoiseStage
from vhgen.sensor.state import SensorState
from vhgen.yamlio import configs_dir

F, B = 571.26, 0.075
H, W = 120, 160


def _cfg(effects: str, tmp_path, name="t", width=W, height=H) -> SensorConfig:
    p = tmp_path / f"{name}.yaml"
    p.write_text(f"name: {name}\nwidth: {width}\nheight: {height}\nfx: {F}\nfy: {F}\n"
                 f"cx: {(width - 1) / 2}\ncy: {(height - 1) / 2}\nbaseline_m: {B}\n"
                 f"pattern_seed: 3\neffects:\n{effects}")
    return SensorConfig.load(p)


def _plane(z, h=H, w=W):
    return np.full((h, w), z, dtype=np.float64)


def test_shipped_sensors_load_and_declare_needs():
    fast = SensorConfig.load("kinect_v1_fast")
    full = SensorConfig.load("kinect_v1_full")
    exact = SensorConfig.load("kinect_v1_exact_shadows")
    ideal = SensorConfig.load("ideal")
    assert fast.needs == frozenset() and ideal.needs == frozenset()
    assert full.needs == {"incidence"} and "projector_depth" not in full.needs
    assert exact.needs >= {"projector_depth", "incidence"}
    for p in (configs_dir() / "sensors").glob("*.yaml"):
        SensorConfig.load(p)


def test_quantisation_rounds_half_up(tmp_path):
    m = SensorModel(_cfg("  - disparity_quantisation: {step_px: 0.125}\n", tmp_path))
    d = np.array([1.0, 1.0625, 1.0624, 1.1875, 3.3])  # px
    z = np.zeros((H, W))
    z[0, :5] = F * B / d
    out = m.simulate(z, None)
    np.testing.assert_allclose(out.disparity[0, :5], [1.0, 1.125, 1.0, 1.25, 3.25], atol=1e-9)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_quantised_depth_error_bound_float32_and_float64(tmp_path, dtype):
    m = SensorModel(_cfg("  - disparity_quantisation: {}\n", tmp_path))
    z = np.linspace(0.5, 6.0, H * W).reshape(H, W).astype(dtype)
    out = m.simulate(z, None)
    d = F * B / z.astype(np.float64)
    bound = F * B / (16 * d * (d - 1 / 16)) + 0.0005  # + mm rounding
    got = out.depth_mm / 1000.0
    assert np.all(np.abs(got - z) <= bound)
    # float32 input and its float64 copy give the same bytes
    out64 = m.simulate(z.astype(np.float64), None)
    np.testing.assert_array_equal(out.depth_mm, out64.depth_mm)


def test_no_hit_zero_nan_inf_out_of_range_never_leak(tmp_path):
    cfg = _cfg("  - range_gate: {z_min_m: 0.8, z_max_m: 4.0}\n"
               "  - axial_noise: {model: disparity, sigma_px: 0.07}\n"
               "  - disparity_quantisation: {}\n  - encode: {raw11: true}\n", tmp_path)
    z = _plane(2.0)
    z[0, :7] = [0.0, np.nan, np.inf, -1.0, 0.3, 4.5, 1e9]
    out = SensorModel(cfg).simulate(z, np.random.default_rng(0))
    assert (out.depth_mm[0, :7] == 0).all() and (out.raw11[0, :7] == 2047).all()
    assert np.isfinite(out.disparity).all()
    assert out.holes["no_hit"] >= 3 and out.holes["range"] >= 3
    assert out.valid[1:].all()


def test_noise_pushing_disparity_below_zero_is_a_hole(tmp_path):
    cfg = _cfg("  - axial_noise: {model: disparity, sigma_px: 2.0}\n", tmp_path)
    out = SensorModel(cfg).simulate(_plane(200.0), np.random.default_rng(1))  # d = 0.2 px
    assert 0 < out.holes["noise"] < H * W and np.isfinite(out.disparity).all()
    assert (out.depth_mm[~out.valid] == 0).all()


def test_deterministic_per_frame_generator_and_no_draws_when_not_random(tmp_path):
    full = SensorModel(SensorConfig.load("kinect_v1_full"))
    z = _plane(2.0, 480, 640)
    z[:, 300:] = 1.2
    n = np.ones((480, 640), np.float32)
    a = full.simulate(z, np.random.default_rng(7), incidence=n)
    b = full.simulate(z, np.random.default_rng(7), incidence=n)
    np.testing.assert_array_equal(a.depth_mm, b.depth_mm)
    np.testing.assert_array_equal(a.raw11, b.raw11)
    with pytest.raises(ValueError, match="Generator"):
        full.simulate(z, None, incidence=n)
    with pytest.raises(ValueError, match="incidence"):
        full.simulate(z, np.random.default_rng(7))
    rng = np.random.default_rng(3)
    state = rng.bit_generator.state
    SensorModel(SensorConfig.load("ideal")).simulate(z, rng)
    assert rng.bit_generator.state == state  # nothing drawn for a noiseless sensor


def test_noise_models_match_their_published_sigmas(tmp_path):
    z0 = 2.5
    for model, expected in [("khoshelham", 1.425e-3 * z0 ** 2),
                            ("nguyen", 0.0012 + 0.0019 * (z0 - 0.4) ** 2)]:
        cfg = _cfg(f"  - axial_noise: {{model: {model}}}\n", tmp_path, model, 640, 480)
        out = SensorModel(cfg).simulate(_plane(z0, 480, 640), np.random.default_rng(5))
        got = (out.disparity[out.valid] ** -1 * F * B).std()
        assert abs(got / expected - 1) < 0.03, model
    cfg = _cfg("  - axial_noise: {model: disparity, sigma_px: 0.07}\n", tmp_path, "d", 640, 480)
    out = SensorModel(cfg).simulate(_plane(z0, 480, 640), np.random.default_rng(5))
    assert abs(out.disparity[out.valid].std() / 0.07 - 1) < 0.03


def test_barron_malik_bias_removed():
    """The published ICL code biases depth nearer by ~z^2/(2*35130) cm; ours is unbiased
    to within the 1 cm input rounding."""
    z0 = 3.0
    ideal = SensorConfig.load("ideal")
    s = SensorState(ideal.intrinsics, B, _plane(z0, 480, 640), np.ones((480, 640), bool))
    AxialNoiseStage(AxialNoise(model="barron_malik"), ideal).apply(s, np.random.default_rng(0))
    ours = s.z[s.valid].mean()
    rng = np.random.default_rng(0)
    icl = (35130 / np.round(35130 / np.round(z0 * 100) + rng.standard_normal(480 * 640) / 6
                            + 0.5) / 100).mean()
    bias_icl = z0 ** 2 * 1e4 / (2 * 35130) / 100  # metres
    assert abs(ours - z0) < 0.2 * bias_icl
    assert icl < z0 - 0.5 * bias_icl


@pytest.mark.parametrize("method", ["screen_space", "exact"])
def test_shadow_band_width_matches_parallax(tmp_path, method):
    """Foreground at 1 m over the right half, wall at 3 m: the projector (at +x) leaves a
    band of f b (1/1 - 1/3) = 28.6 px unlit just left of the foreground edge."""
    w = 640
    cfg = _cfg(f"  - projector_shadow: {{method: {method}}}\n", tmp_path, width=w, height=48)
    z = np.full((48, w), 3.0)
    z[:, 400:] = 1.0
    proj = np.full((48, w), 3.0)
    # the projector sees the foreground edge (x = 399.5) shifted left by f b / 1 m = 42.8 px
    proj[:, int(np.ceil(399.5 - F * B / 1.0)):] = 1.0
    out = SensorModel(cfg).simulate(z, None, projector_depth=proj)
    band = np.flatnonzero(~out.valid[24, 100:]) + 100
    expected = F * B * (1 / 1.0 - 1 / 3.0)
    assert band.max() == 399 and abs(len(band) - expected) <= 1.5, (band.min(), len(band))
    if method == "exact":
        # the projector lights nothing left of column f b / 3 m = 14.3: the Kinect's
        # invalid left border, which the screen-space rule cannot know
        assert (~out.valid[24, :14]).all() and out.valid[24, 16:100].all()


def test_screen_space_shadow_misses_outside_occluders_exact_does_not(tmp_path):
    """An occluder just outside the right image border: only the projector pass sees it."""
    w = 320
    cfg_s = _cfg("  - projector_shadow: {method: screen_space}\n", tmp_path, "s", w, 16)
    cfg_e = _cfg("  - projector_shadow: {method: exact}\n", tmp_path, "e", w, 16)
    z = np.full((16, w), 3.0)
    proj = np.full((16, w), 3.0)
    proj[:, w - 20:] = 1.0  # seen by the projector, outside the camera's view
    assert SensorModel(cfg_s).simulate(z, None, projector_depth=proj).valid.all()
    assert (~SensorModel(cfg_e).simulate(z, None, projector_depth=proj).valid).sum() > 16 * 5


def test_correlation_window_fills_planes_loses_thin_rods_fattens_edges(tmp_path):
    cfg = _cfg("  - correlation_window: {}\n", tmp_path, width=320, height=240)
    m = SensorModel(cfg)
    plane = m.simulate(_plane(2.0, 240, 320), None)
    inner = plane.valid[8:-8, 8:-8]
    assert inner.mean() > 0.97  # splats fill between dots
    # the 9x9 window needs a 4 px margin; splats (r 3.1) reach back to row and column 1
    assert not plane.valid[:1].any() and not plane.valid[:, :1].any()
    assert plane.valid[1:4].mean() < inner.mean()
    for width_px, survives in ((2, False), (30, True)):
        z = _plane(3.0, 240, 320)
        z[:, 150:150 + width_px] = 2.0
        out = m.simulate(z, None)
        rod = out.disparity[40:200, 150:150 + width_px]
        near = np.isclose(rod, F * B / 2.0, atol=0.2)
        assert (near.mean() > 0.5) == survives, width_px
    fattened = []  # pixels rendered far, measured (and now labelled) near
    for zf, hole_band in ((1.5, True), (2.5, False)):
        z = _plane(3.0, 240, 320)
        z[:, 160:] = zf
        lab = np.where(np.arange(320) >= 160, 2, 1).astype(np.uint32) + np.zeros((240, 1),
                                                                                 np.uint32)
        out = m.simulate(z, None, labels=lab)
        fg = np.isclose(out.disparity, F * B / zf, atol=0.3)
        cols = np.array([np.flatnonzero(fg[r])[0] for r in range(40, 200) if fg[r].any()])
        off = np.abs(cols - 160)  # the edge moves by about the window half-width at most
        assert np.percentile(off, 95) <= 4 and off.max() <= 6
        # a pixel measures the surface of the dot that won it, and is labelled with it:
        # the pixels the near plane's splats took from the far one are the near plane's
        bg = np.isclose(out.disparity, F * B / 3.0, atol=0.3)
        assert (out.labels[fg & out.valid] == 2).all() and (out.labels[bg & out.valid] == 1).all()
        fattened.append(int(((lab == 1) & fg & out.valid).sum()))
        holes = (~out.valid[40:200, 150:170]).sum(axis=1)
        # a 14 px disparity jump fails the inlier test on both sides: a band of holes
        assert (np.median(holes) >= 2) == hole_band, zf
    assert max(fattened) > 20, fattened


def test_grazing_dropout_and_nguyen_angle_term_stay_finite(tmp_path):
    cfg = _cfg("  - axial_noise: {model: nguyen, angle_term: true}\n"
               "  - dropout: {max_angle_deg: 80}\n", tmp_path)
    normals = np.zeros((H, W, 3))
    normals[..., 2] = -1.0
    normals[:, :40] = [1.0, 0.0, 0.0]  # exactly 90 deg to the optical axis
    normals[:, 40:80] = [np.sin(np.deg2rad(85)), 0, -np.cos(np.deg2rad(85))]
    rays = pixel_rays(cfg.intrinsics)
    n = np.abs((normals * rays).sum(-1) / np.linalg.norm(rays, axis=-1))
    out = SensorModel(cfg).simulate(_plane(2.0), np.random.default_rng(0), incidence=n)
    assert np.isfinite(out.disparity).all()
    assert not out.valid[:, :30].any() and out.valid[:, 100:].mean() > 0.99


def test_lens_distortion_moves_depth_and_labels_together(tmp_path):
    cfg = _cfg("  - lens_distortion: {}\n", tmp_path, width=640, height=480)
    z = _plane(2.0, 480, 640)
    z[:, 320:] = 3.0
    labels = np.where(z < 2.5, 1, 2).astype(np.uint8)
    out = SensorModel(cfg).simulate(z, None, labels=labels)
    ok = out.valid
    near = out.depth_mm == 2000
    np.testing.assert_array_equal(near[ok], out.labels[ok] == 1)
    assert out.holes.get("distortion", 0) > 0 or ok.all()
