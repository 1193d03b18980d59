"""The GL sensor (``sensor.backend: gl``) against the CPU sensor, the reference.

Deterministic effects (range gate, shadows, registration, dropout, quantisation, the
correlation window, the speckle filter) are compared pixel by pixel: the GL passes compute
in float32, the CPU stages in float64, so a handful of pixels on a threshold may differ
(bounded below). Random effects draw from a different generator (a counter-based hash of
the frame's key), so their statistics are compared: noise std against distance, the
dropout rate against depth, the lateral displacement. A rendered person through
``openni_525`` on both backends gives the realism bench's 14 statistics within stated
tolerances.
"""

import numpy as np
import pytest

from vhgen.errors import ConfigError
from vhgen.sensor.simulator import SensorConfig, SensorModel
from vhgen.sensor.spec import effect_types
from vhgen.yamlio import configs_dir

F, B = 525.0, 0.05
H, W = 120, 160


def _cfg(effects: str, tmp_path, name="t", width=W, height=H, backend=None) -> SensorConfig:
    p = tmp_path / f"{name}.yaml"
    p.write_text(f"name: {name}\nwidth: {width}\nheight: {height}\nfx: {F}\nfy: {F}\n"
                 f"cx: {(width - 1) / 2}\ncy: {(height - 1) / 2}\nbaseline_m: {B}\n"
                 + (f"backend: {backend}\n" if backend else "")
                 + f"pattern_seed: 3\neffects:\n{effects}")
    return SensorConfig.load(p)


def _both(ctx, cfg, depth, seed=0, row_threads=None, **kw):
    from vhgen.render.sensor_gl import GLSensorModel

    g = GLSensorModel(ctx, cfg, row_threads=row_threads)
    try:
        gl = g.simulate(depth, np.random.default_rng(seed), **kw)
    finally:
        g.release()
    cpu = SensorModel(cfg).simulate(depth, np.random.default_rng(seed), **kw)
    return cpu, gl


def _steps(h=H, w=W, far=3.0, nears=(0.9, 1.4, 2.0)):
    """A wall at ``far`` with boxes at ``nears`` side by side (vertical edges)."""
    z = np.full((h, w), far)
    edges = np.linspace(0, w, 2 * len(nears) + 2).astype(int)
    for k, near in enumerate(nears):
        z[h // 6: -h // 6, edges[2 * k + 1]:edges[2 * k + 2]] = near
    return z


# --- configuration (no GL) ---------------------------------------------------------------

def test_every_effect_with_gl_has_a_pass_and_no_other():
    from vhgen.render.sensor_gl import gl_effects

    have = gl_effects()
    for name, cls in effect_types().items():
        assert cls.GL == (cls in have), name


def test_backend_gl_refuses_effects_without_a_pass_at_load(tmp_path):
    from dataclasses import dataclass

    from vhgen.sensor.effects import RangeGate
    from vhgen.sensor.sensor_config import check_backend

    with pytest.raises(ConfigError) as e:
        _cfg("  - structured_light: {}\n", tmp_path, backend="gl")
    msg = str(e.value)
    assert "effects[0].structured_light" in msg and "backend: cpu" in msg
    assert "\n" not in msg
    with pytest.raises(ConfigError, match="backend: must be one of cpu, gl, got 'cuda'"):
        _cfg("  - range_gate: {}\n", tmp_path, backend="cuda")
    _cfg("  - structured_light: {}\n", tmp_path)  # the CPU runs it

    @dataclass(frozen=True)
    class NearGate(RangeGate):  # not registered: a pass that cannot take some values
        def gl_unsupported(self):
            return ("z_min_m", "below 1 m has no GL pass") if self.z_min_m < 1 else None

    with pytest.raises(ConfigError, match=r"x.yaml: effects\[1\]\.range_gate\.z_min_m: "
                                          r"below 1 m has no GL pass: backend gl cannot"):
        check_backend((RangeGate(), NearGate(z_min_m=0.5)), "gl", "x.yaml")
    assert check_backend((NearGate(z_min_m=1.5),), "gl", "x.yaml") == "gl"
    # every shipped preset but the structured-light reference runs on GL
    for p in (configs_dir() / "sensors").glob("*.yaml"):
        if p.stem == "kinect_v1_reference":
            with pytest.raises(ConfigError, match="structured_light"):
                SensorConfig.load(p).with_backend("gl")
        else:
            assert SensorConfig.load(p).with_backend("gl").backend == "gl"


def test_a_context_without_compute_shaders_is_refused_in_one_line():
    from vhgen.errors import RenderError
    from vhgen.render.sensor_gl import GLSensorModel

    class OldContext:
        version_code = 330
        info = {"GL_RENDERER": "some GL 3.3 driver"}

    with pytest.raises(RenderError) as e:
        GLSensorModel(OldContext(), SensorConfig.load("openni_525").with_backend("gl"))
    assert "4.3 compute shaders" in str(e.value) and "3.3" in str(e.value)
    assert "use sensor.backend: cpu" in str(e.value) and "\n" not in str(e.value)


def test_backend_shows_in_the_description_only_when_gl():
    cpu = SensorConfig.load("openni_525")
    assert "backend" not in cpu.to_dict()  # CPU stores keep their bytes
    assert cpu.with_backend("gl").to_dict()["backend"] == "gl"
    assert cpu.with_backend("cpu") is cpu


def test_job_config_selects_the_backend(tmp_path):
    from vhgen.job_config import JobConfig
    from vhgen.mocap.clips import BUILTIN_MOTION

    p = tmp_path / "job.yaml"
    p.write_text(f"name: j\nmotions: [{BUILTIN_MOTION}]\n"
                 "sensor: {preset: openni_525, backend: gl}\n")
    cfg = JobConfig.load(p)
    assert cfg.sensor.name == "openni_525" and cfg.sensor.backend == "gl"
    p.write_text(f"name: j\nmotions: [{BUILTIN_MOTION}]\n"
                 "sensor: {preset: kinect_v1_reference, backend: gl}\n")
    with pytest.raises(ConfigError, match=r"sensor: .*effects\[0\]\.structured_light"):
        JobConfig.load(p)
    p.write_text(f"name: j\nmotions: [{BUILTIN_MOTION}]\n"
                 "sensor: {preset: openni_525, backend: gl, speed: 2}\n")
    with pytest.raises(ConfigError, match="sensor.speed: unknown key"):
        JobConfig.load(p)


# --- deterministic effects, pixel by pixel -----------------------------------------------

def _agree(cpu, gl, max_pixels=0, mm=1):
    """Valid masks differ on at most ``max_pixels`` pixels; where both are valid, depth
    within ``mm`` mm (float32 against float64)."""
    differ = int(np.count_nonzero(cpu.valid != gl.valid))
    assert differ <= max_pixels, differ
    both = cpu.valid & gl.valid
    gap = np.abs(cpu.depth_mm[both].astype(int) - gl.depth_mm[both].astype(int))
    assert gap.max(initial=0) <= mm


# the row scans (shadows, registration, the speckle filter's runs) in both layouts: one
# invocation a row (what llvmpipe runs) and several with the stretches combined in shared
# memory (what a GPU runs: 128; 8 leaves 20 pixels a stretch at 160 wide, 128 at 157 wide
# leaves invocations with empty stretches)
ROW_LAYOUTS = pytest.mark.parametrize("row_threads,width", [(None, W), (8, W), (128, 157)])


@pytest.mark.gl
@ROW_LAYOUTS
def test_gate_shadow_registration_quantisation_match_the_cpu(gl_ctx, tmp_path, row_threads,
                                                             width):
    cfg = _cfg("  - range_gate: {z_min_m: 0.5, z_max_m: 2.5}\n"
               "  - projector_shadow: {}\n"
               "  - disparity_quantisation: {step_px: 0.0765}\n"
               "  - registration: {ir_offset_m: -0.0229, left_px: 5, right_px: 4, top_px: 3,"
               " bottom_px: 2}\n"
               "  - encode: {raw11: true}\n", tmp_path, width=width)
    z = _steps(far=2.2, w=width)
    z[:, -10:] = 4.0  # gated away
    z[0, 0] = np.nan  # no hit
    cpu, gl = _both(gl_ctx, cfg, z, row_threads=row_threads)
    _agree(cpu, gl, max_pixels=0, mm=1)
    for cause in ("range", "shadow", "registration", "no_hit"):
        assert np.array_equal(cpu.hole_masks[cause], gl.hole_masks[cause]), cause
    assert cpu.holes["shadow"] > 100 and cpu.holes["registration"] > 100
    # quantisation steps: every disparity a multiple of the step
    d = gl.disparity[gl.valid] / 0.0765
    np.testing.assert_allclose(d, np.round(d), atol=2e-4)
    np.testing.assert_array_equal(cpu.raw11, gl.raw11)


@pytest.mark.gl
def test_dropout_matches_the_cpu(gl_ctx, tmp_path):
    cfg = _cfg("  - dropout: {max_angle_deg: 60, albedo: 0.5}\n", tmp_path)
    z = np.linspace(0.6, 4.0, H * W).reshape(H, W)
    inc = np.tile(np.linspace(0.0, 1.0, W, dtype=np.float32), (H, 1))
    cpu, gl = _both(gl_ctx, cfg, z, incidence=inc)
    # thresholds: |cos| 0.5 (exact in float32), range (0.5 - 0.01) / 0.16 = 3.06 m
    _agree(cpu, gl, max_pixels=2)
    assert 0.2 < cpu.holes["dropout"] / z.size < 0.8


@pytest.mark.gl
def test_correlation_window_matches_the_cpu(gl_ctx, tmp_path):
    cfg = _cfg("  - correlation_window: {window: 9, frac: 0.6666667, inlier_px: 0.0609,"
               " splat_radius_px: 4.1}\n", tmp_path, width=320, height=240)
    z = _steps(240, 320)
    lab = np.arange(z.size, dtype=np.uint32).reshape(z.shape)
    cpu, gl = _both(gl_ctx, cfg, z, labels=lab)
    # float32 means against float64 summed-area tables: a dot on an inlier threshold may
    # go either way, and its splat with it
    _agree(cpu, gl, max_pixels=30, mm=1)
    assert cpu.holes["window"] > 500
    assert abs(cpu.holes["window"] - gl.holes["window"]) <= 30
    # every pixel carries the ids of the dot it took its disparity from (the ids are the
    # pixel indices here): the same dots as the CPU's but where a dot's verdict differs
    moved = cpu.labels != lab
    assert moved.sum() > 1000
    assert (cpu.labels != gl.labels).sum() <= 30 * 60  # a dot's splat: at most ~55 px
    src = gl.labels.astype(np.int64)
    ys, xs = np.divmod(src, z.shape[1])
    yy, xx = np.mgrid[0:z.shape[0], 0:z.shape[1]]
    assert ((ys - yy) ** 2 + (xs - xx) ** 2 <= 4.1 ** 2).all()  # within the splat radius


@pytest.mark.gl
def test_exact_shadow_matches_the_cpu(gl_ctx, tmp_path):
    cfg = _cfg("  - projector_shadow: {method: exact, tolerance: 0.01}\n", tmp_path)
    z = _steps()
    # the projector's view of fronto-parallel planes: each pixel moved by its disparity
    proj = np.zeros_like(z)
    v, u = np.mgrid[0:H, 0:W]
    up = np.clip(np.rint(u - F * B / z).astype(int), 0, W - 1)
    order = np.argsort(-z, axis=None)  # far first, so the nearest is written last
    proj[v.reshape(-1)[order], up.reshape(-1)[order]] = z.reshape(-1)[order]
    cpu, gl = _both(gl_ctx, cfg, z, projector_depth=proj)
    assert cpu.holes["shadow"] > 100
    _agree(cpu, gl, max_pixels=0)


@pytest.mark.gl
def test_lens_distortion_matches_the_cpu(gl_ctx, tmp_path):
    cfg = _cfg("  - lens_distortion: {}\n  - range_gate: {z_min_m: 0.5, z_max_m: 4}\n",
               tmp_path)
    z = _steps()
    lab = np.arange(z.size, dtype=np.uint32).reshape(z.shape)
    cpu, gl = _both(gl_ctx, cfg, z, labels=lab)
    assert cpu.holes["distortion"] > 100
    _agree(cpu, gl, max_pixels=0)
    np.testing.assert_array_equal(cpu.labels, gl.labels)
    np.testing.assert_array_equal(cpu.hole_masks["distortion"], gl.hole_masks["distortion"])


@pytest.mark.gl
@ROW_LAYOUTS
def test_speckle_filter_matches_the_cpu(gl_ctx, tmp_path, row_threads, width):
    cfg = _cfg("  - speckle_filter: {max_area_px: 20}\n", tmp_path, width=width)
    rng = np.random.default_rng(4)
    z = np.where(rng.random((H, width)) < 0.55, 2.0, 0.0)  # islands of every size
    z[40:80, 40:120] = 2.0  # and one big component
    z[60, 60:100] = 0.0  # with a cut that is not one
    cpu, gl = _both(gl_ctx, cfg, z, row_threads=row_threads)
    assert cpu.holes["speckle"] > 100
    np.testing.assert_array_equal(cpu.valid, gl.valid)
    np.testing.assert_array_equal(cpu.hole_masks["speckle"], gl.hole_masks["speckle"])


# --- random effects: statistics ----------------------------------------------------------

@pytest.mark.gl
def test_axial_noise_std_against_distance(gl_ctx, tmp_path):
    """Disparity noise: std of d against distance within 4% of the CPU's (and of sigma),
    for each of four planes; the depth models: std of z within 4%."""
    depths = (0.8, 1.6, 2.4, 3.2)
    z = np.repeat(np.array(depths), W // 4)[None, :].repeat(H, 0)
    truth_d = F * B / z
    for model, sigma in (("disparity", 0.5), ("khoshelham", 0.07), ("nguyen", 0.07)):
        cfg = _cfg(f"  - axial_noise: {{model: {model}, sigma_px: {sigma}}}\n", tmp_path)
        cpu, gl = _both(gl_ctx, cfg, z, seed=1)
        for k, dz in enumerate(depths):
            cols = slice(k * W // 4, (k + 1) * W // 4)
            if model == "disparity":
                s_cpu = np.std(cpu.disparity[:, cols] - truth_d[:, cols])
                s_gl = np.std(gl.disparity[:, cols] - truth_d[:, cols])
                assert abs(s_gl / sigma - 1) < 0.04, (dz, s_gl)
            else:
                s_cpu = np.std(cpu.depth_mm[:, cols] / 1000.0)
                s_gl = np.std(gl.depth_mm[:, cols] / 1000.0)
            assert abs(s_gl / s_cpu - 1) < 0.04, (model, dz, s_cpu, s_gl)


@pytest.mark.gl
def test_range_dropout_rate_against_depth(gl_ctx, tmp_path):
    cfg = _cfg("  - range_dropout: {z_start_m: 1.0, z_end_m: 5.0, power: 2.0, blob_px: 2}\n",
               tmp_path, width=320, height=240)
    depths = (2.0, 3.0, 4.0)
    z = np.repeat(np.array(depths), 320 // 3 + 1)[None, :320].repeat(240, 0)
    cpu, gl = _both(gl_ctx, cfg, z, seed=2)
    for dz in depths:
        cols = z[0] == dz
        p = ((dz - 1.0) / 4.0) ** 2
        # one draw per 2x2 cell: about 240 * 106 / 4 = 6400 cells per depth
        tol = 4 * np.sqrt(p * (1 - p) / 6000)
        for out in (cpu, gl):
            rate = 1 - out.valid[:, cols].mean()
            assert abs(rate - p) < tol, (dz, rate, p)
    # blobs: pixels of a cell go together
    lost = ~gl.valid[:, :106]
    assert np.array_equal(lost[0::2, 0::2], lost[1::2, 1::2])


@pytest.mark.gl
def test_lateral_noise_moves_labels_with_the_pixels(gl_ctx, tmp_path):
    cfg = _cfg("  - lateral_noise: {model: icl, sigma_px: 0.8}\n", tmp_path)
    v, u = np.mgrid[0:H, 0:W]
    z = 1.00023 + 0.01 * u + 0.0001 * v  # every pixel its own depth (off the .5 mm ties)
    lab = (v * W + u).astype(np.uint32)  # every pixel its own label
    cpu, gl = _both(gl_ctx, cfg, z, seed=3, labels=lab)
    for out in (cpu, gl):
        src = out.labels.astype(np.int64)
        sy, sx = src // W, src % W
        # the depth came from the pixel the label came from
        np.testing.assert_array_equal(out.depth_mm,
                                      np.floor(z[sy, sx] * 1000 + 0.5).astype(np.uint16))
    inner = (slice(10, -10), slice(10, -10))  # away from the clamped border

    def moved(out):
        src = out.labels.astype(np.int64)
        return (src % W - u)[inner], (src // W - v)[inner]

    for a, b in zip(moved(cpu), moved(gl), strict=True):
        # rounding sigma N to the nearest pixel: std about 0.86 for sigma 0.8
        assert abs(a.std() - b.std()) < 0.03 and abs(b.mean()) < 0.03
        assert abs(np.mean(a == 0) - np.mean(b == 0)) < 0.02


@pytest.mark.gl
def test_same_seed_same_frame_other_seed_other_frame(gl_ctx):
    from vhgen.render.sensor_gl import GLSensorModel

    cfg = SensorConfig.load("openni_525")
    z = _steps(480, 640, far=3.5)
    inc = np.full(z.shape, 0.9, np.float32)
    lab = np.arange(z.size, dtype=np.uint32).reshape(z.shape) % 4096
    g = GLSensorModel(gl_ctx, cfg)
    try:
        a, b, c = (g.simulate(z, np.random.default_rng(s), labels=lab, incidence=inc)
                   for s in (5, 5, 6))
    finally:
        g.release()
    for k in ("depth_mm", "labels", "raw11", "disparity", "valid"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    assert a.holes == b.holes
    assert not np.array_equal(a.depth_mm, c.depth_mm)


# --- a rendered frame through both backends: the realism statistics -----------------------

# |GL - CPU| allowed per realism statistic (summary values over 4 frames of each): the
# measured gaps on a person in front of a wall (docs/realism.md, "The GL sensor") are a
# fraction of these
REALISM_TOLERANCE = {
    "valid_fraction": 0.003, "depth": 0.002, "nearest": 0.005, "farthest": 0.005,
    "shadow_band": 0.5, "other_band": 0.5, "edge_holes": 0.03, "hole_blobs": 0.05,
    "holes_per_frame": 0.08, "speckles": 0.5, "axial_noise": 0.05, "noise_coeff": 0.03,
    "quant_step": 0.02, "border_band": 0.5,
}
RELATIVE = {"holes_per_frame", "axial_noise"}  # relative to the CPU's value


@pytest.fixture(scope="module")
def egl_ctx():
    from vhgen.render.context import create_context

    ctx = create_context("egl")
    yield ctx
    ctx.release()


@pytest.mark.gl
def test_realism_statistics_agree_on_a_rendered_person(egl_ctx, asset_dir):
    from vhgen.mocap.clips import builtin_motion_path
    from vhgen.quality.fidelity_scenes import human_frame
    from vhgen.realism.compare import STATISTICS, compare
    from vhgen.realism.stats import frame_stats

    cfg = SensorConfig.load("openni_525")
    fr = human_frame(egl_ctx, cfg.intrinsics, cfg.baseline_m, asset_dir,
                     builtin_motion_path(), wall=3.5)
    cpu, gl = [], []
    for seed in range(4):
        c, g = _both(egl_ctx, cfg, fr.depth, seed=seed, labels=fr.labels,
                     incidence=fr.incidence)
        cpu.append(frame_stats(c.depth_mm, cfg.intrinsics.fx))
        gl.append(frame_stats(g.depth_mm, cfg.intrinsics.fx))
        # the window and lateral noise move labels with the depth: the person's pixels
        # stay where the CPU puts them, give or take the noise
        assert abs(int((g.labels > 0).sum()) - int((c.labels > 0).sum())) < 150
    res = compare(cpu, gl)
    assert set(res) == {s.key for s in STATISTICS} and len(res) == 14
    for key, tol in REALISM_TOLERANCE.items():
        a, b = res[key]["real"], res[key]["sim"]  # real = CPU, sim = GL
        gap = abs(b - a) / abs(a) if key in RELATIVE else abs(b - a)
        assert gap <= tol, (key, a, b)


@pytest.mark.gl
def test_gl_sensor_over_a_real_background(egl_ctx):
    """vhgen.sensor.composite with the GL sensor: both passes draw the same key from the
    copied generator, so real pixels out of the people's reach keep their bytes."""
    from vhgen.render.sensor_gl import GLSensorModel
    from vhgen.sensor.composite import reach_px, real_depth_m, simulate_over_real

    cfg = SensorConfig.load("openni_525")
    g = GLSensorModel(egl_ctx, cfg)
    try:
        h, w = cfg.intrinsics.height, cfg.intrinsics.width
        inc = np.ones((h, w), np.float32)
        real = g.simulate(np.full((h, w), 3.0), np.random.default_rng(99),
                          incidence=inc).depth_mm
        real_id, box_id = 5 << 16, 7 | 1 << 8 | 4 << 16
        depth = real_depth_m(real)
        ids = np.full((h, w), real_id, np.uint32)
        box = (slice(180, 330), slice(250, 330))
        depth[box] = 1.5
        ids[box] = box_id
        out = simulate_over_real(g, depth, np.random.default_rng(1), real_mm=real,
                                 labels=ids, real_label=real_id, incidence=inc)
    finally:
        g.release()
    rows, cols = reach_px(g, 1.5)
    far = np.ones((h, w), bool)
    far[180 - rows:330 + rows, 250 - cols:330 + cols] = False
    assert (out.depth_mm[far] == real[far]).all()
    assert (out.labels[far] == real_id).all()
    assert out.valid[190:320, 260:320].mean() > 0.95
    assert sum(out.holes.values()) == int((~out.valid).sum())


@pytest.mark.gl
def test_reading_the_render_target_equals_the_uploaded_arrays(gl_ctx, body, tmp_path):
    """simulate_target (the frame read where the renderer drew it, no upload) gives the
    very bytes simulate gives on the read-back view, with the packed ids moved alike."""
    from vhgen.body.skinning import bone_matrices
    from vhgen.camera import look_at
    from vhgen.render.renderer import DepthLabelRenderer, Draw
    from vhgen.render.sensor_gl import GLSensorModel

    cfg = SensorConfig.load("openni_525")
    ren = DepthLabelRenderer(gl_ctx, cfg.intrinsics, incidence=True)
    g = GLSensorModel(gl_ctx, cfg)
    try:
        mesh = ren.upload(body.vertices, body.faces, body.joints, body.weights,
                          body.face_labels, body.num_bones)
        b = body.num_bones
        mats = bone_matrices(body.rig, np.broadcast_to(np.eye(3), (b, 3, 3)),
                             body.rig.heads[0])
        view = ren.draw([Draw(mesh, look_at([0, 0.9, 2.6], [0, 0.85, 0]) @ mats, 1, 4)])
        target = g.simulate_target(ren, np.random.default_rng(8))
        arrays = g.simulate(view.depth, np.random.default_rng(8), labels=view.ids,
                            incidence=view.incidence)
        mesh.release()
    finally:
        g.release()
        ren.release()
    assert target.valid.sum() > 10000
    for k in ("depth_mm", "valid", "labels", "raw11", "disparity"):
        np.testing.assert_array_equal(getattr(target, k), getattr(arrays, k), err_msg=k)
    assert target.labels.dtype == np.uint32 and target.holes == arrays.holes
