"""The wheel as a new user gets it: built from this repository, installed into a fresh
virtualenv outside the clone, and run from an unrelated folder.

Cost: about half a minute here (wheel build ~5 s, virtualenv + install of the dependencies
by uv from its cache, which scripts/setup.sh filled, a few seconds; pip's resolver took
~60 s; an 8-frame job on one OSMesa worker ~15 s)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow


def _sh(cmd: list[str], cwd: Path, timeout: float = 600, env=None) -> str:
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
    assert r.returncode == 0, f"{' '.join(cmd)} -> {r.returncode}\n{r.stdout}\n{r.stderr}"
    return r.stdout + r.stderr


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    # from a clean copy: setuptools reuses an in-tree build/ folder, whose stale files
    # (a module since deleted) would otherwise end up in the wheel
    src = out / "src"
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "*.egg-info", "__pycache__", "out", ".*_cache",
        ".hypothesis"))
    _sh([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q", "-w", str(out)],
        cwd=out)
    (whl,) = out.glob("vhgen-*.whl")
    return whl


def test_wheel_ships_every_module_config_and_shader(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    want = {str(p.relative_to(REPO)) for p in (REPO / "vhgen").rglob("*")
            if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"}
    want |= {"vhgen/" + str(p.relative_to(REPO)) for p in (REPO / "configs").rglob("*")
             if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"}
    assert "vhgen/render/shaders/skinning.glsl" in want
    assert "vhgen/configs/scenes/default.yaml" in want
    assert not want - names, f"missing from the wheel: {sorted(want - names)}"
    # zarr finds the depth codec of vhgen's stores through this entry point
    (eps,) = [n for n in names if n.endswith(".dist-info/entry_points.txt")]
    text = zipfile.ZipFile(wheel).read(eps).decode()
    assert "[zarr.codecs]" in text and "vhgen.palette = vhgen.store.palette:PaletteCodec" in text


def test_installed_wheel_runs_the_default_job_elsewhere(wheel, tmp_path, asset_dir):
    venv = tmp_path / "venv"
    work = tmp_path / "elsewhere"  # an unrelated folder: no configs/, no clone
    work.mkdir()
    assert not str(tmp_path).startswith(str(REPO))
    _sh(["python3", "-m", "venv", str(venv)], cwd=work)
    uv = Path(sys.executable).parent / "uv"  # scripts/setup.sh installs it in .venv
    if uv.is_file():
        _sh([str(uv), "pip", "install", "-q", "--python", str(venv / "bin" / "python"),
             str(wheel)], cwd=work)
    else:
        _sh([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", str(wheel)], cwd=work)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    env["VHGEN_ASSETS"] = str(asset_dir)
    where = _sh([str(venv / "bin" / "python"), "-c", "import vhgen.yamlio as y, vhgen; "
                 "print(vhgen.__file__); print(y.configs_dir())"], cwd=work, env=env)
    assert str(REPO) not in where and str(venv) in where
    log = _sh([str(venv / "bin" / "vhgen"), "generate", "default", "--out", "run.zarr",
               "--backend", "osmesa", "--num-workers", "1", "--max-frames", "8"],
              cwd=work, env=env)
    assert "wrote 8 frames" in log and "Traceback" not in log
    assert "Token authentication" not in log  # Ray's own warnings are not shown
    check = ("import json, zarr; g = zarr.open_group('run.zarr', mode='r'); "
             "lab = g['labels'][:]; d = g['depth'][:]; print(json.dumps([list(lab.shape), "
             "int((lab > 0).sum(axis=(1, 2)).min()), int(d.max())]))")
    shape, body_min, depth_max = json.loads(
        _sh([str(venv / "bin" / "python"), "-c", check], cwd=work, env=env).splitlines()[-1])
    assert shape == [8, 480, 640]
    assert body_min > 5000 and 800 < depth_max < 4000
    _sh([str(venv / "bin" / "vhgen"), "preview", "run.zarr", "-o", "p.png"], cwd=work, env=env)
    assert (work / "p.png").stat().st_size > 10_000


def test_a_source_tree_without_a_build_finds_its_configs(tmp_path):
    """vhgen imported from a checkout on sys.path with no build (PYTHONPATH=., or pytest
    putting the repository first on a machine where vhgen is installed from the wheel, as
    on a GPU node) has no vhgen.configs package: the configs are the folder beside it."""
    import sysconfig

    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    # -S: no site, so no editable install's finder; the dependencies by path
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), sysconfig.get_paths()["purelib"]])
    out = _sh([sys.executable, "-S", "-c", "import vhgen, vhgen.yamlio as y; "
               "from vhgen.sensor.sensor_config import SensorConfig; "
               "print(vhgen.__file__); print(y.configs_dir()); "
               "print(SensorConfig.load('openni_525').name)"], cwd=tmp_path, env=env)
    package, configs, sensor = out.strip().splitlines()[-3:]
    assert package == str(REPO / "vhgen" / "__init__.py")
    assert configs == str(REPO / "configs") and sensor == "openni_525"
