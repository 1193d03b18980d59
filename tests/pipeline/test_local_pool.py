"""The local executor: frame workers in child processes of the driver, without Ray.

Which executor a job gets, what the user sees when a worker fails, that a replacement
worker sets up without holding up the job and that its death or failure in set-up is
retried or reported like any other, that a user's script needs no
``if __name__ == "__main__"`` guard, and that no worker outlives its driver."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import pytest

from tests.pipeline.faulty_worker import run_faulty
from vhgen.errors import VhgenError
from vhgen.executor.local import RemoteTraceback
from vhgen.job_config import JobConfig
from vhgen.pipeline.driver import run_job
from vhgen.pipeline.resources import choose_executor
from vhgen.store.inspect import inspect_store

REPO = Path(__file__).resolve().parents[2]

SCENE = """
name: pool
seed: 3
motions: [builtin:demo]
poses: {frame_step: 8}
avatars: {count: 1}
output: {frames_per_shard: 4}
render: {backend: osmesa}
num_workers: 2
"""


@pytest.fixture
def cfg(tmp_path) -> JobConfig:
    p = tmp_path / "pool.yaml"
    p.write_text(SCENE)
    return JobConfig.load(p)


def test_executor_choice(cfg):
    gpu = replace(cfg, gpus_per_worker=1.0)
    assert choose_executor("auto", None, cfg) == "local"
    assert choose_executor("auto", "10.0.0.1:6379", cfg) == "ray"
    assert choose_executor("ray", None, cfg) == "ray"
    assert choose_executor("local", None, cfg) == "local"
    with pytest.raises(VhgenError, match="cannot use the Ray cluster at 10.0.0.1:6379"):
        choose_executor("local", "10.0.0.1:6379", cfg)
    with pytest.raises(VhgenError, match="--executor: 'threads' is not one of"):
        choose_executor("threads", None, cfg)
    assert choose_executor("auto", None, gpu) == "ray"  # Ray assigns the GPUs
    with pytest.raises(VhgenError, match="render.gpus_per_worker needs --executor ray"):
        choose_executor("local", None, gpu)


def test_worker_bug_keeps_its_traceback(cfg, tmp_path):
    """An internal error in a worker reaches the driver as the same exception type, with
    the worker's traceback attached (a bug must stay debuggable)."""
    with pytest.raises(RuntimeError, match="injected bug on shard 1") as info:
        run_faulty(cfg, tmp_path / "bug.zarr", {"crash": {1}}, max_frames=8,
                   executor="local")
    cause = info.value.__cause__
    assert isinstance(cause, RemoteTraceback)
    assert "faulty_worker.py" in cause.text and "in run" in cause.text


def test_script_without_main_guard(cfg, tmp_path):
    """A plain script calling run_job at top level works: the workers do not re-run the
    caller's main module (multiprocessing's spawn would, and fail)."""
    script = tmp_path / "plain.py"
    script.write_text(
        "from vhgen.job_config import JobConfig\n"
        "from vhgen.pipeline.driver import run_job\n"
        f"s = run_job(JobConfig.load({str(tmp_path / 'pool.yaml')!r}), "
        f"{str(tmp_path / 'plain.zarr')!r}, max_frames=8)\n"
        "print('frames', s.frames, s.executor)\n")
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                       cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "frames 8 local" in r.stdout


def _children(pid: int) -> list[int]:
    out = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                stat = (p / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(p.name))
    return out


def _alive(pid: int) -> bool:
    try:
        stat = (Path("/proc") / str(pid) / "stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def test_workers_do_not_outlive_a_killed_driver(tmp_path):
    """SIGKILL the driver mid-job: its workers see their socket close and exit."""
    (tmp_path / "long.yaml").write_text(SCENE.replace("frame_step: 8", "frame_step: 1"))
    log = tmp_path / "driver.log"
    with open(log, "w") as err:
        driver = subprocess.Popen(
            [sys.executable, "-c", "import sys; from vhgen.cli import main; sys.exit(main())",
             "-q", "generate", str(tmp_path / "long.yaml"), "--out",
             str(tmp_path / "long.zarr")], cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=err)
    try:
        parts = tmp_path / "long.zarr" / "manifest"
        workers: list[int] = []
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and driver.poll() is None:
            workers = _children(driver.pid)
            if len(workers) == 2 and parts.is_dir() and any(parts.glob("part-*.parquet")):
                break  # mid-job: both workers up, a shard written
            time.sleep(0.1)
        assert driver.poll() is None, f"driver ended early: {log.read_text()[-2000:]}"
        assert len(workers) == 2, f"expected 2 workers, found {workers}"
        os.kill(driver.pid, signal.SIGKILL)
        driver.wait(10)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.2)
        assert not any(_alive(w) for w in workers), "a worker outlived its driver"
    finally:
        if driver.poll() is None:
            driver.kill()


def test_ctrl_c_is_one_line_and_stops_the_workers(tmp_path):
    """SIGINT to the job's process group (Ctrl-C on a terminal): the driver answers in
    one line with exit code 130, no worker prints a traceback, no worker is left, and
    --resume finishes the store."""
    (tmp_path / "long.yaml").write_text(SCENE.replace("frame_step: 8", "frame_step: 1"))
    cmd = [sys.executable, "-c", "import sys; from vhgen.cli import main; sys.exit(main())",
           "-q", "generate", str(tmp_path / "long.yaml"), "--out", str(tmp_path / "i.zarr")]
    driver = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, start_new_session=True,
                              preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    parts = tmp_path / "i.zarr" / "manifest"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and driver.poll() is None and not (
            parts.is_dir() and any(parts.glob("part-*.parquet"))):
        time.sleep(0.1)
    workers = _children(driver.pid)
    assert driver.poll() is None and len(workers) == 2
    os.killpg(driver.pid, signal.SIGINT)
    _, err = driver.communicate(timeout=60)
    assert driver.returncode == 130
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines() == [
        "vhgen: interrupted (finished shards are kept: rerun with --resume)"]
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(w) for w in workers):
        time.sleep(0.1)
    assert not any(_alive(w) for w in workers)
    r = subprocess.run([*cmd, "--resume"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    rep = inspect_store(tmp_path / "i.zarr")
    assert rep.ok, rep.defects


def test_spilled_load_writes_the_same_bytes_and_cleans_up(cfg, tmp_path, monkeypatch):
    """A job whose every array goes to the workers through a memory-mapped file writes
    the same frames as one that pickles them, and leaves no temporary file behind."""
    import tempfile

    from vhgen.executor import local

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))

    def frames(out: Path) -> dict[str, bytes]:
        return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*"))
                if p.is_file() and {"depth", "labels"} & set(p.parts)}

    monkeypatch.setattr(local, "SPILL_BYTES", 1)  # every array spilled
    run_job(cfg, tmp_path / "mapped.zarr", max_frames=8, executor="local")
    assert list(tmp.iterdir()) == []
    monkeypatch.setattr(local, "SPILL_BYTES", 1 << 62)  # none
    run_job(cfg, tmp_path / "pickled.zarr", max_frames=8, executor="local")
    a, b = frames(tmp_path / "mapped.zarr"), frames(tmp_path / "pickled.zarr")
    assert len(a) >= 4 and a == b


@contextmanager
def _deadline(seconds: int) -> Iterator[None]:
    """Fail (TimeoutError) instead of hanging: the dispatch loop and the pool's reads are
    in this thread, so the alarm's exception unwinds the job and closes its workers."""
    def expire(signum: int, frame: object) -> None:
        raise TimeoutError(f"the job did not end within {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.mark.parametrize("executor", ["local", pytest.param("ray", marks=pytest.mark.slow)])
def test_replacement_dying_in_setup_is_retried(cfg, tmp_path, executor):
    """A worker dies on shard 0; its replacement dies in its own set-up (a GL driver
    crash, an OOM kill): that counts as one more attempt on the shard, the next
    replacement finishes it, and every frame is written exactly once."""
    import pyarrow.parquet as pq

    out = tmp_path / "setup-once.zarr"
    with _deadline(120):
        summary = run_faulty(cfg, out, {"die_once": {0}, "die_in_setup": 1}, max_frames=16,
                             executor=executor)
    assert summary.frames == 16 and summary.written == 4
    assert summary.retries == 2  # the death on the shard, the death in set-up
    rep = inspect_store(out)
    assert rep.ok, rep.defects
    man = pq.read_table(out / "manifest.parquet")
    assert man.column("frame").to_pylist() == list(range(16))


def test_replacement_always_dying_in_setup_ends_in_one_line(cfg, tmp_path):
    """Every replacement dies in its set-up: after MAX_ATTEMPTS retries of the shard the
    job ends with one line (no hang, no WorkerDied traceback), the shards the other
    worker finished stay, and --resume completes the store."""
    from vhgen.pipeline.driver import MAX_ATTEMPTS

    out = tmp_path / "setup-always.zarr"
    with _deadline(120), pytest.raises(VhgenError) as info:
        run_faulty(cfg, out, {"die_once": {0}, "die_in_setup": 100}, max_frames=16,
                   executor="local")
    msg = str(info.value)
    assert "\n" not in msg
    assert f"shard 0 (frames 0-4): worker died {MAX_ATTEMPTS + 1} times; rerun with " \
        "--resume" in msg
    parts = {p.name for p in (out / "manifest").glob("part-*.parquet")}
    assert parts, "the shards the other worker finished were not kept"
    assert parts <= {f"part-{k:06d}.parquet" for k in (1, 2, 3)}
    with _deadline(120):
        summary = run_job(cfg, out, max_frames=16, executor="local", resume=True)
    assert summary.written == 4 - len(parts)  # only what was missing
    rep = inspect_store(out)
    assert rep.ok, rep.defects


@pytest.mark.parametrize("executor", ["local", pytest.param("ray", marks=pytest.mark.slow)])
def test_replacement_setup_error_is_one_line(cfg, tmp_path, executor):
    """A replacement whose set-up fails with a user-facing error (no GL device left)
    ends the job with that error for the shard it was to redo, in one line."""
    with _deadline(120), pytest.raises(VhgenError) as info:
        run_faulty(cfg, tmp_path / "setup-error.zarr",
                   {"die_once": {0}, "replacement_setup_error":
                    "cannot create an egl OpenGL context: no device"},
                   max_frames=16, executor=executor)
    assert str(info.value) == "shard 0: cannot create an egl OpenGL context: no device"


def test_dispatch_goes_on_while_a_replacement_sets_up(cfg, tmp_path):
    """The replacement of the worker that died on shard 0 cannot finish its set-up
    before the other worker has written shards 1-3: the driver must keep handing that
    worker shards meanwhile (it used to block until the replacement was loaded)."""
    out = tmp_path / "overlap.zarr"
    others = [str(out / "manifest" / f"part-{k:06d}.parquet") for k in (1, 2, 3)]
    with _deadline(120):
        summary = run_faulty(cfg, out, {"die_once": {0}, "replacement_waits_for": others},
                             max_frames=16, executor="local")
    assert summary.written == 4 and summary.retries == 1
    # the retried shard came last (its shard files are the newest; the merge removed the
    # manifest parts)
    written = {k: (out / "depth" / "c" / str(k) / "0" / "0").stat().st_mtime_ns
               for k in range(4)}
    assert written[0] > max(written[1], written[2], written[3])
    rep = inspect_store(out)
    assert rep.ok, rep.defects


@pytest.mark.gl
def test_worker_takes_its_share_of_codec_threads(cfg, monkeypatch):
    # zarr's codec pool has a thread per core in each process; a frame worker keeps its
    # share of the cores (16 pools of 16 on a 16-core node cost 17% of its frames/s)
    import zarr

    from vhgen.pipeline.worker import FrameWorker
    from vhgen.store.zarr_store import set_codec_threads

    before = zarr.config.get("threading.max_workers")
    cores = len(os.sched_getaffinity(0))
    try:
        monkeypatch.delenv("ZARR_THREADING__MAX_WORKERS", raising=False)
        for workers, share in ((1, cores), (cores * 4, 1)):
            w = FrameWorker(replace(cfg, num_workers=workers))
            assert w.setup_error is None
            assert zarr.config.get("threading.max_workers") == share
            w.ctx.release()
        zarr.config.set({"threading.max_workers": 3})  # as zarr reads the variable
        monkeypatch.setenv("ZARR_THREADING__MAX_WORKERS", "3")  # the user's choice wins
        set_codec_threads(1)
        assert zarr.config.get("threading.max_workers") == 3
    finally:
        zarr.config.set({"threading.max_workers": before})
