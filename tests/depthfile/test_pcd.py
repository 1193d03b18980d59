"""The one depth reader: PCD (every encoding, against our writer and the shared real
files), PNG, intrinsics recovery, and one line per malformed file."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from tests.conftest import REPO
from vhgen.camera import Intrinsics, backproject
from vhgen.depthfile import (
    iter_depth_files,
    lzf,
    read_depth,
    recover_intrinsics,
    write_pcd,
)
from vhgen.depthfile.pcd import ENCODINGS, write_pcd_points
from vhgen.errors import DepthFileError

REAL = REPO.parent / "shared" / "real"
INTR = Intrinsics(64, 48, 57.0, 58.5, 31.5, 23.5)


def _depth(seed: int = 0) -> np.ndarray:
    """(48, 64) uint16 mm: a tilted wall with a box and some holes."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:48, 0:64]
    d = (2000 + 10 * u + 5 * v).astype(np.uint16)
    d[10:30, 20:40] = 1200
    d[rng.random(d.shape) < 0.1] = 0
    return d


# -- LZF ---------------------------------------------------------------------------------

def test_lzf_round_trip_and_back_references():
    rng = np.random.default_rng(1)
    for data in (b"", b"x", bytes(5000), b"abcd" * 3000,
                 rng.integers(0, 256, 4000, dtype=np.uint8).tobytes(),
                 rng.integers(0, 3, 70000, dtype=np.uint8).tobytes()):
        c = lzf.compress(data)
        assert lzf.decompress(c, len(data)).tobytes() == data
    # repetitive input compresses far below its size: only back-references can do that
    assert len(lzf.compress(b"abcd" * 3000)) < 500
    # a hand-made stream: literal 'a', then a 5-byte back-reference at distance 1
    # (overlapping: a run), then one with a long length byte (7 + 3 + 2 = 12 bytes)
    stream = bytes([0, ord("a"), 3 << 5, 0, 7 << 5, 3, 0])
    assert lzf.decompress(stream, 18).tobytes() == b"a" * 18


@pytest.mark.parametrize("stream,size,match", [
    (bytes([5, 1, 2]), 6, "ends inside"),            # literal run cut short
    (bytes([0, 1, 1 << 5]), 4, "ends inside"),        # back-reference without offset
    (bytes([1 << 5, 0]), 3, "before the start"),      # nothing to refer to yet
    (bytes([3, 1, 2, 3, 4]), 2, "more bytes"),        # decodes past the header's size
    (bytes([0, 1]), 5, "decodes to 1 bytes"),         # decodes short
])
def test_lzf_damaged_streams(stream, size, match):
    with pytest.raises(ValueError, match=match):
        lzf.decompress(stream, size)


# -- PCD against our writer ----------------------------------------------------------------

@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("version", ["0.7", "0.6"])
@pytest.mark.parametrize("rgb", [False, True])
def test_pcd_round_trip(tmp_path, encoding, version, rgb):
    d = _depth()
    colors = np.full((48, 64, 3), (200, 10, 30), np.uint8) if rgb else None
    p = write_pcd(tmp_path / "f.pcd", d, INTR, encoding=encoding, rgb=colors, version=version)
    f = read_depth(p)
    np.testing.assert_array_equal(f.depth_mm, d)
    assert f.source_format == f"pcd-{encoding}"
    assert f.intrinsics == INTR  # recovered exactly (to the tidy half pixel)
    assert not f.depth_mm.flags.writeable


def test_pcd_extra_fields_counts_and_types(tmp_path):
    """FIELDS in any order with SIZE/TYPE/COUNT honoured: rgba U 4, a normal of COUNT 3,
    x y z in float64, an int8 field; only x y z are kept."""
    d = _depth(2)
    pts = backproject(INTR, d / 1000.0)
    pts[d == 0] = np.nan
    n = d.size
    dt = np.dtype([("rgba", "<u4"), ("x", "<f8"), ("normal", "<f4", (3,)), ("y", "<f8"),
                   ("tag", "i1"), ("z", "<f8")])
    rec = np.zeros(n, dt)
    for k, name in enumerate("xyz"):
        rec[name] = pts[..., k].reshape(-1)
    rec["normal"] = 0.5
    head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS rgba x normal_x y tag z\nSIZE 4 8 4 8 1 8\n"
            "TYPE U F F F I F\nCOUNT 1 1 3 1 1 1\nWIDTH 64\nHEIGHT 48\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3072\n")
    (tmp_path / "b.pcd").write_bytes((head + "DATA binary\n").encode() + rec.tobytes())
    f = read_depth(tmp_path / "b.pcd")
    np.testing.assert_array_equal(f.depth_mm, d)
    # the same fields one after the other, LZF-compressed
    soa = b"".join(np.ascontiguousarray(rec[name]).tobytes() for name in dt.names)
    comp = lzf.compress(soa)
    body = np.array([len(comp), len(soa)], "<u4").tobytes() + comp
    (tmp_path / "c.pcd").write_bytes((head + "DATA binary_compressed\n").encode() + body)
    np.testing.assert_array_equal(read_depth(tmp_path / "c.pcd").depth_mm, d)
    # and as text, 0.6-style (VERSION .6, COLUMNS for FIELDS, no VIEWPOINT)
    rows = [" ".join(["4294967295", repr(float(r["x"])), "0.5 0.5 0.5", repr(float(r["y"])),
                      "-3", repr(float(r["z"]))]) for r in rec]
    txt = head.replace("VERSION 0.7", "VERSION .6").replace("FIELDS", "COLUMNS").replace(
        "VIEWPOINT 0 0 0 1 0 0 0\n", "")
    (tmp_path / "a.pcd").write_text(txt + "DATA ascii\n" + "\n".join(rows) + "\n")
    np.testing.assert_array_equal(read_depth(tmp_path / "a.pcd").depth_mm, d)


def test_header_without_count_and_points(tmp_path):
    """Old headers may omit COUNT (one each) and POINTS (WIDTH * HEIGHT)."""
    raw = write_pcd(tmp_path / "f.pcd", _depth(4), INTR, encoding="binary").read_bytes()
    raw = raw.replace(b"COUNT 1 1 1\n", b"").replace(b"POINTS 3072\n", b"")
    (tmp_path / "g.pcd").write_bytes(raw)
    np.testing.assert_array_equal(read_depth(tmp_path / "g.pcd").depth_mm, _depth(4))


def test_given_intrinsics_win(tmp_path):
    p = write_pcd(tmp_path / "f.pcd", _depth(), INTR)
    other = Intrinsics(64, 48, 100.0, 100.0, 30.0, 20.0)
    assert read_depth(p, other).intrinsics == other


def test_recover_intrinsics_refuses_a_non_pinhole_cloud(tmp_path):
    pts = backproject(INTR, _depth() / 1000.0)
    pts[..., 0] += 0.02 * np.sin(np.arange(64) / 3.0)  # columns no longer on a pinhole
    with pytest.raises(DepthFileError, match="not a pinhole image: column .* RMS residual"):
        recover_intrinsics(pts, "warped.pcd")
    p = write_pcd_points(tmp_path / "w.pcd", pts)
    with pytest.raises(DepthFileError) as e:
        read_depth(p)
    assert str(e.value).startswith(str(p)) and "\n" not in str(e.value)


# -- the shared real frames -----------------------------------------------------------------

def test_shared_real_frames():
    files = sorted(REAL.glob("*.pcd"))
    assert len(files) == 6
    for p in files:
        f = read_depth(p)
        assert f.intrinsics == Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5), p
        assert f.source_format == "pcd-binary_compressed"
        valid = f.depth_mm > 0
        assert 0.78 <= valid.mean() <= 0.82, (p, valid.mean())  # SOURCES.md: 0.79-0.81
        lo, hi = f.depth_mm[valid].min(), f.depth_mm[valid].max()
        if p.name == "person.pcd":
            assert 590 <= lo <= 620 and hi <= 3800  # SOURCES.md: 0.6-3.8 m
        else:
            assert 1350 <= lo and hi <= 3750  # SOURCES.md: 1.4-3.7 m
        # OpenNI depth is integer mm on disparity steps: between 2 and 3 m the distinct
        # values lie 2.9e-3 z^2 m apart (1/8 px at f b = 43 px m)
        lev = np.unique(f.depth_mm[valid]).astype(float)
        lev = lev[(lev >= 2000) & (lev <= 3000)]
        gap = np.median(np.diff(lev) / (lev[1:] / 1000) ** 2)
        assert 2.6 < gap < 3.2, (p, gap)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_shared_frame_rewritten_in_every_encoding(tmp_path, encoding):
    f = read_depth(REAL / "capture0004.pcd")
    p = write_pcd(tmp_path / "r.pcd", f.depth_mm, f.intrinsics, encoding=encoding)
    g = read_depth(p)
    np.testing.assert_array_equal(g.depth_mm, f.depth_mm)
    assert g.intrinsics == f.intrinsics


def test_png(tmp_path):
    d = _depth()
    Image.fromarray(d).save(tmp_path / "d.png")
    f = read_depth(tmp_path / "d.png")
    np.testing.assert_array_equal(f.depth_mm, d)
    assert f.intrinsics is None and f.source_format == "png"
    assert read_depth(tmp_path / "d.png", INTR).intrinsics == INTR


# -- malformed files: one line each ----------------------------------------------------------

def _good(tmp_path, encoding="binary") -> bytes:
    return write_pcd(tmp_path / "good.pcd", _depth(), INTR, encoding=encoding).read_bytes()


def _cases(tmp_path):
    b = _good(tmp_path)
    c = _good(tmp_path, "binary_compressed")
    head_end = c.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    cs, us = np.frombuffer(c[head_end:head_end + 8], "<u4")
    damaged = bytearray(c)
    damaged[head_end + 8] = 1 << 5  # the first chunk now refers before the start
    rgb = tmp_path / "rgb.png"
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(rgb)
    return {
        "noheader.pcd": (b"VERSION 0.7\nFIELDS x y z\n", "no DATA line"),
        "text.pcd": (b"hello\nworld\n", "unknown header line"),
        "unknown.pcd": (b"FOO 1\nDATA ascii\n", "unknown header line"),
        "points.pcd": (b.replace(b"POINTS 3072", b"POINTS 3000"), "POINTS 3000 is not"),
        "truncated.pcd": (b[:-100], "DATA binary truncated"),
        "usize.pcd": (c[:head_end + 4] + np.array([us + 4], "<u4").tobytes()
                      + c[head_end + 8:], "uncompressed size"),
        "csize.pcd": (c[:head_end] + np.array([cs + 50, us], "<u4").tobytes()
                      + c[head_end + 8:], "truncated"),
        "lzf.pcd": (bytes(damaged), "back-reference points before"),
        "unorganized.pcd": (b.replace(b"WIDTH 64\nHEIGHT 48", b"WIDTH 3072\nHEIGHT 1"),
                            "unorganized cloud"),
        "noz.pcd": (b.replace(b"FIELDS x y z", b"FIELDS x y w"), "no z field"),
        "type.pcd": (b.replace(b"TYPE F F F", b"TYPE F F Q"), "TYPE Q"),
        "sizes.pcd": (b.replace(b"SIZE 4 4 4", b"SIZE 4 4"), "SIZE has 2 entries"),
        "data.pcd": (b.replace(b"DATA binary", b"DATA zip"), "DATA 'zip'"),
        "ascii.pcd": (b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\n"
                      b"HEIGHT 2\nDATA ascii\n1 2 3\n1 2 x\n4 5 6\n7 8 9\n", "not a number"),
        "rgb.png": (rgb.read_bytes(), "16-bit depth PNG"),
        "junk.png": (b"not a png", "not an image"),
        "depth.exr": (b"x", "unknown depth file type"),
    }


def test_malformed_files_one_line_each(tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    cases = _cases(tmp_path)
    for name, (data, _) in cases.items():
        (bad / name).write_bytes(data)
    for name, (_, match) in cases.items():
        with pytest.raises(DepthFileError) as e:
            read_depth(bad / name)
        msg = str(e.value)
        assert msg.startswith(str(bad / name) + ": ") and "\n" not in msg, msg
        assert match in msg, (name, msg)
    with pytest.raises(DepthFileError, match="no such file"):
        read_depth(bad / "missing.pcd")


def test_one_bad_file_never_stops_a_folder(tmp_path):
    write_pcd(tmp_path / "a.pcd", _depth(1), INTR)
    (tmp_path / "b.pcd").write_bytes(b"broken\n")
    Image.fromarray(_depth(3)).save(tmp_path / "c.png")
    (tmp_path / "notes.txt").write_text("not a depth file")
    got = list(iter_depth_files([tmp_path]))
    assert [type(g).__name__ for g in got] == ["DepthFrame", "DepthFileError", "DepthFrame"]
    assert "b.pcd" in str(got[1])
