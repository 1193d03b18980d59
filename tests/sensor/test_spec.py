"""Effect specs: typed fields, errors naming file and field, orderings checked at load."""

import numpy as np
import pytest

from vhgen.errors import ConfigError
from vhgen.sensor.effects import CorrelationWindow, LensDistortion, ProjectorShadow
from vhgen.sensor.simulator import SensorConfig, SensorModel
from vhgen.sensor.spec import SpecError, effect_types

F, B = 571.26, 0.075
H, W = 48, 64


def _load(effects: str, tmp_path, name="t") -> SensorConfig:
    p = tmp_path / f"{name}.yaml"
    p.write_text(f"name: {name}\nwidth: {W}\nheight: {H}\nfx: {F}\nfy: {F}\ncx: {(W - 1) / 2}\n"
                 f"cy: {(H - 1) / 2}\nbaseline_m: {B}\npattern_seed: 3\neffects:\n{effects}")
    return SensorConfig.load(p)


def test_fields_are_typed_and_integers_stay_integers():
    cw = CorrelationWindow(window=7)
    assert isinstance(cw.window, int) and cw.to_dict() == {"correlation_window": {
        "window": 7, "frac": 1 / 1.5, "inlier_px": 0.1, "splat_radius_px": 3.1}}
    assert isinstance(ProjectorShadow(tolerance=0).tolerance, float)
    nine = CorrelationWindow.from_dict({"window": 9.0})  # as older sensor files wrote it
    assert nine.window == 9 and isinstance(nine.window, int)
    with pytest.raises(AttributeError):
        cw.window = 9  # type: ignore[misc]  # frozen


@pytest.mark.parametrize("effect, field, message", [
    ("correlation_window: {window: 9.5}", "effects[1].correlation_window.window",
     "must be an integer"),
    ("correlation_window: {window: 8}", "effects[1].correlation_window.window", "must be odd"),
    ("structured_light: {window: 10}", "effects[1].structured_light.window", "must be odd"),
    ("structured_light: {d_min_px: 7.5}", "effects[1].structured_light.d_min_px",
     "must be an integer"),
    ("axial_noise: {model: gauss}", "effects[1].axial_noise.model", "not one of"),
    ("axial_noise: {angle_term: 1}", "effects[1].axial_noise.angle_term", "true/false"),
    ("dropout: {max_angle_deg: 95}", "effects[1].dropout.max_angle_deg",
     r"outside \[0.0, 90.0\] deg"),
    ("dropout: {max_angel_deg: 5}", "effects[1].dropout.max_angel_deg", "unknown parameter"),
    ("range_gate: {z_min_m: 5, z_max_m: 4}", "effects[1].range_gate.z_min_m", "below z_max_m"),
    ("lens_distortion: {k1: .nan}", "effects[1].lens_distortion.k1", "finite"),
    ("encode: {raw11: yes please}", "effects[1].encode.raw11", "true/false"),
    ("warp_drive: {}", "effects[1]", "unknown effect"),
])
def test_bad_parameter_names_file_and_field(tmp_path, effect, field, message):
    with pytest.raises(ConfigError, match=message) as e:
        _load(f"  - range_gate: {{}}\n  - {effect}\n", tmp_path)
    assert e.value.field == field
    assert e.value.source is not None and e.value.source.endswith("t.yaml")


def test_encoding_is_one_field_last_in_the_list(tmp_path):
    cfg = _load("  - range_gate: {}\n  - encode: {raw11: true, d_off: 1000}\n", tmp_path)
    assert cfg.encoding.raw11 and cfg.encoding.d_off == 1000.0
    assert cfg.effect_names == ["range_gate"]
    assert cfg.to_dict()["effects"][-1] == {"encode": {"raw11": True, "d_off": 1000.0}}
    with pytest.raises(ConfigError, match="encode must come last"):
        _load("  - encode: {}\n  - range_gate: {}\n", tmp_path)
    with pytest.raises(ConfigError, match="listed twice"):
        _load("  - range_gate: {}\n  - range_gate: {}\n", tmp_path)


def test_shadow_then_lens_distortion_runs(tmp_path):
    """The crash of issue 11: lens_distortion after an effect that moved the state to
    disparity. Its undistortion map is built with the stage, so it now runs."""
    cfg = _load("  - projector_shadow: {}\n  - lens_distortion: {}\n", tmp_path)
    z = np.full((H, W), 2.0)
    z[:, W // 2:] = 1.0
    out = SensorModel(cfg).simulate(z, None, labels=np.ones((H, W), np.uint8))
    assert out.holes["shadow"] > 0 and out.valid.any()
    assert set(np.unique(out.depth_mm[out.valid])) <= {1000, 2000}


@pytest.mark.parametrize("late", ["projector_shadow: {method: exact}", "structured_light: {}"])
def test_projector_reads_after_lens_distortion_are_refused_with_a_reason(tmp_path, late):
    with pytest.raises(ConfigError, match="reads projector_depth.*list .* before "
                                          "lens_distortion") as e:
        _load(f"  - lens_distortion: {{}}\n  - {late}\n", tmp_path)
    assert e.value.field.startswith("effects[1].")
    # the other way round is fine
    _load(f"  - {late}\n  - lens_distortion: {{}}\n", tmp_path)


def test_specs_declare_channels_and_needs():
    assert ProjectorShadow(method="exact").needs == {"projector_depth"}
    assert ProjectorShadow().needs == frozenset()
    assert "pixel_grid" in LensDistortion().writes
    names = set(effect_types())
    assert {"range_gate", "structured_light", "correlation_window"} <= names
    assert "encode" not in names  # the encoding is a sensor field, not an effect
    with pytest.raises(SpecError):
        CorrelationWindow.from_dict({"windw": 3})
