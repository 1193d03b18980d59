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


BATCH_JOB = """
name: batches
seed: 5
motions: [builtin:demo]
labels: pcl25
sensor: {{preset: openni_525, backend: gl}}
poses: {{frame_step: 40}}
avatars: {{count: 2}}
camera: {{preset: tv_top_kinect, distance_m: [1.8, 2.6]}}
scene:
  floor: true
  room: {{width_m: [3, 4], depth_m: [5, 5.5], height_m: [2.4, 2.8], yaw_deg: [-25, 25]}}
  people: [1, 2]
  clutter: {{count: [4, 6], kinds: [window, shelf, plant, boxes]}}
output: {{frames_per_shard: {per_shard}}}
render: {{backend: egl, batch_frames: {batch}}}
num_workers: 1
"""


@pytest.mark.gl
def test_frames_in_batches_are_the_frames_one_by_one(tmp_path):
    """With the GL sensor a worker draws and senses render.batch_frames frames, two
    batches in flight, before it reads any back, and takes the window glass out on the
    GPU: every array and manifest row is what reading each frame back before the next
    gives (glass in view included; batches that do not divide a shard)."""
    import pyarrow.parquet as pq
    import zarr

    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    frames = 10
    stores = {}
    for batch in (0, 3, 8):
        p = tmp_path / f"b{batch}.yaml"
        p.write_text(BATCH_JOB.format(per_shard=5, batch=batch))
        cfg = JobConfig.load(p)
        assert cfg.batch_frames == batch
        stores[batch] = tmp_path / f"b{batch}.zarr"
        run_job(cfg, stores[batch], max_frames=frames, executor="local")
    ref = zarr.open_group(str(stores[0]), mode="r")
    glass = JobConfig.load(tmp_path / "b0.yaml").scene.no_return_ids
    classes = np.asarray(ref["classes"][:])
    assert sum(np.isin(c, glass).any() for c in classes) >= 2  # frames with glass in view
    rows = pq.read_table(stores[0] / "manifest.parquet").to_pylist()
    assert len(rows) == frames
    for batch in (3, 8):
        got = zarr.open_group(str(stores[batch]), mode="r")
        for key in ("depth", "labels", "instances", "classes"):
            np.testing.assert_array_equal(np.asarray(got[key][:]), np.asarray(ref[key][:]),
                                          err_msg=f"batch {batch}: {key}")
        assert pq.read_table(stores[batch] / "manifest.parquet").to_pylist() == rows


@pytest.mark.parametrize("value", ["-1", "2.5", "yes", "65"])
def test_a_bad_batch_size_is_one_line_naming_the_field(tmp_path, value):
    from vhgen.errors import ConfigError
    from vhgen.job_config import JobConfig

    p = tmp_path / "b.yaml"
    p.write_text(f"name: b\nmotions: [builtin:demo]\nrender: {{batch_frames: {value}}}\n")
    with pytest.raises(ConfigError, match="render.batch_frames") as e:
        JobConfig.load(p)
    assert "\n" not in str(e.value) and str(p) in str(e.value)


@pytest.mark.gl
def test_a_context_lost_with_batches_in_flight_is_a_dead_worker(tmp_path):
    """The GL context fails while a batch is in flight (injected at a shard's second
    batch): the worker exits, the shard is redone whole, and the store is the same bytes
    as a run without the fault, every frame once."""
    import pyarrow.parquet as pq

    from tests.pipeline.faulty_worker import run_faulty
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    p = tmp_path / "b.yaml"
    p.write_text(BATCH_JOB.format(per_shard=4, batch=2))
    cfg = JobConfig.load(p)
    run_job(cfg, tmp_path / "plain.zarr", max_frames=8, executor="local")
    summary = run_faulty(cfg, tmp_path / "lost.zarr", {"gl_lost_once": {1}},
                         max_frames=8, executor="local")
    assert summary.frames == 8 and summary.retries == 1

    def arrays(store):
        return {str(f.relative_to(store)): f.read_bytes() for f in sorted(store.rglob("*"))
                if f.is_file() and {"depth", "labels", "instances", "classes"} & set(f.parts)}

    a, b = arrays(tmp_path / "plain.zarr"), arrays(tmp_path / "lost.zarr")
    assert a and a == b
    frames = pq.read_table(tmp_path / "lost.zarr" / "manifest.parquet").column("frame")
    assert frames.to_pylist() == list(range(8))


@pytest.mark.gl
def test_a_batch_is_queued_without_waiting_for_the_gpu(tmp_path, monkeypatch):
    """Drawing and sensing a batch calls nothing that waits for the GPU (a buffer mapped
    or read, a target read back other than into a pixel buffer): moderngl's Buffer.clear
    maps the buffer, so one a frame in the speckle pass made the CPU wait for the frames
    in flight on a GPU node (3 ms a frame on an H200), where llvmpipe hides it. Only
    collecting a batch reads back."""
    import moderngl

    from vhgen.job_config import JobConfig
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job

    p = tmp_path / "b.yaml"
    p.write_text(BATCH_JOB.format(per_shard=4, batch=3))
    gen = FrameGenerator(prepare_job(JobConfig.load(p)))
    waits: list[str] = []
    submit = gen._submit

    def watched(*a, **k):
        waits.append("submit")
        try:
            return submit(*a, **k)
        finally:
            waits.append("done")

    def waiting(cls, name):
        original = getattr(cls, name)

        def call(self, *a, **k):
            into_buffer = name == "read_into" and isinstance(a[0], moderngl.Buffer)
            if waits and waits[-1] == "submit" and not into_buffer:  # a PBO: no wait
                waits.append(f"{cls.__name__}.{name}")
            return original(self, *a, **k)
        monkeypatch.setattr(cls, name, call)

    for cls, names in ((moderngl.Buffer, ("clear", "read", "read_into", "read_chunks")),
                       (moderngl.Framebuffer, ("read", "read_into")),
                       (moderngl.Texture, ("read", "read_into"))):
        for name in names:
            waiting(cls, name)
    monkeypatch.setattr(gen, "_submit", watched)
    try:
        got = list(gen.frames(0, 7))
    finally:
        gen.close()
    assert len(got) == 7 and waits.count("submit") == 3
    assert [w for w in waits if w not in ("submit", "done")] == []
