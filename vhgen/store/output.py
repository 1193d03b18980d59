"""A job's output store: checked before any work, created or resumed, its attributes.

Faults here are one line each (:class:`~vhgen.errors.StoreError`): an output that
cannot be written or must not be replaced, a store made by another config, a full disk.
"""

from __future__ import annotations

import errno
import json
import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from vhgen.errors import StoreError
from vhgen.store.manifest import unreadable_parts
from vhgen.store.zarr_store import MANIFEST_PARTS, clean_partials, create_store, read_attrs

log = logging.getLogger(__name__)

# the attributes that must agree for a store to be resumed with a config
RESUME_KEYS = ("seed", "num_frames", "frames_per_shard", "label_names", "sensor",
               "class_names")


def check_output(out: Path, *, resume: bool, overwrite: bool) -> None:
    """Refuse, before any work, an output that cannot be written or must not be replaced."""
    if out.exists():
        if not out.is_dir():
            raise StoreError(f"{out}: exists and is not a folder")
        is_store = (out / "zarr.json").is_file()
        if not (resume or overwrite):
            raise StoreError(f"{out}: exists; pass --resume to finish it or --overwrite to "
                             "replace it")
        if not is_store and any(out.iterdir()):
            # creating the store deletes the folder's contents: only ever a store we wrote
            raise StoreError(f"{out}: a folder that is not a vhgen store and not empty; "
                             "choose another --out")
        target = out
    else:
        target = out.parent
        while not target.exists() and target != target.parent:
            target = target.parent
    if not os.access(target, os.W_OK | os.X_OK):
        why = "read-only file system" if _read_only(target) else "permission denied"
        raise StoreError(f"{out}: cannot write output ({target}: {why})")


def _read_only(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def os_error_line(e: OSError, out: Path, what: str) -> str:
    """One line for an OSError writing ``out``: what failed, the errno, and what to do."""
    name = errno.errorcode.get(e.errno or 0, "")
    hint = {errno.ENOSPC: "free space", errno.EDQUOT: "raise the quota",
            errno.EROFS: "make the output writable", errno.EACCES: "fix the permissions"}
    return (f"{out}: {what}: {e.strerror or e} ({name}{': ' + e.filename if e.filename else ''})"
            f"; finished shards are kept: {hint.get(e.errno or 0, 'fix the cause')}, then "
            "rerun with --resume")


def check_same_config(out: Path, attrs: dict[str, Any]) -> None:
    """Refuse to resume a store made by another config (the keys of :data:`RESUME_KEYS`
    present in ``attrs``)."""
    old = read_attrs(out)
    for k in RESUME_KEYS:
        if k in attrs and json.dumps(old.get(k), sort_keys=True) != json.dumps(
                attrs[k], sort_keys=True):
            raise StoreError(f"{out}: made by another config ({k!r} differs: store "
                             f"{_short(old.get(k))}, config {_short(attrs[k])}); "
                             "cannot resume it (use another --out or --overwrite)")


def _short(v: Any) -> str:
    s = json.dumps(v, sort_keys=True)
    return s if len(s) <= 40 else s[:37] + "..."


def open_output(out: Path, attrs: dict[str, Any], num_frames: int, resume: bool, *,
                height: int, width: int, frames_per_shard: int,
                compression_level: int | None, arrays: Sequence[str],
                codec: str = "zstd", palette: bool | None = None) -> None:
    """Create the store for ``num_frames`` frames (H x W, shards of ``frames_per_shard``)
    holding ``arrays`` with ``attrs``, or, when resuming an existing one (whose config the
    caller checked before any work, :func:`check_same_config`), remove the partial files a
    killed writer left and the manifest parts that cannot be read (their shards are
    rendered again)."""
    try:
        if resume and (out / "zarr.json").is_file():
            n_clean = clean_partials(out)
            if n_clean:
                log.warning("removed %d partial files left by a killed writer", n_clean)
            for shard in unreadable_parts(out):  # damaged: its shard is rendered again
                part = out / MANIFEST_PARTS / f"part-{shard:06d}.parquet"
                log.warning("%s: unreadable; shard %d is rendered again", part, shard)
                part.unlink()
        else:
            create_store(out, num_frames=num_frames, height=height, width=width,
                         frames_per_shard=frames_per_shard,
                         compression_level=compression_level, attrs=attrs,
                         overwrite=True, arrays=arrays, codec=codec, palette=palette)
    except OSError as e:
        raise StoreError(os_error_line(e, out, "cannot create the store")) from None
