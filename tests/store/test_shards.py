"""vhgen.store.shards: frames decoded straight from shard files equal zarr's, bit for bit;
damaged shards raise ShardError naming store, array and shard, and the rest still reads."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from tests.conftest import write_synthetic_store
from vhgen.errors import ShardError
from vhgen.store.shards import ShardReader, array_layout, zstd_content_size


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    return write_synthetic_store(tmp_path_factory.mktemp("shards") / "s.zarr", frames=22,
                                 frames_per_shard=4)


@pytest.fixture(scope="module")
def lz4_store(tmp_path_factory):
    return write_synthetic_store(tmp_path_factory.mktemp("shards") / "lz4.zarr", frames=22,
                                 frames_per_shard=4, codec="lz4")


@pytest.fixture
def damaged(store, tmp_path):
    out = tmp_path / "damaged.zarr"
    shutil.copytree(store, out)
    return out


def _zarr(store):
    import zarr

    g = zarr.open_group(str(store), mode="r")
    return {n: g[n][:] for n in ("depth", "labels", "instances", "classes")}


@pytest.mark.parametrize("threads", [1, 3])
def test_frames_equal_zarr(store, threads):
    truth = _zarr(store)
    reader = ShardReader(store, list(truth), threads=threads)
    assert all(reader.layouts[n] is not None for n in truth)  # the direct path, not zarr
    frames = np.random.default_rng(threads).permutation(22)
    for name, want in truth.items():
        out = reader.empty(name, len(frames))
        reader.read_into([(name, int(f), out[k]) for k, f in enumerate(frames)])
        assert out.dtype == want.dtype and np.array_equal(out, want[frames])
    reader.close()


def test_lz4_store_decodes_to_the_same_arrays(store, lz4_store):
    """output.codec lz4 (blosc, shuffled bytes) changes the files, not one value."""
    truth = _zarr(store)
    assert all(np.array_equal(a, truth[n]) for n, a in _zarr(lz4_store).items())
    reader = ShardReader(lz4_store, list(truth), threads=2)
    assert {reader.layouts[n].compressor for n in truth} == {"blosc"}  # type: ignore[union-attr]
    frames = np.random.default_rng(0).permutation(22)
    for name, want in truth.items():
        out = reader.empty(name, len(frames))
        reader.read_into([(name, int(f), out[k]) for k, f in enumerate(frames)])
        assert out.dtype == want.dtype and np.array_equal(out, want[frames])
    size = {s: sum(f.stat().st_size for f in (s / "depth").rglob("*")) for s in
            (store, lz4_store)}
    assert size[lz4_store] != size[store]  # really another codec


def test_stores_of_the_old_codecs_read_the_same(store, tmp_path):
    """A store with the codecs vhgen wrote before (zstd 3 on every array: ``store``) and
    one with today's per-array levels hold the same values, read through zarr and the
    shard reader; each array's zarr.json names its codec and level."""
    import json

    from vhgen.store.zarr_store import ARRAYS

    new = write_synthetic_store(tmp_path / "new.zarr", frames=22, frames_per_shard=4,
                                compression_level=None)
    truth = _zarr(store)
    assert all(np.array_equal(a, truth[n]) for n, a in _zarr(new).items())
    for path, level in ((store, {n: 3 for n in truth}),
                        (new, {n: ARRAYS[n][2] for n in truth})):
        for name in truth:
            meta = json.loads((path / name / "zarr.json").read_text())
            inner = meta["codecs"][0]["configuration"]["codecs"]
            assert inner[-1] == {"name": "zstd",
                                 "configuration": {"level": level[name], "checksum": False}}
        reader = ShardReader(path, list(truth), threads=2)
        frames = np.random.default_rng(1).permutation(22)
        for name, want in truth.items():
            out = reader.empty(name, len(frames))
            reader.read_into([(name, int(f), out[k]) for k, f in enumerate(frames)])
            assert np.array_equal(out, want[frames])
        reader.close()


def test_other_layouts_read_through_zarr(tmp_path):
    import zarr

    g = zarr.open_group(str(tmp_path / "u.zarr"), mode="w", zarr_format=3)
    data = np.arange(5 * 6 * 7, dtype=np.uint16).reshape(5, 6, 7)
    g.create_array("depth", shape=data.shape, dtype="uint16", chunks=(2, 6, 7))[:] = data
    assert array_layout(tmp_path / "u.zarr", "depth") is None
    reader = ShardReader(tmp_path / "u.zarr", ["depth"], threads=2)
    out = reader.empty("depth", 3)
    reader.read_into([("depth", f, out[k]) for k, f in enumerate((4, 0, 2))])
    assert np.array_equal(out, data[[4, 0, 2]])


def test_zstd_content_size():
    import numcodecs.zstd

    for n in (0, 10, 300, 70000, 2**20 + 3):
        assert zstd_content_size(numcodecs.zstd.compress(b"x" * n, 3)) == n
    assert zstd_content_size(b"not zstd at all") is None


def test_missing_shard_file(damaged):
    (damaged / "labels" / "c" / "2" / "0" / "0").unlink()
    reader = ShardReader(damaged, ["depth", "labels"])
    out = reader.empty("labels")
    with pytest.raises(ShardError, match=r"damaged.zarr: labels shard 2 \(frames 8-11\): "
                       r"shard file labels/c/2/0/0 missing") as e:
        reader.read_into([("labels", 9, out)])
    assert (e.value.array, e.value.shard, e.value.frames) == ("labels", 2, (8, 11))
    errors: list[ShardError] = []
    outs = reader.empty("labels", 3)
    reader.read_into([("labels", f, outs[k]) for k, f in enumerate((1, 9, 21))], errors)
    assert [err.shard for err in errors] == [2]
    truth = _zarr(damaged)
    assert np.array_equal(outs[[0, 2]], truth["labels"][[1, 21]])  # the others still read


def test_index_checksum_and_truncation(damaged):
    shard = damaged / "depth" / "c" / "1" / "0" / "0"
    blob = bytearray(shard.read_bytes())
    blob[-10] ^= 0xFF
    shard.write_bytes(bytes(blob))
    short = damaged / "depth" / "c" / "3" / "0" / "0"
    short.write_bytes(short.read_bytes()[:50])
    reader = ShardReader(damaged, ["depth"])
    out = reader.empty("depth")
    with pytest.raises(ShardError, match="depth shard 1 .*index checksum does not match"):
        reader.read_into([("depth", 5, out)])
    with pytest.raises(ShardError, match="depth shard 3 .*shorter than its index"):
        reader.read_into([("depth", 13, out)])
    reader.read_into([("depth", 0, out)])


def test_damaged_chunk_spoils_only_its_frame(store, damaged):
    # the index: (offset, nbytes) uint64 per frame, then a crc32c, at the end of the file
    idx = np.frombuffer((store / "depth/c/0/0/0").read_bytes()[-(16 * 4 + 4):-4], "<u8")
    offset = int(idx.reshape(4, 2)[2, 0])
    shard = damaged / "depth" / "c" / "0" / "0" / "0"
    blob = bytearray(shard.read_bytes())
    blob[offset + 20:offset + 60] = bytes(40)  # inside frame 2's compressed data
    shard.write_bytes(bytes(blob))
    bad = ShardReader(damaged, ["depth"], threads=1)
    out = bad.empty("depth", 4)
    errors: list[ShardError] = []
    bad.read_into([("depth", f, out[f]) for f in (0, 1, 3)], errors)
    assert not errors and np.array_equal(out[[0, 1, 3]], _zarr(store)["depth"][[0, 1, 3]])
    with pytest.raises(ShardError, match="depth shard 0 .*frame 2"):
        bad.read_into([("depth", 2, out[2])])



@pytest.mark.parametrize("palette", [True, False])
def test_shards_written_directly_are_the_bytes_zarr_writes(tmp_path, palette):
    """write_shard writes the layout create_store makes straight to its shard files
    (write_shard_file): every file byte for byte what zarr writes for the same frames,
    a last shard with fewer frames than its slots and a frame all fill value included;
    with and without the palette (uint16 arrays, raw at its own level)."""
    import zarr

    from vhgen.store.shard_files import write_shard_file, writes_directly
    from vhgen.store.zarr_store import ARRAYS, create_store, open_store, write_shard

    rng = np.random.default_rng(5)
    frames, per, h, w = 11, 4, 40, 56
    depth = (rng.integers(500, 4000, (frames, 1, 1))
             + rng.integers(0, 8, (frames, h, w))).astype(np.uint16)
    depth[3] = 0  # all fill value: still a chunk of its own, as write_shard asks of zarr
    labels = rng.integers(0, 4, (frames, h, w), dtype=np.uint8)
    data = {"depth": depth, "labels": labels, "instances": (labels > 0).astype(np.uint8),
            "classes": labels // 2, "raw": (2047 - depth // 4).astype(np.uint16)}
    paths = {how: tmp_path / f"{how}.zarr" for how in ("direct", "zarr")}
    for path in paths.values():
        create_store(path, num_frames=frames, height=h, width=w, frames_per_shard=per,
                     compression_level=None, attrs={}, arrays=list(data), palette=palette)
    for s in range(-(-frames // per)):
        part = {k: v[s * per:(s + 1) * per] for k, v in data.items()}
        write_shard(paths["direct"], s, per, part["depth"], part["labels"], part["raw"],
                    extra={k: part[k] for k in ("instances", "classes")})
        root = open_store(paths["zarr"], mode="r+")
        for name, arr in part.items():
            root[name].with_config({"write_empty_chunks": True})[s * per:
                                                                   s * per + len(arr)] = arr
    files = sorted(p.relative_to(paths["zarr"]) for p in paths["zarr"].rglob("*")
                   if p.is_file() and "/c/" in f"/{p.relative_to(paths['zarr'])}")
    assert len(files) == len(data) * 3
    for rel in files:
        assert (paths["direct"] / rel).read_bytes() == (paths["zarr"] / rel).read_bytes(), rel
    assert not list(paths["direct"].rglob("*.tmp"))
    layouts = {name: array_layout(paths["direct"], name) for name in data}
    assert all(writes_directly(layout) for layout in layouts.values())
    assert layouts["labels"].level == ARRAYS["labels"][2]
    assert layouts["raw"].level == ARRAYS["raw"][2]
    back = zarr.open_group(str(paths["direct"]), mode="r")
    for name, arr in data.items():
        assert np.array_equal(back[name][:], arr)
    with pytest.raises(ValueError, match="not written directly"):
        write_shard_file(layouts["labels"], 2, labels[8:10])  # the shard holds 3 frames


def test_lz4_shards_are_written_through_zarr(lz4_store):
    """A layout write_shard_file does not write (blosc: output.codec lz4) goes through
    zarr, as before; lz4_store was written that way and reads back."""
    from vhgen.store.shard_files import writes_directly

    assert not writes_directly(array_layout(lz4_store, "depth"))
    reader = ShardReader(lz4_store, ["depth"], threads=1)
    out = reader.empty("depth", 2)
    reader.read_into([("depth", 0, out[0]), ("depth", 21, out[1])])
    assert out[0].any() and out[1].any()
    reader.close()
