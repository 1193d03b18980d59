import numpy as np
import pytest

from vhgen.sensor.kinect import depth_to_mm, quantise_disparity, simulate

F, B = 571.26, 0.075
KW = dict(focal_px=F, baseline_m=B, z_min=0.8, z_max=4.0)


def test_quantisation_rounds_half_up_in_eighths():
    d = np.array([1.0, 1.0625, 1.0624, 1.1875, -0.0625, 3.3])
    np.testing.assert_array_equal(quantise_disparity(d), [1.0, 1.125, 1.0, 1.25, 0.0, 3.25])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_quantised_depth_error_bounded_by_half_step(dtype):
    z = np.linspace(0.8, 4.0, 5000).astype(dtype)[None]
    zq, valid = simulate(z, disparity_noise_px=0.0, subpixel=0.125, rng=None, **KW)
    assert valid.all()
    # |d_q - d| <= 1/16 px, so |z_q - z| = f b |d - d_q| / (d d_q) <= f b / (16 d (d - 1/16))
    d = F * B / z.astype(np.float64)
    bound = F * B / (16 * d * (d - 1 / 16)) * (1 + 1e-9)
    assert np.all(np.abs(zq - z) <= bound)
    assert zq.dtype == np.float64


def test_invalid_inputs_never_produce_nan_or_values():
    z = np.array([[0.0, np.nan, np.inf, -1.0, 0.5, 4.5, 2.0, 1e9]])
    zq, valid = simulate(z, disparity_noise_px=0.0, subpixel=0.125, rng=None, **KW)
    assert valid.tolist() == [[False] * 6 + [True, False]]
    assert np.isfinite(zq).all() and (zq[~valid] == 0).all()
    mm = depth_to_mm(zq, valid)
    assert mm.dtype == np.uint16 and mm.tolist()[0][:6] == [0] * 6


def test_noise_is_seeded_and_can_push_disparity_below_zero():
    z = np.full((64, 64), 3.9)
    a = simulate(z, disparity_noise_px=0.5, subpixel=0.125, rng=np.random.default_rng(7), **KW)
    b = simulate(z, disparity_noise_px=0.5, subpixel=0.125, rng=np.random.default_rng(7), **KW)
    np.testing.assert_array_equal(a[0], b[0])
    # far wall with huge noise: d = f b / z ~ 0.2 px: many pixels get d <= 0 or leave range
    far = np.full((64, 64), 200.0)
    zq, valid = simulate(far, focal_px=F, baseline_m=B, z_min=0.1, z_max=1e6,
                         disparity_noise_px=1.0, subpixel=0.125, rng=np.random.default_rng(1))
    assert (~valid).sum() > 1000 and np.isfinite(zq).all() and (zq >= 0).all()


def test_noise_statistics_match_disparity_sigma():
    z0 = 2.0
    z = np.full((480, 640), z0)
    zq, valid = simulate(z, disparity_noise_px=0.07, subpixel=0.0, rng=np.random.default_rng(3),
                         **KW)
    # sigma_z = z^2 / (f b) * sigma_d to first order
    expected = z0**2 / (F * B) * 0.07
    assert abs(zq[valid].std() / expected - 1) < 0.02


def test_noise_needs_a_generator():
    with pytest.raises(ValueError, match="Generator"):
        simulate(np.ones((2, 2)), disparity_noise_px=0.1, subpixel=0.125, rng=None, **KW)


def test_mm_encoding_overflow_is_invalid():
    z = np.array([0.0004, 1.2345, 65.535, 65.6])
    mm = depth_to_mm(z, np.ones(4, bool))
    assert mm.tolist() == [0, 1235, 65535, 0]
