"""Realism statistics on synthetic frames with known answers, the distances, and the
bench command on the shared real frames."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.conftest import REPO
from tests.forest.conftest import write_store
from vhgen.cli import main
from vhgen.realism.compare import compare, table, wasserstein
from vhgen.realism.stats import (
    blob_areas,
    border_band,
    edge_runs,
    frame_stats,
    planar_patches,
    valid_fraction,
)
from vhgen.sensor.sensor_config import SensorConfig
from vhgen.sensor.simulator import SensorModel

REAL = REPO.parent / "shared" / "real"


def _sensor(tmp_path, effects: str, baseline: float = 0.075):
    p = tmp_path / "s.yaml"
    p.write_text(f"name: t\nwidth: 640\nheight: 480\nfx: 525\nfy: 525\ncx: 319.5\n"
                 f"cy: 239.5\nbaseline_m: {baseline}\neffects:\n{effects}")
    return SensorConfig.load(p)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_plane_noise_and_quantisation(dtype):
    """A fronto plane at 2 m with N(0, 4 mm) noise, then on 11 mm steps: the patch noise
    is the RMS of noise and rounding, the step is 11 mm."""
    rng = np.random.default_rng(0)
    z = (2.0 + rng.normal(0, 0.004, (480, 640))).astype(dtype)
    mm = np.rint(z * 1000).astype(np.uint16)
    zm, sig, step = planar_patches(mm, 525.0)
    assert len(zm) == 40 * 53 and abs(np.median(zm) - 2.0) < 0.002
    assert abs(np.median(sig) - 4.0) < 0.25  # 4 mm (+ 1 mm rounding, 0.29 mm RMS)
    q = (np.rint(z * 1000 / 11) * 11).astype(np.uint16)
    _, sig_q, step_q = planar_patches(q, 525.0)
    assert np.nanmedian(step_q) == 11.0
    assert abs(np.median(sig_q) - np.sqrt(4.0 ** 2 + 11 ** 2 / 12)) < 0.4
    # a tilted plane (inverse depth affine in the pixel) leaves no residual but rounding
    v, u = np.mgrid[0:480, 0:640]
    tilt = np.rint(1000 / (0.5 + 0.0005 * u + 0.0002 * v)).astype(np.uint16)
    _, sig_t, _ = planar_patches(tilt, 525.0)
    assert np.median(sig_t) < 0.45  # 1 mm rounding: RMS 0.29 mm


def test_box_shadow_width(tmp_path):
    """A box at 1.2 m before a wall at 3 m through the projector shadow: every shadow-side
    edge has a band of f b (1/z_f - 1/z_b) px, so width / jump = f b."""
    cfg = _sensor(tmp_path, "  - projector_shadow: {method: screen_space}\n")
    z = np.full((480, 640), 3.0)
    z[100:380, 250:400] = 1.2
    out = SensorModel(cfg).simulate(z, None)
    sj, sw, oj, ow = edge_runs(out.depth_mm, 525.0)
    fb = 525.0 * 0.075
    expect = fb * (1 / 1.2 - 1 / 3.0)  # 19.7 px
    assert len(sw) == 280 and np.all(np.abs(sw - expect) <= 1.0)
    assert np.all(np.abs(sw / sj - fb) <= 1.0 / sj)
    # the other side of the box: no band without registration
    assert len(ow) == 280 and np.all(ow == 0)
    st = frame_stats(out.depth_mm, 525.0)
    assert st.shadow_width.size == 280


def test_border_band_blobs_and_speckles():
    d = np.full((480, 640), 2000, np.uint16)
    d[:, :10] = 0
    d[:, -7:] = 0
    d[:5] = 0
    d[-3:] = 0
    np.testing.assert_array_equal(border_band(d), [10, 7, 5, 3])
    d[200:204, 300:303] = 0       # a 12 px hole
    d[100, 100] = 0               # a 1 px hole
    d[300:320, 300:320] = 0       # a hole with a 2x2 speckle inside
    d[305:307, 305:307] = 2000
    holes, speckles = blob_areas(d)
    assert sorted(holes.tolist())[:3] == [1, 12, 396]
    assert speckles.tolist() == [4]
    assert valid_fraction(np.zeros((3, 3), np.uint16)) == 0.0


def test_distances():
    a = np.array([0.8, 0.81, 0.79])
    assert wasserstein(a, a) == 0.0
    assert abs(wasserstein(a, a - 0.2) - 0.2) < 1e-12
    assert np.isnan(wasserstein(a, np.zeros(0)))


def test_compare_real_against_real():
    """The captures against themselves are at distance 0; against person.pcd not."""
    from vhgen.realism.collect import real_stats

    caps = real_stats([str(REAL / f"capture000{i}.pcd") for i in (1, 2)]).stats
    person = real_stats([str(REAL / "person.pcd")]).stats
    same = compare(caps, caps)
    assert all(e["distance"] == 0 or np.isnan(e["distance"]) for e in same.values())
    other = compare(caps, person)
    assert other["border_band"]["distance"] > 3  # person.pcd: 14 px on the left, not 28
    assert other["speckles"]["real"] == 0 and other["speckles"]["sim"] == 0
    text = table("real", {"person": other})
    assert "valid-pixel fraction" in text and "border band" in text


def test_bench_realism_cli(tmp_path, capsys):
    """The command on the shared frames (and one bad file) against a tiny store: a table,
    a JSON, a PNG; the bad file is one warning line."""
    rng = np.random.default_rng(0)
    d = np.full((3, 480, 640), 2500, np.uint16)
    d[:, :, :30] = 0
    d += rng.integers(0, 20, d.shape).astype(np.uint16) * (d > 0)
    store = write_store(tmp_path / "s.zarr", d, np.zeros(d.shape, np.uint8))
    (tmp_path / "bad.pcd").write_bytes(b"nonsense\n")
    code = main(["bench", "realism", str(REAL / "capture0001.pcd"), str(REAL / "person.pcd"),
                 str(tmp_path / "bad.pcd"), "--store", store, "--out", str(tmp_path / "o")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert err.count("\n") == 1 and "bad.pcd" in err and "warning" in err
    assert "valid-pixel fraction" in out and "real (2)" in out
    res = json.loads((tmp_path / "o" / "realism.json").read_text())
    r = res["results"]["s.zarr"]
    assert abs(r["valid_fraction"]["sim"] - (1 - 30 / 640)) < 1e-9
    assert r["border_band"]["sim_sides"] == [30, 0, 0, 0]
    assert (tmp_path / "o" / "realism.png").stat().st_size > 10000
    code = main(["bench", "realism", str(tmp_path / "bad.pcd"), "--store", store])
    _, err = capsys.readouterr()
    assert code == 2 and err.splitlines()[-1].startswith("vhgen: error: no readable real")
