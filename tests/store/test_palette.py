"""vhgen.palette (depth's lossless filter before zstd): exact round trips, smaller stores,
readable by plain zarr through the entry point, and damaged chunks named."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import write_synthetic_store
from vhgen.errors import ShardError
from vhgen.store import palette
from vhgen.store.shards import ShardReader, array_layout

REAL = Path(__file__).resolve().parents[3] / "shared" / "real"


def _sensor_like(rng, n=4, h=96, w=128) -> np.ndarray:
    """Depth as a structured-light sensor gives it: millimetres of disparity quantised to
    1/8 px (fx 580, baseline 75 mm), a plane, a nearer box and noise, and holes."""
    y, x = np.mgrid[:h, :w]
    z = 1500.0 + 8.0 * y + 2.0 * x + np.where((abs(x - 60) < 20) & (abs(y - 50) < 25), -600, 0)
    out = []
    for _ in range(n):
        disp = 580 * 75 / (z + rng.normal(0, 4, z.shape))
        mm = np.round(580 * 75 / (np.round(disp * 8) / 8)).astype(np.uint16)
        mm[rng.random(z.shape) < 0.05] = 0
        out.append(mm)
    return np.stack(out)


@pytest.mark.parametrize("values", [
    "sensor", "few", "many", "all", "odd", "single", "empty"])
def test_round_trip_is_exact(values):
    rng = np.random.default_rng(1)
    data = {"sensor": lambda: _sensor_like(rng, 1)[0],
            "few": lambda: rng.choice([0, 700, 4095], (48, 64)).astype(np.uint16),
            "many": lambda: rng.integers(0, 600, (48, 64)).astype(np.uint16),  # 2 planes
            "all": lambda: np.arange(65536, dtype=np.uint16)[rng.permutation(65536)],
            "odd": lambda: rng.integers(1000, 1100, (7, 9)).astype(np.uint16),
            "single": lambda: np.array([65535], np.uint16),
            "empty": lambda: np.zeros((0, 5), np.uint16)}[values]()
    n = len(np.unique(data))
    width = data.shape[-1] if data.ndim == 2 and data.shape[-1] else 1
    for rows in (None, width):  # the plain indexes (stores written before), differences
        enc = palette.encode(data, rows)
        assert enc.size == (4 + (4 if rows else 0) + 2 * n
                            + data.size * (2 if n > 256 else 1))
        for buf in (enc, enc.tobytes()):
            out = np.full_like(data, 12345)
            palette.decode_into(buf, out)
            assert np.array_equal(out, data)


def test_differences_down_the_rows_are_mostly_zero_and_flagged():
    """On sensor-like depth the differences from the row above are mostly 0 (what makes
    zstd's work small); the chunk's first word carries the flag, so a decoder that does
    not know it reads far too many values and fails on the size, never with wrong
    values; a width that does not divide the chunk is refused."""
    frame = _sensor_like(np.random.default_rng(3), 1)[0]
    plain, rows = palette.encode(frame), palette.encode(frame, frame.shape[1])
    n = len(np.unique(frame))
    idx_plain, idx_rows = plain[4 + 2 * n:], rows[8 + 2 * n:]
    assert np.mean(idx_rows == 0) > 2 * np.mean(idx_plain == idx_plain[0])
    first = int(rows[:4].view("<u4")[0])
    assert first & palette.ROWS and first & ~palette.ROWS == n
    assert int(rows[4:8].view("<u4")[0]) == frame.shape[1]
    with pytest.raises(ValueError, match="rows of"):
        palette.encode(frame, 7)
    bad = rows.copy()
    bad[4:8] = np.array([7], "<u4").view(np.uint8)
    with pytest.raises(palette.PaletteError, match="rows of 7"):
        palette.decode_into(bad, np.empty_like(frame))
    bad = rows.copy()
    assert n <= 256  # one plane: the last pixel's difference adds up to index n
    above = int(np.searchsorted(np.unique(frame), frame[-2, -1]))
    bad[-1] = (n - above) % 256
    with pytest.raises(palette.PaletteError, match="past its"):
        palette.decode_into(bad, np.empty_like(frame))


def test_damaged_chunks_raise():
    data = np.random.default_rng(2).integers(0, 40, (16, 16)).astype(np.uint16)
    enc = palette.encode(data)
    out = np.empty_like(data)
    with pytest.raises(palette.PaletteError, match="expected"):
        palette.decode_into(enc[:-3], out)  # cut short
    with pytest.raises(palette.PaletteError, match="header"):
        palette.decode_into(enc[:2], out)
    bad = enc.copy()
    bad[-1] = 250  # an index past the 40 values
    with pytest.raises(palette.PaletteError, match="past its"):
        palette.decode_into(bad, out)
    with pytest.raises(TypeError):
        palette.decode_into(enc, out.astype(np.int32))


def _real_frames() -> np.ndarray:
    """Real PrimeSense frames (PCD, millimetres) from ../shared/real, and one Kinect v1
    PNG of skeltrack/ (its person alone, the rest 0)."""
    from vhgen.depthfile import read_depth, read_png_mm

    pcd = [np.round(np.nan_to_num(read_depth(REAL / f"capture000{i}.pcd").depth_m) * 1000)
           .astype(np.uint16) for i in (1, 2, 3, 4)]
    png = read_png_mm(REAL / "skeltrack" / "depth-data-1028894671.png")
    return np.stack([*pcd, png, pcd[0][::-1].copy()])


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The same real frames written with and without the palette (zstd 3)."""
    from vhgen.store.zarr_store import create_store, write_shard

    frames = _real_frames()
    labels = (frames > 1500).astype(np.uint8)
    stores = {}
    for use in (True, False):
        path = tmp_path_factory.mktemp("palette") / f"{use}.zarr"
        create_store(path, num_frames=6, height=480, width=640, frames_per_shard=2,
                     attrs={"label_names": ["a"]}, palette=use)
        for s in range(3):
            part = slice(2 * s, 2 * s + 2)
            write_shard(path, s, 2, frames[part], labels[part],
                        extra={"instances": labels[part], "classes": labels[part]})
        stores[use] = path
    return frames, stores


def _bytes(path, name):
    return sum(f.stat().st_size for f in (path / name / "c").rglob("*") if f.is_file())


def test_store_is_smaller_and_reads_the_same(pair):
    import zarr

    frames, stores = pair
    codecs = json.loads((stores[True] / "depth" / "zarr.json").read_text())
    inner = codecs["codecs"][0]["configuration"]["codecs"]
    assert [c["name"] for c in inner] == ["bytes", "vhgen.palette", "zstd"]
    assert inner[1]["configuration"] == {"typesize": 2, "rows": True}
    labels = json.loads((stores[True] / "labels" / "zarr.json").read_text())
    assert "vhgen.palette" not in json.dumps(labels)  # uint8 arrays: zstd alone
    plain = json.loads((stores[False] / "depth" / "zarr.json").read_text())
    assert "vhgen.palette" not in json.dumps(plain)
    # real frames hold 120-160 values (1/8 px disparity steps): 8-11% fewer bytes here
    assert _bytes(stores[True], "depth") < 0.95 * _bytes(stores[False], "depth")
    for use in (True, False):
        assert np.array_equal(zarr.open_group(str(stores[use]), mode="r")["depth"][:],
                              frames)
        reader = ShardReader(stores[use], ["depth"], threads=2)
        layout = array_layout(stores[use], "depth")
        assert layout is not None and layout.palette is use
        out = reader.empty("depth", 6)
        order = np.random.default_rng(4).permutation(6)
        reader.read_into([("depth", int(f), out[k]) for k, f in enumerate(order)])
        assert np.array_equal(out, frames[order])


def test_plain_zarr_reads_it_through_the_entry_point(pair):
    """A user's own zarr code, vhgen never imported: the installed entry point finds the
    codec."""
    frames, stores = pair
    code = ("import sys, zarr, numpy as np; "
            f"a = zarr.open_group({str(stores[True])!r}, mode='r')['depth'][:]; "
            "print(int(a.astype(np.int64).sum()))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert int(run.stdout.split()[-1]) == int(frames.astype(np.int64).sum())


def test_damaged_palette_chunk_names_the_shard(pair, tmp_path):
    import shutil

    _, stores = pair
    out = tmp_path / "d.zarr"
    shutil.copytree(stores[True], out)
    shard = out / "depth" / "c" / "1" / "0" / "0"
    data = bytearray(shard.read_bytes())
    data[20:60] = bytes(40)  # inside frame 2's zstd frame
    shard.write_bytes(bytes(data))
    reader = ShardReader(out, ["depth"], threads=1)
    found: list[ShardError] = []
    got = reader.empty("depth", 6)
    reader.read_into([("depth", f, got[f]) for f in range(6)], errors=found)
    assert len(found) == 1 and found[0].shard == 1 and "depth" in str(found[0])
    assert np.array_equal(got[4:], pair[0][4:])  # the other shards still read


def test_config_palette_flag(tmp_path):
    from vhgen.errors import ConfigError
    from vhgen.job_config import JobConfig

    base = (tmp_path / "c.yaml")
    for text, want in (("", True), ("  palette: false\n", False),
                       ("  codec: lz4\n", False), ("  codec: lz4\n  palette: true\n", True)):
        base.write_text("name: t\nmotions: [a.bvh]\noutput:\n  frames_per_shard: 4\n" + text)
        assert JobConfig.load(base).palette is want
    base.write_text("name: t\nmotions: [a.bvh]\noutput:\n  palette: maybe\n")
    with pytest.raises(ConfigError, match="output.palette"):
        JobConfig.load(base)


def test_synthetic_store_uses_it_by_default(tmp_path):
    path = write_synthetic_store(tmp_path / "s.zarr", frames=4, frames_per_shard=2)
    layout = array_layout(path, "depth")
    assert layout is not None and layout.palette


def test_codec_refuses_other_dtypes(tmp_path):
    import zarr

    from vhgen.store.palette import PaletteCodec

    with pytest.raises(ValueError, match="uint16"):
        zarr.create_array(str(tmp_path / "a.zarr"), shape=(4, 4), chunks=(2, 2),
                          dtype="float32", compressors=[PaletteCodec()])
    ok = zarr.create_array(str(tmp_path / "b.zarr"), shape=(4, 4), chunks=(2, 2),
                           dtype="uint16", compressors=[PaletteCodec()])
    ok[:] = np.arange(16, dtype=np.uint16).reshape(4, 4) * 1000
    assert np.array_equal(ok[:], np.arange(16).reshape(4, 4) * 1000)


def test_inspect_names_the_codecs(pair):
    from vhgen.store.inspect import inspect_store

    _, stores = pair
    text = inspect_store(stores[True]).format()
    assert "depth: bytes > vhgen.palette rows > zstd 3" in text
    assert "where vhgen is installed" in text
    plain = inspect_store(stores[False])
    assert plain.to_dict()["codecs"]["depth"] == "bytes > zstd 3"
    assert "where vhgen is installed" not in plain.format()


def test_store_of_the_plain_indexes_reads_the_same(tmp_path):
    """A store written before the differences (``vhgen.palette`` with ``{"typesize": 2}``
    only, zstd 7) reads through zarr and the training reader as it did."""
    import zarr
    from zarr.codecs import ZstdCodec

    from vhgen.store.palette import PaletteCodec, register

    register()
    frames = _sensor_like(np.random.default_rng(5), 4, 48, 64)
    root = zarr.open_group(str(tmp_path / "old.zarr"), mode="w", zarr_format=3)
    arr = root.create_array("depth", shape=frames.shape, dtype="uint16", chunks=(1, 48, 64),
                            shards=(2, 48, 64), compressors=[PaletteCodec(), ZstdCodec(level=7)],
                            fill_value=0, dimension_names=("frame", "y", "x"))
    arr[:] = frames
    meta = json.loads((tmp_path / "old.zarr" / "depth" / "zarr.json").read_text())
    assert {"typesize": 2} in [c.get("configuration") for c in
                               meta["codecs"][0]["configuration"]["codecs"]]
    assert np.array_equal(zarr.open_group(str(tmp_path / "old.zarr"), mode="r")["depth"][:],
                          frames)
    reader = ShardReader(tmp_path / "old.zarr", ["depth"], threads=1)
    out = reader.empty("depth", 4)
    reader.read_into([("depth", f, out[f]) for f in range(4)])
    assert np.array_equal(out, frames)
