"""The local pool's own mechanics, without a frame job: any worker class, set-up inputs
as memory maps, errors with the worker's traceback, stale spill folders."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass

import numpy as np
import pytest

from vhgen.errors import VhgenError
from vhgen.executor import local
from vhgen.executor.local import LocalPool, RemoteTraceback


@dataclass(frozen=True, eq=False)
class Inputs:
    big: np.ndarray
    small: np.ndarray
    table: dict
    other: tuple


class Echo:
    """A worker that keeps what set-up gave it and answers questions about it."""

    def __init__(self, name: str):
        if name == "broken":
            raise VhgenError("cannot set up: broken")
        self.name = name
        self.inputs: Inputs | None = None

    def take(self, inputs: Inputs) -> str:
        self.inputs = inputs
        return self.name

    def describe(self, k: int) -> tuple:
        assert self.inputs is not None
        b = self.inputs.big
        return (self.name, type(b).__name__, b.flags.writeable, float(b.sum()) * k,
                os.getpid())

    def fail(self) -> None:
        raise ValueError("a bug in the worker")


def test_big_arrays_anywhere_are_memory_maps(tmp_path):
    """Arrays of at least SPILL_BYTES anywhere in the set-up inputs (a dataclass field, a
    dict value) are written once and read back as read-only memory maps equal to what was
    sent; small arrays and other values come back as they were."""
    big = np.arange(local.SPILL_BYTES // 8 + 1, dtype=np.float64).reshape(-1, 1)
    small = np.arange(10)
    x = Inputs(big, small, {"seeds": big.ravel().astype(np.uint64), "n": small}, (1, "a"))
    got = local._mapped_loads(local.spill_dumps((x, 0.5), tmp_path))
    y, half = got
    assert half == 0.5 and y.other == (1, "a")
    assert isinstance(y.big, np.memmap) and not y.big.flags.writeable
    assert np.array_equal(y.big, big) and y.big.dtype == big.dtype
    assert isinstance(y.table["seeds"], np.memmap)
    assert np.array_equal(y.table["seeds"], x.table["seeds"])
    assert not isinstance(y.small, np.memmap) and np.array_equal(y.small, small)
    assert len(list(tmp_path.glob("*.npy"))) == 2


def test_any_worker_class_runs_in_child_processes():
    """Workers are built in their own processes from their arguments, set-up reaches all
    of them, map() and submit()/wait() call them, errors come back with the worker's
    traceback; close() leaves no process behind."""
    pool = LocalPool(Echo)
    try:
        pool.start([("a",), ("b",)])
        big = np.ones(local.SPILL_BYTES // 8 + 1)
        assert pool.setup("take", Inputs(big, big[:3], {}, ())) == ["a", "b"]
        answers = pool.map("describe", 2)
        assert [a[:4] for a in answers] == [("a", "memmap", False, 2.0 * big.size),
                                            ("b", "memmap", False, 2.0 * big.size)]
        pids = {a[4] for a in answers}
        assert len(pids) == 2 and os.getpid() not in pids
        wid = next(iter(pool.workers))
        pool.submit(wid, "t1", "fail")
        [(got_wid, task, kind, err)] = pool.wait(timeout=60)
        assert (got_wid, task, kind) == (wid, "t1", "error")
        assert isinstance(err, ValueError) and isinstance(err.__cause__, RemoteTraceback)
        assert "in fail" in err.__cause__.text
        procs = [w.process for w in pool.workers.values()]
    finally:
        pool.close()
    assert all(p.poll() is not None for p in procs)


def test_a_worker_that_cannot_be_built_answers_with_its_error():
    pool = LocalPool(Echo)
    try:
        pool.start([("broken",)])
        with pytest.raises(VhgenError, match="cannot set up: broken"):
            pool.setup("take", Inputs(np.zeros(1), np.zeros(1), {}, ()))
    finally:
        pool.close()


def test_stale_spill_folders_of_dead_drivers_are_removed(tmp_path, monkeypatch):
    """A spill folder whose driver no longer runs (killed before close()) goes at the next
    load; one of a running driver stays."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f"{local._SPILL_PREFIX}{dead.pid}-x1"
    live = tmp_path / f"{local._SPILL_PREFIX}{os.getpid()}-x2"
    for d in (stale, live):
        d.mkdir()
        (d / "array-0.npy").write_bytes(b"0")
    local._remove_stale_spills()
    assert not stale.exists() and live.exists()


