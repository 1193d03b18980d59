import numpy as np

from vhgen.camera import Intrinsics, backproject, look_at, project

INTR = Intrinsics(640, 480, 571.26, 571.26, 319.5, 239.5)


def test_gl_projection_matches_pixel_convention():
    """Clip -> NDC -> window coordinates land on project()'s pixel + 0.5 (pixel centres)."""
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), rng.uniform(0.5, 8, 50)])
    clip = np.column_stack([pts, np.ones(50)]) @ INTR.gl_projection(0.1, 20).T
    ndc = clip[:, :3] / clip[:, 3:]
    win = np.column_stack([(ndc[:, 0] + 1) * 320, (ndc[:, 1] + 1) * 240])
    np.testing.assert_allclose(win - 0.5, project(INTR, pts), atol=1e-9)
    assert np.all(np.abs(ndc[:, 2]) < 1)


def test_backproject_inverts_project():
    z = np.full((480, 640), 2.5)
    pts = backproject(INTR, z)
    uv = project(INTR, pts)
    v, u = np.mgrid[0:480, 0:640]
    np.testing.assert_allclose(uv[..., 0], u, atol=1e-9)
    np.testing.assert_allclose(uv[..., 1], v, atol=1e-9)


def test_look_at_axes():
    w2c = look_at([0, 1, 3], [0, 1, 0])
    r = w2c[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) > 0
    # world +x (the subject's left when facing the camera) is image right, world up is
    # image up (camera -y), the target is straight ahead
    np.testing.assert_allclose(r @ [1, 0, 0], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(r @ [0, 1, 0], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(w2c @ [0, 1, 0, 1], [0, 0, 3, 1], atol=1e-12)


def test_skip_camera_draws_what_sample_camera_draws():
    """A frame of a shared layout skips its own camera; its stream (the sensor noise that
    follows) must go on exactly where placing the camera would have left it."""
    from vhgen.camera import CameraConfig, sample_camera, skip_camera

    for cfg in (CameraConfig(), CameraConfig(pitch_deg=(5.0, 20.0), roll_deg=(-2.0, 2.0)),
                CameraConfig(distance_m=(2.0, 2.0), pitch_deg=(10.0, 10.0))):
        for seed in range(5):
            placed, skipped = np.random.default_rng(seed), np.random.default_rng(seed)
            sample_camera(placed, cfg)
            skip_camera(skipped, cfg)
            assert placed.bit_generator.state == skipped.bit_generator.state
            assert placed.random() == skipped.random()
