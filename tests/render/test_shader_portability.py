"""Every shader vhgen compiles, in the variants jobs ask for, passes the Khronos reference
compiler (glslangValidator; ``bash scripts/setup.sh dev`` installs it). CI renders with
Mesa, whose compiler accepts some sources that the GLSL specification, and so a GPU
vendor's compiler, need not; and some variants (the row scans' 128 invocations a row)
are what a GPU runs, not llvmpipe. A shader that a GPU driver refuses would fail every
worker of a job on a GPU node, where no test runs."""

from __future__ import annotations

import shutil
import subprocess
from itertools import product

import numpy as np
import pytest

GLSLANG = shutil.which("glslangValidator")


def _refused(sources: dict[str, str], tmp_path) -> list[str]:
    """The sources (by file name; the suffix names the stage) glslangValidator refuses,
    each with its first error line."""
    bad = []
    for i, (name, src) in enumerate(sorted(sources.items())):
        path = tmp_path / f"{i}.{name.rsplit('.', 1)[1]}"
        path.write_text(src)
        run = subprocess.run([GLSLANG, str(path)], capture_output=True, text=True)
        if run.returncode != 0:
            errors = [ln for ln in run.stdout.splitlines() if "ERROR" in ln]
            bad.append(f"{name}: {(errors or [run.stdout.strip()])[0]}")
    return bad


def test_the_reference_compiler_is_installed():
    assert GLSLANG, "glslangValidator not found: bash scripts/setup.sh dev installs glslang-tools"


def test_the_reference_compiler_refuses_what_the_spec_does(tmp_path):
    """The check can fail: an implicit float-to-int conversion, which the spec forbids."""
    src = "#version 430\nlayout(local_size_x = 1) in;\nvoid main() { int i = 1.5; }\n"
    assert _refused({"bad.comp": src}, tmp_path)


def test_renderer_shaders_in_every_variant(tmp_path):
    from vhgen.render.renderer import SKINNING_MODES, _defines, _shader

    sources = {}
    for mode, incidence, garments, background in product(SKINNING_MODES, *[(False, True)] * 3):
        defs = _defines(64, mode)
        defs.update({"WANT_INCIDENCE": 1} if incidence else {})
        defs.update({"GARMENTS": 1, "CLOTH_MARGIN": "0.004"} if garments else {})
        defs.update({"BACKGROUND_DEPTH": 1} if background else {})
        key = f"{mode}-{int(incidence)}{int(garments)}{int(background)}"
        sources[f"{key}-skin.vert"] = _shader("skin.vert", defs)
        sources[f"{key}-skin.frag"] = _shader("skin.frag", defs)
    for mode in SKINNING_MODES:
        sources[f"{mode}-skin_feedback.vert"] = _shader("skin_feedback.vert", _defines(64, mode))
    assert len(sources) == 34
    assert _refused(sources, tmp_path) == []


@pytest.mark.gl
def test_sensor_passes_of_every_shipped_sensor_in_both_row_layouts(tmp_path, monkeypatch):
    """Every compute program the GL sensor builds for the shipped sensors (the fused
    per-pixel chains, the row scans with one and with 128 invocations a row, the window's
    and the speckle filter's steps), as it builds them."""
    import vhgen.render.sensor_gl as sensor_gl
    from vhgen.errors import ConfigError
    from vhgen.render.context import create_context
    from vhgen.sensor.sensor_config import SensorConfig
    from vhgen.yamlio import configs_dir

    sources: dict[str, str] = {}  # each source built once, with its file's name
    build = sensor_gl._shader

    def recorded(name, defines):
        src = build(name, defines)
        sources.setdefault(src, name)
        return src

    monkeypatch.setattr(sensor_gl, "_shader", recorded)
    ctx = create_context("egl")
    ran = []
    try:
        for path in sorted((configs_dir() / "sensors").glob("*.yaml")):
            try:
                cfg = SensorConfig.load(path).with_backend("gl")
            except ConfigError:
                continue  # an effect without a GL pass: the config refuses backend gl
            h, w = cfg.intrinsics.height, cfg.intrinsics.width
            z = np.full((h, w), 3.0, np.float32)
            z[h // 4: 3 * h // 4, w // 3: w // 2] = 1.2  # a box: shadow and occlusion bands
            kw = {"labels": np.ones((h, w), np.uint32),
                  "incidence": np.ones((h, w), np.float32),
                  "projector_depth": z}
            for row_threads in (1, 128):
                model = sensor_gl.GLSensorModel(ctx, cfg, row_threads=row_threads)
                try:
                    model.simulate(z, np.random.default_rng(0), **kw)
                finally:
                    model.release()
            ran.append(path.stem)
    finally:
        ctx.release()
    assert {"openni_525", "kinect_v1_full", "kinect_v1_exact_shadows"} <= set(ran)
    assert {"sensor_chain.comp", "sensor_scan.comp", "sensor_speckle.comp",
            "sensor_window.comp"} <= set(sources.values())
    numbered = {f"{i}-{name}": src for i, (src, name) in enumerate(sources.items())}
    assert _refused(numbered, tmp_path) == []
