"""A job with ``sensor: {preset: openni_525, backend: gl}``: the frame path runs the GL
sensor, writes a store like the CPU sensor's, and the two stores are close on the realism
bench's statistics."""

from __future__ import annotations

import json

import numpy as np
import pytest

JOB = """
name: {name}
seed: 11
motions: [builtin:demo]
sensor: {{preset: openni_525, backend: {backend}}}
poses: {{frame_step: 40}}
avatars: {{count: 2}}
camera: {{preset: tv_top_kinect}}
scene:
  floor: true
  room: {{width_m: [4, 6], depth_m: [4.5, 6], height_m: [2.4, 2.8], yaw_deg: [-20, 20]}}
  people: [1, 2]
  props: {{count: [1, 2], kinds: [box, table]}}
output: {{frames_per_shard: 4, arrays: [depth, labels, instances, classes, raw]}}
render: {{backend: egl}}
num_workers: 1
"""
FRAMES = 8


@pytest.mark.gl
def test_gl_sensor_job_writes_a_store_close_to_the_cpu_one(tmp_path):
    import pyarrow.parquet as pq
    import zarr

    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job
    from vhgen.quality.realism_bench import store_stats
    from vhgen.realism.compare import compare

    stores = {}
    for backend in ("cpu", "gl"):
        p = tmp_path / f"{backend}.yaml"
        p.write_text(JOB.format(name=backend, backend=backend))
        cfg = JobConfig.load(p)
        assert cfg.sensor.backend == backend
        stores[backend] = tmp_path / f"{backend}.zarr"
        run_job(cfg, stores[backend], max_frames=FRAMES, executor="local")
    cpu, gl = (zarr.open_group(str(stores[b]), mode="r") for b in ("cpu", "gl"))
    for key in ("depth", "labels", "instances", "classes", "raw"):
        assert gl[key].shape == cpu[key].shape and gl[key].dtype == cpu[key].dtype, key
    # the truth is the renderer's: labels agree but where lateral noise moved them
    same = np.mean(np.asarray(gl["classes"][:]) == np.asarray(cpu["classes"][:]))
    assert same > 0.97
    rows = pq.read_table(stores["gl"] / "manifest.parquet").to_pylist()
    assert len(rows) == FRAMES
    assert json.loads(rows[0]["sensor"])["backend"] == "gl"
    assert "backend" not in json.loads(
        pq.read_table(stores["cpu"] / "manifest.parquet").to_pylist()[0]["sensor"])
    s_cpu, _ = store_stats(stores["cpu"])
    s_gl, _ = store_stats(stores["gl"])
    res = compare(s_cpu, s_gl)  # "real" = the CPU store
    assert abs(res["valid_fraction"]["sim"] - res["valid_fraction"]["real"]) < 0.01
    assert abs(res["noise_coeff"]["sim"] / res["noise_coeff"]["real"] - 1) < 0.1
    assert abs(res["quant_step"]["sim"] / res["quant_step"]["real"] - 1) < 0.05
    assert abs(res["holes_per_frame"]["sim"] / res["holes_per_frame"]["real"] - 1) < 0.15
    assert res["border_band"]["distance"] < 0.5
