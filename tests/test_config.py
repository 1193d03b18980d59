import pytest

from vhgen.errors import ConfigError
from vhgen.job_config import JobConfig, SensorConfig
from vhgen.yamlio import configs_dir


def test_shipped_configs_load():
    cfg = JobConfig.load(configs_dir() / "scenes" / "default.yaml")
    assert cfg.sensor.intrinsics.width == 640 and cfg.motions == ("builtin:demo",)
    assert cfg.codec == "zstd"  # stores stay as they were unless output.codec says lz4
    for p in (configs_dir() / "sensors").glob("*.yaml"):
        SensorConfig.load(p)


@pytest.mark.parametrize("text, field", [
    ("name: x\nmotions: [a.bvh]\ncamera: {distanse_m: 2}\n", "camera.distanse_m"),
    ("name: x\nmotions: [a.bvh]\navatars: {count: 0}\n", "avatars.count"),
    ("name: x\nmotions: [a.bvh]\ncamera: {yaw_deg: [10, -10]}\n", "camera.yaw_deg"),
    ("name: x\nmotions: 3\n", "motions"),
    ("name: x\nmotions: [a.bvh]\nrender: {backend: vulkan}\n", "render.backend"),
    ("name: x\nmotions: [a.bvh]\nsensor: nosuch\n", "sensor"),
    ("name: x\nmotions: [a.bvh]\nseed: -1\n", "seed"),
    ("name: x\nmotions: [a.bvh]\noutput: {codec: gzip}\n", "output.codec"),
    ("name: x\nmotions: [a.bvh]\noutput: {arrays: [depth, labels, normals]}\n",
     "output.arrays"),
    ("name: x\nmotions: [a.bvh]\noutput: {arrays: [depth, classes]}\n", "output.arrays"),
    ("name: x\nmotions: [a.bvh]\noutput: {arrays: depth}\n", "output.arrays"),
    ("name: x\nmotions: [a.bvh]\nsensor: ideal\noutput: {arrays: [depth, labels, raw]}\n",
     "output.arrays"),
    ("name: x\nmotions: [a.bvh\n", "line"),
])
def test_bad_configs_name_file_and_field(tmp_path, text, field):
    p = tmp_path / "job.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as ei:
        JobConfig.load(p)
    assert str(p) in str(ei.value) and field in str(ei.value)


@pytest.mark.parametrize("old, new, field", [
    ("z_min_m: 0.8", "z_min_m: 5.0", "effects[0].range_gate.z_min_m"),
    ("- range_gate:", "- range_gait:", "unknown effect 'range_gait'"),
    ("sigma_px: 0.07", "sigma: 0.07", "effects[1].axial_noise.sigma"),
    ("model: disparity", "model: gaussian", "effects[1].axial_noise.model"),
    ("  - encode: {}\n", ""  , None),
])
def test_sensor_config_errors_name_the_field(tmp_path, old, new, field):
    src = (configs_dir() / "sensors" / "kinect_v1_fast.yaml").read_text()
    p = tmp_path / "s.yaml"
    p.write_text(src.replace(old, new))
    if field is None:  # encode is optional
        assert SensorConfig.load(p).effect("encode") is None
        return
    with pytest.raises(ConfigError) as ei:
        SensorConfig.load(p)
    assert field in str(ei.value) and str(p) in str(ei.value)


def test_output_arrays(tmp_path):
    """raw is written only when asked for; the names come back in the store's order; a
    wrong name is one line naming the field and the known arrays."""
    p = tmp_path / "job.yaml"
    p.write_text("name: x\nmotions: [a.bvh]\nsensor: openni_525\n")
    cfg = JobConfig.load(p)  # the sensor keeps raw11, the store does not unless asked
    assert cfg.sensor.encoding.raw11 and cfg.arrays == ("depth", "labels", "instances",
                                                        "classes")
    assert cfg.compression_level is None  # each array's own level
    p.write_text("name: x\nmotions: [a.bvh]\nsensor: openni_525\n"
                 "output: {arrays: [raw, labels, depth], compression_level: 5}\n")
    cfg = JobConfig.load(p)
    assert cfg.arrays == ("depth", "labels", "raw") and cfg.compression_level == 5
    p.write_text("name: x\nmotions: [a.bvh]\noutput: {arrays: [depth, labels, normals]}\n")
    with pytest.raises(ConfigError) as ei:
        JobConfig.load(p)
    msg = str(ei.value)
    assert "\n" not in msg and "output.arrays" in msg and "'normals'" in msg
    assert "depth, labels, instances, classes, raw" in msg


def test_output_codec(tmp_path):
    p = tmp_path / "job.yaml"
    p.write_text("name: x\nmotions: [a.bvh]\noutput: {codec: lz4, frames_per_shard: 4}\n")
    cfg = JobConfig.load(p)
    assert cfg.codec == "lz4" and cfg.frames_per_shard == 4
