"""The local pool: frame workers in processes of this machine, without Ray.

A local Ray costs 3-6 s to start and about 1 s to stop on a small machine
(``../shared/design/platform-notes.md``), more than a whole small job. For a job on one
machine the driver therefore runs its :class:`~vhgen.pipeline.worker.FrameWorker` s in
plain child processes, one socket pair each. The contract is the Ray path's: workers set
up while the driver plans, every shard is written by its worker, a worker that dies is
replaced and its shard redone whole, so no frame is lost or duplicated. A replacement
sets up while the other workers go on: the dispatch never waits for it, and one that dies
or fails in its set-up answers its first shard with that (the dispatch counts a death as
an attempt on the shard, as for a Ray actor that dies loading).

A child is a fresh interpreter started with ``python -c`` on the driver's ``sys.path``,
not a ``multiprocessing`` spawn: spawn re-runs the caller's main script in every child,
which breaks any user script without an ``if __name__ == "__main__"`` guard; a fork
would inherit the driver's threads and GL state. A child whose driver disappears reads
end-of-file on its socket and exits.
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import pickle
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.config import JobConfig
from vhgen.errors import RenderError

log = logging.getLogger(__name__)

_STOP_SECONDS = 5.0  # a worker told to stop that is still alive after this is terminated
# arrays of load() at least this big reach the workers as one memory-mapped file each
# instead of a pickled copy per worker (see LocalPool.load)
SPILL_BYTES = 1 << 20
_SPILL_PREFIX = "vhgen-load-"  # + the driver's pid + "-"


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker (set as its ``__cause__``)."""

    def __init__(self, text: str):
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f"\n\"\"\"\n{self.text}\"\"\""


_CHILD = ("import json, sys; sys.path[:] = json.loads(sys.argv[2]); "
          "from vhgen.pipeline.local import serve; serve(int(sys.argv[1]))")


def serve(fd: int) -> None:
    """A worker process (its entry point): read the config from the socket ``fd``, set
    up, then answer ``(method, args)`` messages until told to stop or the driver's end of
    the socket closes."""
    import signal

    from vhgen.pipeline.worker import FrameWorker

    # Ctrl-C on a terminal reaches the whole process group: the driver handles it and
    # stops the workers; a worker printing its own KeyboardInterrupt would only be noise
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    conn = Connection(fd)
    try:
        _, (cfg, asset_dir, faults) = conn.recv()
    except (EOFError, OSError):
        return
    worker = FrameWorker(cfg, asset_dir, faults)
    while True:
        try:
            op, args = conn.recv()
        except (EOFError, OSError):
            return  # the driver is gone
        if op == "stop":
            # every shard is written and renamed in place: end now, as a multiprocessing
            # child does, without the seconds' tenth of GL and interpreter teardown
            conn.close()
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)
        try:
            if op == "load":
                args = _mapped(args)
            reply: tuple[str, Any] = ("ok", getattr(worker, op)(*args))
        except Exception as e:  # sent back whole: the driver decides what the user sees
            text = traceback.format_exc()
            try:
                pickle.dumps(e)
            except Exception:
                e = RuntimeError(f"{type(e).__name__}: {e}")
            reply = ("error", (e, text))
        try:
            conn.send(reply)
        except OSError:
            return  # the driver is gone (killed): nobody to answer


@dataclass
class _Worker:
    process: subprocess.Popen
    conn: Connection
    busy: Any = None  # the task in flight
    stopping: bool = False  # told to stop
    # a replacement: its set-up (the reply to "load") is not read yet, and the run of
    # the task submitted meanwhile waits here for it (None: no task yet)
    loading: bool = False
    deferred: tuple | None = None
    writer: threading.Thread | None = None  # sends the poses and plan to a replacement


class WorkerDied(RenderError):
    """A worker process ended during its set-up (a GL driver crash, an OOM kill)."""


class LocalPool:
    """Frame workers in child processes. ``start`` spawns them (set-up begins at once),
    ``load`` hands every worker the poses and the plan, ``submit``/``wait`` run shards."""

    def __init__(self, cfg: JobConfig, asset_dir: str, faults: dict | None = None):
        self.cfg = cfg
        self.asset_dir = asset_dir
        self.faults = faults
        self.workers: dict[int, _Worker] = {}
        self._retired: list[_Worker] = []  # told to stop, not reaped yet
        self._next_id = 0
        self._load_args: tuple | None = None
        self._spill_dir: str | None = None

    # -- life cycle ------------------------------------------------------------------
    def start(self, n: int) -> list[int]:
        """Spawn ``n`` workers; returns their ids. Does not wait for their set-up."""
        return [self._spawn() for _ in range(n)]

    def _spawn(self) -> int:
        a, b = socket.socketpair()
        ours = Connection(a.detach())
        p = subprocess.Popen([sys.executable, "-c", _CHILD, str(b.fileno()),
                              json.dumps(sys.path)], pass_fds=(b.fileno(),),
                             stdin=subprocess.DEVNULL, env=worker_env())
        b.close()  # the child's end only: its death then reads as end-of-file here
        wid = self._next_id
        self._next_id += 1
        self.workers[wid] = w = _Worker(p, ours)
        self._send(w, "config", (self.cfg, self.asset_dir, self.faults))
        return wid

    def load(self, *args: Any) -> list[str]:
        """Send the poses and the plan to every worker and wait for all of them; returns
        their GL renderer strings. A worker's set-up error (a VhgenError) is raised here,
        a worker that dies setting up raises :class:`WorkerDied`.

        Arrays of at least :data:`SPILL_BYTES` (the pose table: 2.2 kB a pose, 0.45 GB
        for 200k poses), top level or values of a top-level dict, are written once to a
        temporary folder and reach every worker as a read-only memory map of that file:
        one copy in the page cache shared by all workers, as Ray's object store does,
        instead of one pickled copy sent to and held by each. The folder (in the
        system's temporary directory, ``TMPDIR``) is removed by :meth:`close`; one left by
        a driver that was killed is removed by the next job's load."""
        if self._spill_dir is None:
            _remove_stale_spills()
            self._spill_dir = tempfile.mkdtemp(prefix=f"{_SPILL_PREFIX}{os.getpid()}-")
        self._load_args = _spill(args, Path(self._spill_dir))
        for w in self.workers.values():
            self._send(w, "load", self._load_args)
        return [self._take_load(wid) for wid in list(self.workers)]

    def _take_load(self, wid: int) -> str:
        w = self.workers[wid]
        kind, value = self._recv(wid)
        if kind == "died":
            raise WorkerDied(f"worker {wid} (pid {w.process.pid}) died during set-up "
                             f"(exit code {value})")
        if kind == "error":
            raise _with_remote(value)
        return str(value)

    def stop(self, wids: list[int]) -> None:
        """Stop these workers (e.g. more workers than tasks), without waiting: a worker
        still setting up reads the request after its set-up; close() reaps it."""
        for wid in wids:
            w = self.workers.pop(wid)
            self._send(w, "stop", ())
            w.stopping = True
            self._retired.append(w)

    def release(self) -> None:
        """Tell every idle worker to stop, without waiting (close() reaps them). A
        replacement still setting up is not told: close() terminates it."""
        for w in self.workers.values():
            if w.busy is None and not w.stopping and not w.loading:
                w.stopping = True
                self._send(w, "stop", ())

    def close(self) -> None:
        """Stop every worker; the ones that do not stop in time are terminated."""
        self.release()
        for w in [*self.workers.values(), *self._retired]:
            # a worker still busy (an error stopped the job) or still setting up holds
            # no finished work: it is not waited for
            _end(w.process, _STOP_SECONDS if w.busy is None and not w.loading else 0.0)
            _close(w)
        self.workers.clear()
        self._retired.clear()
        if self._spill_dir is not None:
            shutil.rmtree(self._spill_dir, ignore_errors=True)
            self._spill_dir = None

    def replace(self, wid: int) -> int:
        """Start a new worker in place of the dead one ``wid`` and return its id at once.

        Its set-up and load go on while the dispatch collects the other workers' shards:
        a task submitted to it runs after its load, and if it dies or fails setting up,
        :meth:`wait` answers that task with ``died`` or ``error``."""
        old = self.workers.pop(wid)
        _end(old.process, 1.0)
        _close(old)
        new = self._spawn()
        if self._load_args is not None:
            w = self.workers[new]
            w.loading = True
            # from a thread: the poses and plan are larger than the socket's buffer, so
            # sending them blocks until the new worker has set up and reads them
            w.writer = threading.Thread(target=_write, args=(w.conn, ("load", self._load_args)),
                                        name=f"vhgen-load-{new}", daemon=True)
            w.writer.start()
        return new

    # -- tasks -----------------------------------------------------------------------
    def submit(self, wid: int, task: Any, *args: Any) -> None:
        """Run ``worker.run(*args)`` on worker ``wid``; ``task`` is returned by wait()."""
        w = self.workers[wid]
        w.busy = task
        if w.loading:
            w.deferred = args  # sent by wait() once the load has succeeded
        else:
            self._send(w, "run", args)

    def wait(self, timeout: float | None = None) -> list[tuple[int, Any, str, Any]]:
        """Block until at least one busy worker answers or dies, or ``timeout`` seconds
        pass (then: an empty list). Returns ``(worker id, task, kind, value)`` with kind
        ``ok`` (value: the result), ``died`` (value: the exit code) or ``error`` (value:
        the exception, its ``__cause__`` the worker's traceback).

        A busy replacement answers its load first: a load that succeeded is not
        reported (the task's run is sent then, its reply comes later); one that died
        or raised answers the task with ``died`` or ``error``, as :meth:`load` would
        have raised it."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            busy = {wid: w for wid, w in self.workers.items() if w.busy is not None}
            if not busy:
                return []
            # a dead worker's socket reads as end-of-file: readable, like a reply. A
            # replacement has one request in flight at a time (its run is sent only after
            # its load's reply), so each readable socket holds the answer to that one
            handles = {w.conn: wid for wid, w in busy.items()}
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready = {handles[h] for h in wait(list(handles), left)}  # type: ignore[index]
            out = []
            for wid in sorted(ready):
                w = self.workers[wid]
                kind, value = self._recv(wid)
                if w.loading:
                    w.loading = False
                    if kind == "ok":  # set up and loaded: now the task
                        self._send(w, "run", w.deferred or ())
                        w.deferred = None
                        continue
                    w.deferred = None
                task, w.busy = w.busy, None
                out.append((wid, task, kind,
                            _with_remote(value) if kind == "error" else value))
            # a load that succeeded is no answer: wait on, for what time is left
            if out or (not ready and deadline is not None and time.monotonic() >= deadline):
                return out

    # -- pipe ------------------------------------------------------------------------
    def _send(self, w: _Worker, op: str, args: tuple) -> None:
        if w.writer is not None:
            # the load goes first: sent by now (only called once the worker replied or
            # for a worker that is not loading)
            w.writer.join()
        _write(w.conn, (op, args))

    def _recv(self, wid: int) -> tuple[str, Any]:
        """The worker's next reply, or ``("died", exit code)``; a reply sent just before
        the process ended is still read."""
        w = self.workers[wid]
        try:
            return w.conn.recv()
        except (EOFError, OSError):
            _end(w.process, 1.0)
            return "died", w.process.returncode


def worker_env() -> dict[str, str]:
    """The driver's environment, with one thread per worker for the math libraries (the
    workers are the parallelism; what Ray sets for a one-CPU actor) unless the user chose."""
    env = dict(os.environ)
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
              "NUMBA_NUM_THREADS", "LP_NUM_THREADS"):
        env.setdefault(k, "1")
    return env


def _end(p: subprocess.Popen, seconds: float) -> None:
    """Wait up to ``seconds`` for a worker to exit, then terminate (and reap) it."""
    try:
        p.wait(seconds)
        return
    except subprocess.TimeoutExpired:
        pass
    p.terminate()
    try:
        p.wait(_STOP_SECONDS)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()


@dataclass(frozen=True)
class _MappedArray:
    """A stand-in for an array written to ``path`` (.npy), read back memory-mapped."""

    path: str


def _remove_stale_spills() -> None:
    """Remove the spill folders of drivers that no longer run (killed before close())."""
    for p in Path(tempfile.gettempdir()).glob(f"{_SPILL_PREFIX}*-*"):
        pid = p.name[len(_SPILL_PREFIX):].split("-", 1)[0]
        if pid.isdigit() and p.is_dir() and not _running(int(pid)):
            shutil.rmtree(p, ignore_errors=True)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # exists, another user's
    return True


def _each_array(args: tuple, fn: Any) -> tuple:
    """``args`` with ``fn`` applied to each top-level value and each value of a top-level
    dict (where load()'s arrays are)."""
    return tuple({k: fn(v) for k, v in a.items()} if isinstance(a, dict) else fn(a)
                 for a in args)


def _spill(args: tuple, folder: Path) -> tuple:
    """``args`` with every big array (see :func:`_each_array`) written to ``folder`` and
    replaced by a :class:`_MappedArray`."""
    count = itertools.count()

    def one(a: Any) -> Any:
        if not isinstance(a, np.ndarray) or a.nbytes < SPILL_BYTES or a.dtype.hasobject:
            return a
        path = folder / f"array-{next(count)}.npy"
        np.save(path, a, allow_pickle=False)
        return _MappedArray(str(path))

    return _each_array(args, one)


def _mapped(args: tuple) -> tuple:
    """The inverse of :func:`_spill` in a worker: read-only memory maps of the files."""
    return _each_array(args, lambda a: np.load(a.path, mmap_mode="r")
                       if isinstance(a, _MappedArray) else a)


def _write(conn: Connection, message: tuple) -> None:
    try:
        conn.send(message)
    except OSError:
        pass  # the worker is dead: its socket reads as end-of-file in wait()


def _close(w: _Worker) -> None:
    """Close the driver's end of a worker's socket, once its process has ended (a load
    still being sent then fails at once) and nothing writes to it any more (closing a
    descriptor another thread writes to could let a new socket reuse its number)."""
    if w.writer is not None:
        w.writer.join()
    w.conn.close()


def _with_remote(value: tuple[BaseException, str]) -> BaseException:
    exc, text = value
    exc.__cause__ = RemoteTraceback(text)
    return exc
