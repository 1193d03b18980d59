"""Every shipped scene config writes the same output as when the fingerprints were recorded.

Each config in ``configs/scenes`` runs its first frames as a real job (two local workers,
llvmpipe). The fingerprint of a store (:func:`fingerprint`) is

* the sha256 of every array (depth, labels, instances, classes, raw): bit-exact on every
  x86-64 machine, so compared exactly;
* ``manifest``: the sha256 of the manifest rows with every float (also those inside the
  JSON columns) replaced by a placeholder: every integer, string, bool, null and the
  rows' shape, compared exactly (paths are reduced to file names, so a clone elsewhere
  compares equal);
* ``manifest_floats``: per float field (``people.placement``, ``scene{}.props.x``, ...)
  its count, L2 norm and 8 projections on fixed pseudo-random vectors, compared to a
  relative tolerance of :data:`RTOL` of the norm. The manifest's floats (camera matrices,
  placements, joints) differ by a few ulps between CPUs (numpy's SIMD sin/cos/arctan2
  differ between AVX-512 and AVX2, OpenBLAS picks its matrix kernels per CPU; measured up
  to 1e-13 relative), so they cannot be hashed; a real change of output moves a value by
  far more than the tolerance (a single camera-matrix entry moved by 1e-5 is caught).

``test_fingerprint_on_another_cpu`` runs one config with numpy's AVX2/AVX-512 paths and
OpenBLAS's CPU-specific kernels switched off (the code paths of an older CPU) and checks
the same fingerprint. A refactoring of the frame path must leave the fingerprints
unchanged.

Regenerate (only when an output is meant to change, and say why in the commit):
``.venv/bin/python tests/pipeline/test_output_bytes.py [CONFIG ...]``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
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


RTOL = 1e-7  # of a float field's L2 norm, for each of its projections
PROJECTIONS = 8
# numpy without its AVX2/AVX-512 loops, OpenBLAS with its SSE3 kernels, numba for a generic
# x86-64: the float paths of an older CPU on any x86-64 machine
OTHER_CPU = {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
             "OPENBLAS_CORETYPE": "Prescott", "NUMBA_CPU_NAME": "generic"}


def _split(v, path: str, floats: dict[str, list[float]]):
    """``v`` with every finite float replaced by ``"<f>"`` (appended to ``floats[path]``);
    JSON text inside a string is parsed and split the same way."""
    if isinstance(v, dict):
        return {k: _split(x, f"{path}.{k}", floats) for k, x in v.items()}
    if isinstance(v, list):
        return [_split(x, path, floats) for x in v]
    if isinstance(v, float) and np.isfinite(v):
        floats.setdefault(path, []).append(v)
        return "<f>"
    if isinstance(v, str) and v[:1] in "{[":
        try:
            parsed = json.loads(v)
        except ValueError:
            return v
        return {"<json>": _split(parsed, path + "{}", floats)}
    return v


def manifest_prints(rows: list[dict]) -> dict:
    """The manifest's two fingerprints: ``manifest`` (exact, floats left out) and
    ``manifest_floats`` (per float field: count, norm, projections)."""
    floats: dict[str, list[float]] = {}
    exact = _split(_plain(rows), "", floats)
    summary = {}
    for path, values in sorted(floats.items()):
        x = np.asarray(values, np.float64)
        # uniform in [-1, 1) from PCG64's bits: the same on every machine
        seed = int.from_bytes(hashlib.sha256(path.encode()).digest()[:8], "little")
        g = 2.0 * np.random.default_rng(seed).random((PROJECTIONS, len(x))) - 1.0
        summary[path] = [len(x), float(np.sqrt(np.sum(x * x))), *map(float, g @ x)]
    return {"manifest": hashlib.sha256(json.dumps(exact, sort_keys=True).encode()).hexdigest(),
            "manifest_floats": summary}


def fingerprint(name: str, out: Path) -> dict:
    """The fingerprint of a store written from the shipped config ``name`` (its first
    :data:`FRAMES` frames): sha256 of each array, and :func:`manifest_prints`."""
    import pyarrow.parquet as pq
    import zarr

    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job
    from vhgen.yamlio import configs_dir

    cfg = JobConfig.load(configs_dir() / "scenes" / f"{name}.yaml", num_workers=2,
                         **OVERRIDES.get(name, {}))
    run_job(cfg, out, max_frames=FRAMES, executor="local")
    g = zarr.open_group(str(out), mode="r")
    prints: dict = {}
    with warnings.catch_warnings():  # the manifest and report files are not zarr nodes
        warnings.simplefilter("ignore")
        keys = sorted(g.array_keys())
    for key in keys:
        a = np.ascontiguousarray(g[key][:])
        prints[key] = hashlib.sha256(a.dtype.str.encode() + str(a.shape).encode()
                                     + a.tobytes()).hexdigest()
    prints.update(manifest_prints(pq.read_table(out / "manifest.parquet").to_pylist()))
    return prints


def differences(got: dict, recorded: dict) -> list[str]:
    """What differs between two fingerprints: exact keys exactly, floats within RTOL."""
    out = [f"{k}: {got.get(k)} != {recorded.get(k)}" for k in sorted({*got, *recorded})
           if k != "manifest_floats" and got.get(k) != recorded.get(k)]
    gf, rf = got.get("manifest_floats", {}), recorded.get("manifest_floats", {})
    for path in sorted({*gf, *rf}):
        if path not in gf or path not in rf:
            out.append(f"float field {path!r} only in {'the record' if path in rf else 'output'}")
            continue
        a, b = np.asarray(gf[path]), np.asarray(rf[path])
        if a[0] != b[0]:
            out.append(f"float field {path!r}: {a[0]:.0f} values, recorded {b[0]:.0f}")
        elif np.abs(a[1:] - b[1:]).max() > RTOL * max(b[1], 1e-300):
            err = np.abs(a[1:] - b[1:]).max() / max(b[1], 1e-300)
            out.append(f"float field {path!r}: differs by {err:.2e} of its norm "
                       f"(tolerance {RTOL:g})")
    return out


@pytest.mark.parametrize("name", _scenes())
def test_shipped_config_bytes(name, tmp_path, shared_mocap):
    recorded = json.loads(STORE.read_text())
    assert name in recorded, f"no fingerprint for {name}: record it (see the module docstring)"
    assert differences(fingerprint(name, tmp_path / "out.zarr"), recorded[name]) == []


def test_fingerprint_on_another_cpu(tmp_path, shared_mocap):
    """A room config run with an older CPU's float paths: the same fingerprint within the
    tolerance (its manifest floats may differ in the last bits: that is the point)."""
    name = "clothed"
    code = ("import json, sys; sys.path.insert(0, sys.argv[1]); "
            "from pathlib import Path; import test_output_bytes as t; "
            "print(json.dumps(t.fingerprint(sys.argv[2], Path(sys.argv[3]))))")
    r = subprocess.run([sys.executable, "-c", code, str(Path(__file__).parent), name,
                        str(tmp_path / "out.zarr")], capture_output=True, text=True,
                       env={**os.environ, **OTHER_CPU}, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert differences(got, json.loads(STORE.read_text())[name]) == []


def test_differences_catch_a_real_change():
    """The float summary catches a change far below a millimetre, and nothing else."""
    rows = [{"frame": k, "world_to_camera": [float(np.sin(k + i)) for i in range(16)],
             "scene": json.dumps({"x": 1.5 + k}), "motion_file": "/a/b.bvh"} for k in range(16)]
    base = manifest_prints(rows)
    noisy = [{**r, "world_to_camera": [v * (1 + 1e-13) for v in r["world_to_camera"]]}
             for r in rows]
    assert differences(manifest_prints(noisy), base) == []
    moved = [dict(r) for r in rows]
    moved[5] = {**moved[5], "world_to_camera": [*rows[5]["world_to_camera"][:3],
                                                rows[5]["world_to_camera"][3] + 1e-5,
                                                *rows[5]["world_to_camera"][4:]]}
    assert differences(manifest_prints(moved), base)
    inner = [dict(r) for r in rows]
    inner[2] = {**inner[2], "scene": json.dumps({"x": 3.5 + 1e-4})}
    assert differences(manifest_prints(inner), base)
    renamed = [dict(r) for r in rows]
    renamed[0] = {**renamed[0], "motion_file": "/a/c.bvh"}
    assert differences(manifest_prints(renamed), base)


if __name__ == "__main__":
    names = sys.argv[1:] or _scenes()
    prints = json.loads(STORE.read_text()) if STORE.exists() else {}
    for n in names:
        with tempfile.TemporaryDirectory() as d:
            prints[n] = fingerprint(n, Path(d) / "out.zarr")
        print(n, prints[n])
    text = json.dumps(prints, indent=1, sort_keys=True)
    # a float field's numbers on one line
    text = re.sub(r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + " ".join(m[1].split()) + "]", text)
    STORE.write_text(text + "\n")
