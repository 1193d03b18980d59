"""Every shipped scene config writes the same bytes as when the fingerprints were recorded.

Each config in ``configs/scenes`` runs its first frames as a real job (two local workers,
llvmpipe); the sha256 of every array of the store and of the manifest rows (paths reduced
to their file names, so a clone elsewhere compares equal) must match
``output_fingerprints.json``. A refactoring of the frame path must leave them unchanged.

Regenerate (only when an output is meant to change, and say why in the commit):
``.venv/bin/python tests/pipeline/test_output_bytes.py``.
"""

from __future__ import annotations

import hashlib
import json
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

STORE = Path(__file__).with_name("output_fingerprints.json")
FRAMES = 16
# a config that asks for GPU workers renders here on the CPU (same code, llvmpipe)
OVERRIDES = {"cluster_gpu": {"gpus_per_worker": 0}}


def _scenes() -> list[str]:
    from vhgen.yamlio import configs_dir

    return sorted(p.stem for p in (configs_dir() / "scenes").glob("*.yaml"))


def _plain(v):
    """Manifest values made comparable across machines: paths become file names."""
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_plain(x) for x in v]
    if isinstance(v, str) and v.startswith("/"):
        return Path(v).name
    return v


def fingerprint(name: str, out: Path) -> dict[str, str]:
    """sha256 of each array of a store written from the shipped config ``name`` (its first
    :data:`FRAMES` frames) and of its manifest rows."""
    import pyarrow.parquet as pq
    import zarr

    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job
    from vhgen.yamlio import configs_dir

    cfg = JobConfig.load(configs_dir() / "scenes" / f"{name}.yaml", num_workers=2,
                         **OVERRIDES.get(name, {}))
    run_job(cfg, out, max_frames=FRAMES, executor="local")
    g = zarr.open_group(str(out), mode="r")
    prints = {}
    with warnings.catch_warnings():  # the manifest and report files are not zarr nodes
        warnings.simplefilter("ignore")
        keys = sorted(g.array_keys())
    for key in keys:
        a = np.ascontiguousarray(g[key][:])
        prints[key] = hashlib.sha256(a.dtype.str.encode() + str(a.shape).encode()
                                     + a.tobytes()).hexdigest()
    rows = _plain(pq.read_table(out / "manifest.parquet").to_pylist())
    prints["manifest"] = hashlib.sha256(json.dumps(rows, sort_keys=True).encode()).hexdigest()
    return prints


@pytest.mark.parametrize("name", _scenes())
def test_shipped_config_bytes(name, tmp_path, shared_mocap):
    recorded = json.loads(STORE.read_text())
    assert name in recorded, f"no fingerprint for {name}: record it (see the module docstring)"
    assert fingerprint(name, tmp_path / "out.zarr") == recorded[name]


if __name__ == "__main__":
    names = sys.argv[1:] or _scenes()
    prints = json.loads(STORE.read_text()) if STORE.exists() else {}
    for n in names:
        with tempfile.TemporaryDirectory() as d:
            prints[n] = fingerprint(n, Path(d) / "out.zarr")
        print(n, prints[n])
    STORE.write_text(json.dumps(prints, indent=1, sort_keys=True) + "\n")
