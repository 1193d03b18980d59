"""Every shipped sensor gives the same bytes as when the fingerprints were recorded.

Synthetic NumPy frames (no GL, so no rasteriser rounding) exercise every effect: a tilted
wall, a near box casting a projector shadow, thin rods, pixels outside the range gate, no
hit, NaN and inf. Each shipped sensor runs on each frame with a fixed per-frame seed; the
sha256 of depth_mm, labels, raw11 and the hole counts must match
``fingerprints.json`` (recorded before the sensor refactoring of issue 11).

Regenerate (only when an output is meant to change, and say why in the commit):
``.venv/bin/python tests/sensor/test_bit_identity.py``.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from vhgen.quality.fidelity_scenes import Frame, Rect, analytic_frame
from vhgen.sensor.simulator import SensorConfig, SensorModel
from vhgen.yamlio import configs_dir

STORE = Path(__file__).with_name("fingerprints.json")
SENSORS = sorted(p.stem for p in (configs_dir() / "sensors").glob("*.yaml"))


def frames(cfg: SensorConfig) -> list[tuple[Frame, int]]:
    """Two synthetic frames at the sensor's resolution, each with its seed."""
    intr, b = cfg.intrinsics, cfg.baseline_m
    f = intr.fx
    rects = [Rect(3.2, slope=0.3, label=1),  # tilted wall: grazing-angle effects
             Rect(1.2, x=(0.1, 0.7), y=(-0.4, 0.5), label=2),  # near box: shadow
             Rect(0.6, x=(-0.25, -0.1), y=(0.05, 0.2), label=3),  # nearer than z_min
             Rect(2.0, slope=-6.0, x=(-0.2, -0.1), y=(-0.5, -0.2), label=7),  # grazing
             Rect(2.0, x=(-0.5, -0.5 + 3 * 2.0 / f), y=(-0.6, 0.6), label=4),  # 3 px rod
             Rect(2.0, x=(-0.3, -0.3 + 6 * 2.0 / f), y=(-0.6, 0.6), label=5)]  # 6 px rod
    a = analytic_frame("scene", "mixed", intr, b, rects)
    v, u = np.mgrid[0:intr.height, 0:intr.width]
    # a gentle relief, so disparities vary inside every surface
    a.depth[:] = np.where(a.depth > 0, a.depth * (1 + 0.01 * np.sin(u / 7.0) *
                                                  np.cos(v / 11.0)), 0.0)
    a.depth[:40, :60] = 0.0  # no hit
    a.depth[-30:, -50:] = 9.0  # beyond every z_max
    a.depth[5, 5:10] = [np.nan, np.inf, -1.0, 1e9, 0.0]
    b2 = analytic_frame("steps", "step", intr, b,
                        [Rect(2.5, slope=-0.6, label=1), Rect(0.9, x=(-0.2, 0.05), label=6)])
    b2 = Frame(b2.name, b2.kind, b2.depth.astype(np.float32), b2.labels,
               b2.incidence.astype(np.float32), b2.projector_depth.astype(np.float32), b2.info)
    return [(a, 11), (b2, 12)]


def _sha(a: np.ndarray | None) -> str | None:
    if a is None:
        return None
    a = np.ascontiguousarray(a)
    return hashlib.sha256(a.dtype.str.encode() + str(a.shape).encode() + a.tobytes()).hexdigest()


def fingerprint(sensor: str) -> list[dict]:
    cfg = SensorConfig.load(sensor)
    model = SensorModel(cfg)
    out = []
    for fr, seed in frames(cfg):
        o = model.simulate(fr.depth, np.random.default_rng(seed), labels=fr.labels.copy(),
                           incidence=fr.incidence, projector_depth=fr.projector_depth)
        out.append({"depth_mm": _sha(o.depth_mm), "labels": _sha(o.labels),
                    "raw11": _sha(o.raw11), "holes": dict(sorted(o.holes.items())),
                    "valid_pixels": int(o.valid.sum())})
    return out


RECORDED = json.loads(STORE.read_text()) if STORE.is_file() else {}


@pytest.mark.parametrize("sensor", sorted(RECORDED))
def test_shipped_sensor_bytes_unchanged(sensor):
    assert fingerprint(sensor) == RECORDED[sensor]


def test_recorded_sensors_still_ship():
    # a sensor added later has no "before" to compare with; one recorded must not vanish
    assert RECORDED and set(RECORDED) <= set(SENSORS)


if __name__ == "__main__":
    STORE.write_text(json.dumps({s: fingerprint(s) for s in SENSORS}, indent=1) + "\n")
    print(f"wrote {STORE}")
