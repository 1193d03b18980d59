"""The local pool: worker objects in processes of this machine, without Ray.

A local Ray costs 3-6 s to start and about 1 s to stop on a small machine
(``../shared/design/platform-notes.md``), more than a whole small job. For work on one
machine vhgen therefore runs its workers (the frame job's
:class:`~vhgen.pipeline.worker.FrameWorker`, the forest's image shards) in plain child
processes, one socket pair each; :class:`~vhgen.executor.raypool.RayPool` offers the same
interface on Ray actors. The contract: a worker object is constructed in its process
from picklable arguments (its set-up starts at once, while the caller prepares), a
``setup`` call hands every worker the same large inputs and is replayed on a
replacement, ``submit``/``wait`` run calls one at a time per worker, a worker that dies is
reported as ``died`` (its caller decides what to redo). A replacement sets up while the
other workers go on: the caller never waits for it, and one that dies or fails in its
set-up answers its first call with that.

A child is a fresh interpreter started with ``python -c`` on the driver's ``sys.path``,
not a ``multiprocessing`` spawn: spawn re-runs the caller's main script in every child,
which breaks any user script without an ``if __name__ == "__main__"`` guard; a fork
would inherit the driver's threads and GL state. A child whose driver disappears reads
end-of-file on its socket and exits.
"""

from __future__ import annotations

import io
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

from vhgen.errors import RenderError

log = logging.getLogger(__name__)

_STOP_SECONDS = 5.0  # a worker told to stop that is still alive after this is terminated
# arrays of a setup() call at least this big reach the workers as one memory-mapped file
# each instead of a pickled copy per worker (see LocalPool.setup)
SPILL_BYTES = 1 << 20
_SPILL_PREFIX = "vhgen-setup-"  # + the caller's pid + "-"


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker (set as its ``__cause__``)."""

    def __init__(self, text: str):
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f"\n\"\"\"\n{self.text}\"\"\""


_CHILD = ("import json, sys; sys.path[:] = json.loads(sys.argv[2]); "
          "from vhgen.executor.local import serve; serve(int(sys.argv[1]))")


def serve(fd: int) -> None:
    """A worker process (its entry point): read the worker class and its arguments from
    the socket ``fd``, construct it, then answer ``(op, (method, args))`` messages until
    told to stop or the caller's end of the socket closes."""
    import signal

    # Ctrl-C on a terminal reaches the whole process group: the caller handles it and
    # stops the workers; a worker printing its own KeyboardInterrupt would only be noise
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    conn = Connection(fd)
    try:
        _, (worker_cls, init) = conn.recv()
    except (EOFError, OSError):
        return
    worker: Any = None
    failed: tuple[str, Any] | None = None
    try:
        worker = worker_cls(*init)
    except Exception as e:  # answered to every call: the caller decides what the user sees
        failed = _error_reply(e)
    while True:
        try:
            op, payload = conn.recv()
        except (EOFError, OSError):
            return  # the caller is gone
        if op == "stop":
            # every result is written and renamed in place: end now, as a multiprocessing
            # child does, without the seconds' tenth of GL and interpreter teardown
            conn.close()
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)
        method, args = payload
        reply: tuple[str, Any]
        if failed is not None:
            reply = failed
        else:
            try:
                if op == "setup":
                    args = _mapped_loads(args)
                reply = ("ok", getattr(worker, method)(*args))
            except Exception as e:  # sent back whole
                reply = _error_reply(e)
        try:
            conn.send(reply)
        except OSError:
            return  # the caller is gone (killed): nobody to answer


def _error_reply(e: Exception) -> tuple[str, Any]:
    text = traceback.format_exc()
    try:
        pickle.dumps(e)
    except Exception:
        e = RuntimeError(f"{type(e).__name__}: {e}")
    return "error", (e, text)


@dataclass
class _Worker:
    process: subprocess.Popen
    conn: Connection
    init: tuple  # the constructor's arguments (a replacement gets the same)
    busy: Any = None  # the task in flight
    stopping: bool = False  # told to stop
    # a replacement: its set-up (the reply to the replayed "setup") is not read yet, and
    # the call submitted meanwhile waits here for it (None: no call yet)
    loading: bool = False
    deferred: tuple | None = None
    writer: threading.Thread | None = None  # sends the set-up inputs to a replacement


class WorkerDied(RenderError):
    """A worker process ended during its set-up (a GL driver crash, an OOM kill)."""


class LocalPool:
    """Workers of class ``worker_cls`` in child processes. ``start`` spawns them (each
    constructs its worker at once), ``setup`` hands every worker the same inputs,
    ``submit``/``wait`` run calls, ``map`` calls every worker and gathers the results."""

    def __init__(self, worker_cls: type):
        self.worker_cls = worker_cls
        self.workers: dict[int, _Worker] = {}
        self._retired: list[_Worker] = []  # told to stop, not reaped yet
        self._next_id = 0
        self._setup: tuple | None = None  # the last setup call, replayed on replacements
        self._spill_dir: str | None = None

    # -- life cycle ------------------------------------------------------------------
    def start(self, inits: list[tuple]) -> list[int]:
        """Spawn one worker per tuple of constructor arguments; returns their ids. Does
        not wait for their construction."""
        return [self._spawn(tuple(init)) for init in inits]

    def _spawn(self, init: tuple) -> int:
        a, b = socket.socketpair()
        ours = Connection(a.detach())
        p = subprocess.Popen([sys.executable, "-c", _CHILD, str(b.fileno()),
                              json.dumps(sys.path)], pass_fds=(b.fileno(),),
                             stdin=subprocess.DEVNULL, env=worker_env())
        b.close()  # the child's end only: its death then reads as end-of-file here
        wid = self._next_id
        self._next_id += 1
        self.workers[wid] = w = _Worker(p, ours, init)
        self._send(w, "init", (self.worker_cls, init))
        return wid

    def setup(self, method: str, *args: Any) -> list[Any]:
        """Call ``method(*args)`` on every worker and wait for all of them; returns their
        results in worker order. A worker's error is raised here (with its traceback as
        the cause), a worker that dies in it raises :class:`WorkerDied`. The call is
        replayed on every later replacement before its first task.

        Arrays of at least :data:`SPILL_BYTES` anywhere in ``args`` (the pose table: 2.2
        kB a pose, 0.45 GB for 200k poses) are written once to a temporary folder and
        reach every worker as a read-only memory map of that file: one copy in the page
        cache shared by all workers, as Ray's object store does, instead of one pickled
        copy sent to and held by each. The folder (in the system's temporary directory,
        ``TMPDIR``) is removed by :meth:`close`; one left by a caller that was killed is
        removed by the next pool's set-up."""
        if self._spill_dir is None:
            _remove_stale_spills()
            self._spill_dir = tempfile.mkdtemp(prefix=f"{_SPILL_PREFIX}{os.getpid()}-")
        self._setup = (method, spill_dumps(args, Path(self._spill_dir)))
        for w in self.workers.values():
            self._send(w, "setup", self._setup)
        return [self._take(wid) for wid in list(self.workers)]

    def map(self, method: str, *args: Any) -> list[Any]:
        """Call ``method(*args)`` on every worker and wait for all of them (not replayed
        on replacements); results in worker order, errors raised as by :meth:`setup`."""
        for w in self.workers.values():
            self._send(w, "call", (method, args))
        return [self._take(wid) for wid in list(self.workers)]

    def _take(self, wid: int) -> Any:
        w = self.workers[wid]
        kind, value = self._recv(wid)
        if kind == "died":
            raise WorkerDied(f"worker {wid} (pid {w.process.pid}) died during set-up "
                             f"(exit code {value})")
        if kind == "error":
            raise _with_remote(value)
        return value

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
        """Start a new worker (same constructor arguments) in place of the dead one
        ``wid`` and return its id at once.

        Its construction and set-up go on while the caller collects the other workers'
        results: a call submitted to it runs after its set-up, and if it dies or fails
        setting up, :meth:`wait` answers that call with ``died`` or ``error``."""
        old = self.workers.pop(wid)
        _end(old.process, 1.0)
        _close(old)
        new = self._spawn(old.init)
        if self._setup is not None:
            w = self.workers[new]
            w.loading = True
            # from a thread: the set-up inputs are larger than the socket's buffer, so
            # sending them blocks until the new worker is constructed and reads them
            w.writer = threading.Thread(target=_write, args=(w.conn, ("setup", self._setup)),
                                        name=f"vhgen-setup-{new}", daemon=True)
            w.writer.start()
        return new

    # -- tasks -----------------------------------------------------------------------
    def submit(self, wid: int, task: Any, method: str, *args: Any) -> None:
        """Call ``method(*args)`` on worker ``wid``; ``task`` is returned by wait()."""
        w = self.workers[wid]
        w.busy = task
        if w.loading:
            w.deferred = (method, args)  # sent by wait() once the set-up has succeeded
        else:
            self._send(w, "call", (method, args))

    def wait(self, timeout: float | None = None) -> list[tuple[int, Any, str, Any]]:
        """Block until at least one busy worker answers or dies, or ``timeout`` seconds
        pass (then: an empty list). Returns ``(worker id, task, kind, value)`` with kind
        ``ok`` (value: the result), ``died`` (value: the exit code) or ``error`` (value:
        the exception, its ``__cause__`` the worker's traceback).

        A busy replacement answers its set-up first: a set-up that succeeded is not
        reported (the task's call is sent then, its reply comes later); one that died
        or raised answers the task with ``died`` or ``error``, as :meth:`setup` would
        have raised it."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            busy = {wid: w for wid, w in self.workers.items() if w.busy is not None}
            if not busy:
                return []
            # a dead worker's socket reads as end-of-file: readable, like a reply. A
            # replacement has one request in flight at a time (its call is sent only
            # after its set-up's reply), so each readable socket holds the answer to that
            handles = {w.conn: wid for wid, w in busy.items()}
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready = {handles[h] for h in wait(list(handles), left)}  # type: ignore[index]
            out = []
            for wid in sorted(ready):
                w = self.workers[wid]
                kind, value = self._recv(wid)
                if w.loading:
                    w.loading = False
                    if kind == "ok":  # set up: now the task
                        self._send(w, "call", w.deferred or ("run", ()))
                        w.deferred = None
                        continue
                    w.deferred = None
                task, w.busy = w.busy, None
                out.append((wid, task, kind,
                            _with_remote(value) if kind == "error" else value))
            # a set-up that succeeded is no answer: wait on, for what time is left
            if out or (not ready and deadline is not None and time.monotonic() >= deadline):
                return out

    # -- pipe ------------------------------------------------------------------------
    def _send(self, w: _Worker, op: str, payload: tuple) -> None:
        if w.writer is not None:
            # the set-up goes first: sent by now (only called once the worker replied or
            # for a worker that is not loading)
            w.writer.join()
        _write(w.conn, (op, payload))

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


class _Spiller(pickle.Pickler):
    """Pickles with every large array written to its own .npy file in ``folder`` (the
    pickle holds the path)."""

    def __init__(self, f: io.BytesIO, folder: Path):
        super().__init__(f, protocol=pickle.HIGHEST_PROTOCOL)
        self.folder = folder
        self.count = itertools.count()

    def persistent_id(self, obj: Any) -> Any:
        if not isinstance(obj, np.ndarray) or obj.nbytes < SPILL_BYTES or obj.dtype.hasobject:
            return None
        path = self.folder / f"array-{next(self.count)}.npy"
        np.save(path, obj, allow_pickle=False)
        return str(path)


class _Mapper(pickle.Unpickler):
    """The inverse of :class:`_Spiller`: each spilled array a read-only memory map."""

    def persistent_load(self, pid: Any) -> Any:
        return np.load(pid, mmap_mode="r")


def spill_dumps(obj: Any, folder: Path) -> bytes:
    """``obj`` pickled, with every array of at least :data:`SPILL_BYTES` (anywhere in
    it: dataclass fields, dicts, lists) written to ``folder`` instead."""
    f = io.BytesIO()
    _Spiller(f, folder).dump(obj)
    return f.getvalue()


def _mapped_loads(data: bytes) -> Any:
    """The inverse of :func:`spill_dumps` in a worker: spilled arrays memory-mapped."""
    return _Mapper(io.BytesIO(data)).load()


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
