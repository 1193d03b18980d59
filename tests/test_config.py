import pytest

from vhgen.config import JobConfig, SensorConfig
from vhgen.errors import ConfigError
from vhgen.yamlio import configs_dir


def test_shipped_configs_load():
    cfg = JobConfig.load(configs_dir() / "scenes" / "default.yaml")
    assert cfg.sensor.intrinsics.width == 640 and cfg.motions == ("builtin:demo",)
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
    ("name: x\nmotions: [a.bvh\n", "line"),
])
def test_bad_configs_name_file_and_field(tmp_path, text, field):
    p = tmp_path / "job.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as ei:
        JobConfig.load(p)
    assert str(p) in str(ei.value) and field in str(ei.value)


def test_sensor_range_checked(tmp_path):
    src = (configs_dir() / "sensors" / "kinect_v1.yaml").read_text()
    p = tmp_path / "s.yaml"
    p.write_text(src.replace("z_min_m: 0.8", "z_min_m: 5.0"))
    with pytest.raises(ConfigError, match="z_min_m"):
        SensorConfig.load(p)
