"""Faults on the output side: a full disk (injected in the worker, and a real size-limited
tmpfs), a read-only output, a store made by another config. Each is one clear line, the
finished shards stay intact, and ``--resume`` finishes the job."""

from __future__ import annotations

import errno
import subprocess
from pathlib import Path

import pytest

from tests.conftest import unmerge_manifest
from tests.pipeline.faulty_worker import run_faulty
from vhgen.cli import main
from vhgen.errors import StoreError
from vhgen.job_config import JobConfig
from vhgen.pipeline.driver import run_job
from vhgen.store.zarr_store import completed_shards

pytestmark = pytest.mark.slow

SCENE = """
name: faults
seed: {seed}
motions: [builtin:demo]
poses: {{frame_step: 8}}
avatars: {{count: 1}}
output: {{frames_per_shard: 4}}
render: {{backend: osmesa}}
num_workers: 2
"""


def _cfg(tmp: Path, seed: int = 5) -> JobConfig:
    p = tmp / f"scene{seed}.yaml"
    p.write_text(SCENE.format(seed=seed))
    return JobConfig.load(p)


def _parts(store: Path) -> set[str]:
    return {p.name for p in (store / "manifest").glob("part-*.parquet")}


def _shard_bytes(store: Path, shard: int) -> dict[str, bytes]:
    return {str(p.relative_to(store)): p.read_bytes()
            for arr in ("depth", "labels") for p in (store / arr / "c" / str(shard)).rglob("*")
            if p.is_file()}


@pytest.fixture
def tmpfs(tmp_path):
    """A small tmpfs; fails (never skips) if it cannot be mounted."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()

    def mount(opts: str) -> Path:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(mnt)],
                           capture_output=True, text=True)
        assert r.returncode == 0, f"cannot mount a tmpfs (needs root): {r.stderr}"
        return mnt

    def remount(opts: str) -> None:
        r = subprocess.run(["mount", "-o", f"remount,{opts}", str(mnt)], capture_output=True,
                           text=True)
        assert r.returncode == 0, r.stderr

    yield mount, remount
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


@pytest.mark.parametrize("executor", ["local", "ray"])
def test_injected_disk_full_then_resume(tmp_path, executor):
    cfg = _cfg(tmp_path)
    store = tmp_path / "inj.zarr"
    with pytest.raises(StoreError) as ei:
        run_faulty(cfg, store, {"write_error": (errno.ENOSPC, {1})}, max_frames=16,
                executor=executor)
    msg = str(ei.value)
    assert "\n" not in msg and "shard 1" in msg and "No space left on device" in msg
    assert "ENOSPC" in msg and "--resume" in msg
    assert "part-000001.parquet" not in _parts(store)
    done = _parts(store)
    assert "part-000000.parquet" in done  # the shard in flight with the failing one finished
    before = _shard_bytes(store, 0)
    summary = run_job(cfg, store, max_frames=16, resume=True)
    assert summary.written == 4 - len(done)  # only what was missing
    assert _shard_bytes(store, 0) == before  # finished shards untouched
    import pyarrow.parquet as pq

    assert pq.read_table(store / "manifest.parquet").column("frame").to_pylist() == \
        list(range(16))


def test_real_full_disk_then_resume(tmp_path, tmpfs, capsys):
    mount, remount = tmpfs
    mnt = mount("size=160k")
    scene = tmp_path / "scene.yaml"
    scene.write_text(SCENE.format(seed=5))
    out = mnt / "full.zarr"
    argv = ["-q", "generate", str(scene), "--out", str(out), "--max-frames", "24"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "No space left on device" in err and "--resume" in err and "Traceback" not in err
    remount("size=16m")
    assert main([*argv, "--resume"]) == 0
    # merged: manifest.parquet holds every shard and is the one copy (no parts left)
    assert completed_shards(out) == set(range(6)) and not _parts(out)
    import zarr

    lab = zarr.open_group(str(out), mode="r")["labels"][:]
    assert lab.shape[0] == 24 and (lab > 0).sum(axis=(1, 2)).min() > 5000


def test_read_only_output(tmp_path, tmpfs, capsys):
    mount, remount = tmpfs
    mnt = mount("size=4m")
    (mnt / "existing").mkdir()
    remount("ro")
    scene = tmp_path / "scene.yaml"
    scene.write_text(SCENE.format(seed=5))
    for out, flags in ((mnt / "new.zarr", []), (mnt / "existing", ["--resume"])):
        assert main(["generate", str(scene), "--out", str(out), *flags]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "read-only file system" in err, err


def test_store_from_another_config(tmp_path, capsys):
    store = tmp_path / "a.zarr"
    run_job(_cfg(tmp_path, seed=5), store, max_frames=4)
    before = _shard_bytes(store, 0)
    other = tmp_path / "scene6.yaml"
    other.write_text(SCENE.format(seed=6))
    assert main(["generate", str(other), "--out", str(store), "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "another config" in err and "'seed'" in err
    assert _shard_bytes(store, 0) == before
    # without --resume/--overwrite an existing store is never touched
    assert main(["generate", str(other), "--out", str(store)]) == 2
    assert "exists" in capsys.readouterr().err
    # --overwrite never deletes a folder that is not a vhgen store
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("x")
    assert main(["generate", str(other), "--out", str(tmp_path / "mine"), "--overwrite"]) == 2
    assert "not a vhgen store" in capsys.readouterr().err
    assert (tmp_path / "mine" / "thesis.tex").exists()


@pytest.mark.parametrize("executor", ["local", "ray"])
def test_worker_setup_failure_is_one_line(tmp_path, capsys, executor):
    """A worker that cannot set up (no GL backend, ...) gives its error, not a trace."""
    from vhgen.errors import VhgenError

    with pytest.raises(VhgenError) as ei:
        run_faulty(_cfg(tmp_path), tmp_path / "s.zarr",
                   {"setup_error": "cannot create an egl OpenGL context: no device"},
                   max_frames=4, executor=executor)
    msg = str(ei.value)
    assert "\n" not in msg and "cannot create an egl OpenGL context" in msg


def test_merge_failure_keeps_everything_and_resumes(tmp_path, capsys, monkeypatch):
    """A manifest part the driver cannot read at the end of the job (a reader of another
    version, a damaged file): one line naming the part, every shard and part kept, and
    --resume merges once the cause is gone, rendering nothing again."""
    import pyarrow as pa

    import vhgen.store.manifest as manifest

    real = manifest.read_manifest_table

    def failing(path, columns=None):
        if Path(path).name == "part-000001.parquet":
            raise pa.ArrowInvalid("Expected all lists to be of size=3 but index 1 had size=0")
        return real(path, columns)

    scene = tmp_path / "scene.yaml"
    scene.write_text(SCENE.format(seed=5))
    out = tmp_path / "m.zarr"
    argv = ["-q", "generate", str(scene), "--out", str(out), "--max-frames", "12",
            "--executor", "local"]
    monkeypatch.setattr(manifest, "read_manifest_table", failing)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert "part-000001.parquet" in err and "size=3" in err and "--resume" in err
    assert _parts(out) == {f"part-{k:06d}.parquet" for k in range(3)}
    assert not (out / "manifest.parquet").exists()
    before = {k: _shard_bytes(out, k) for k in range(3)}
    monkeypatch.setattr(manifest, "read_manifest_table", real)
    summary = run_job(JobConfig.load(scene), out, max_frames=12, resume=True,
                      executor="local")
    assert summary.written == 0  # nothing rendered again: only the merge was missing
    assert {k: _shard_bytes(out, k) for k in range(3)} == before
    assert real(out / "manifest.parquet").column("frame").to_pylist() == list(range(12))


def test_damaged_part_is_rendered_again_on_resume(tmp_path):
    """A part damaged on disk (truncated) is still unreadable when resuming: its shard,
    and only it, is rendered again, to the same bytes."""
    import pyarrow.parquet as pq

    cfg = _cfg(tmp_path)
    out = tmp_path / "d.zarr"
    run_job(cfg, out, max_frames=12, executor="local")
    rows = pq.read_table(out / "manifest.parquet").to_pylist()
    before = {k: _shard_bytes(out, k) for k in range(3)}
    assert not (out / "manifest").exists()  # the merge removed the parts
    unmerge_manifest(out)  # as if stopped before the merge, with part 2 damaged
    part = out / "manifest" / "part-000002.parquet"
    part.write_bytes(part.read_bytes()[:100])
    summary = run_job(cfg, out, max_frames=12, resume=True, executor="local")
    assert summary.written == 1
    assert {k: _shard_bytes(out, k) for k in range(3)} == before
    assert pq.read_table(out / "manifest.parquet").to_pylist() == rows
