"""`vhgen bench fidelity` and its analytic scene suite."""

import json

import numpy as np
import pytest

from vhgen.quality.fidelity_scenes import suite
from vhgen.sensor.sensor_config import SensorConfig

F, B = 571.26, 0.075


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """One quick run for both tests below: the structured-light reference, which every
    row is measured against, takes seconds a frame, and a second run computed it again."""
    from vhgen.quality.fidelity_bench import bench_fidelity

    out = tmp_path_factory.mktemp("fidelity")
    res = bench_fidelity(out, quick=True, human=False, backend="osmesa",
                         configs=("ideal", "kinect_v1_full"), gl_sensor=True)
    return out, res, json.loads((out / "fidelity.json").read_text())


@pytest.mark.gl
def test_bench_fidelity_quick(bench):
    out, res, data = bench
    assert (out / "fidelity.png").stat().st_size > 10_000
    assert "kinect_v1_full" in (out / "table.txt").read_text()
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


@pytest.mark.gl
def test_bench_fidelity_gl_rows_agree_with_the_cpu(bench):
    _, res, data = bench
    cfgs = data["configs"]
    assert "kinect_v1_reference [gl]" not in cfgs  # structured light has no GL pass
    cpu, gl = cfgs["kinect_v1_full"]["summary"], cfgs["kinect_v1_full [gl]"]["summary"]
    assert abs(cpu["valid_iou"] - gl["valid_iou"]) < 0.01
    assert abs(cpu["hole_iou"] - gl["hole_iou"]) < 0.02
    assert abs(cpu["shadow_width_error_px"] - gl["shadow_width_error_px"]) < 0.5
    assert abs(cpu["rms_raw"] - gl["rms_raw"]) < 0.1 * cpu["rms_raw"]
    assert "kinect_v1_full [gl]" in res["table"]


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
