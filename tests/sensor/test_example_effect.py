"""The worked example of docs/architecture.md: the file shown there is this code, it
registers itself, loads from a sensor file and does what it says."""

import importlib.util
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from vhgen.errors import ConfigError
from vhgen.sensor.simulator import SensorConfig, SensorModel

DOCS = Path(__file__).resolve().parents[2] / "docs"
EXAMPLE = DOCS / "examples" / "edge_cleanup.py"


def _example():
    name = "vhgen_docs_edge_cleanup"
    if name not in sys.modules:  # register once per process
        spec = importlib.util.spec_from_file_location(name, EXAMPLE)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def _sensor(tmp_path, effects: str) -> SensorConfig:
    p = tmp_path / "s.yaml"
    p.write_text("name: s\nwidth: 64\nheight: 48\nfx: 57.1\nfy: 57.1\ncx: 31.5\ncy: 23.5\n"
                 f"baseline_m: 0.075\neffects:\n{effects}")
    return SensorConfig.load(p)


def test_docs_show_the_example_file_verbatim():
    text = (DOCS / "architecture.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert EXAMPLE.read_text() in blocks
    # and the test shown there is this file's
    assert any(b in Path(__file__).read_text() and "def test_" in b for b in blocks)


def test_example_effect_removes_flying_pixels(tmp_path):
    _example()  # imports docs/examples/edge_cleanup.py once
    cfg = _sensor(tmp_path, "  - range_gate: {}\n  - edge_cleanup: {jump_px: 1.0}\n")
    z = np.full((48, 64), 3.0)
    z[:, 32:] = 1.5  # d = 1.43 px on the wall, 2.86 px on the box: a 1.43 px jump
    out = SensorModel(cfg).simulate(z, None)
    assert out.holes["edge"] == 2 * 48
    assert not out.valid[:, 31:33].any() and out.valid[:, :31].all() and out.valid[:, 33:].all()
    cfg2 = _sensor(tmp_path, "  - edge_cleanup: {jump_px: 2.0}\n")
    assert SensorModel(cfg2).simulate(z, None).valid.all()  # below the threshold


def test_example_effect_parameters_are_validated(tmp_path):
    _example()
    with pytest.raises(ConfigError, match=r"effects\[0\]\.edge_cleanup\.jump_px: .*outside"):
        _sensor(tmp_path, "  - edge_cleanup: {jump_px: 0}\n")
