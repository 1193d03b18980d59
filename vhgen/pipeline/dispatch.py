"""The dispatch loop: shards to workers, one in flight per worker, until all are written.

Works on any pool of :mod:`vhgen.executor` (local processes or Ray actors). A worker that
died is replaced and its shard redone whole (frames are deterministic and a shard is
rewritten whole, so a retry never duplicates or loses a frame); a write error stops the
dispatch, lets the shards in flight finish, and is raised as one line.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from pathlib import Path
from typing import Any

from vhgen.errors import StoreError, VhgenError
from vhgen.pipeline.frames import ShardResult
from vhgen.pipeline.plan import Task
from vhgen.pipeline.progress import Progress
from vhgen.store.manifest import ManifestMerger
from vhgen.store.output import os_error_line

log = logging.getLogger(__name__)

MAX_ATTEMPTS = 3  # retries of one shard after its worker died
POLL_SECONDS = 0.5  # the dispatch loop wakes at least this often (see _CtrlC)


class _CtrlC:
    """Ctrl-C during the dispatch, noticed within :data:`POLL_SECONDS` however it lands.

    Python runs signal handlers in the main thread only, between bytecodes: a SIGINT that
    the kernel hands to another thread (pyarrow's, zarr's) leaves the main thread asleep
    in its wait, and a KeyboardInterrupt raised inside a finaliser or callback is printed
    and dropped. The handler here also records the interrupt, and the dispatch loop,
    which wakes at least every :data:`POLL_SECONDS`, raises it again if it was lost.
    Installed only over Python's own handler, from the main thread (elsewhere, or when
    SIGINT is ignored or handled by the caller, a no-op)."""

    def __init__(self) -> None:
        self.hit = False
        self.previous: Any = None

    def __enter__(self) -> _CtrlC:
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            self.previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def _handler(self, signum: int, frame: Any) -> None:
        self.hit = True
        raise KeyboardInterrupt

    def check(self) -> None:
        if self.hit:
            raise KeyboardInterrupt

    def __exit__(self, *exc: object) -> None:
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)


def dispatch(pool: Any, todo: list[Task], out: Path, bar: Progress, merger: ManifestMerger
             ) -> tuple[list[ShardResult], dict[int, int], float | None]:
    """Run every task on the pool's workers (one in flight per worker), handing each
    finished shard's manifest part to ``merger``. A worker that died is replaced and its
    shard redone whole (the replacement sets up while the others go on; dying in its
    set-up counts as one more attempt on the shard). On a write failure, stop
    dispatching, let the tasks in flight finish, then raise one line. Returns the shards'
    results, the attempts per shard and when the first shard finished."""
    queue = list(todo)
    attempts = {t.shard: 0 for t in todo}
    results: list[ShardResult] = []
    idle = list(pool.workers)
    in_flight = 0
    first_frame: float | None = None
    error: VhgenError | None = None

    def fill() -> None:  # one task to every idle worker
        nonlocal in_flight
        while queue and idle and error is None:
            wid = idle.pop()
            task = queue.pop(0)
            attempts[task.shard] += 1
            pool.submit(wid, task, "run", str(out), task.shard, task.start, task.stop)
            in_flight += 1

    fill()
    with _CtrlC() as ctrl_c:
        while in_flight:
            finished = []
            done = pool.wait(timeout=POLL_SECONDS)
            ctrl_c.check()
            for wid, task, kind, value in done:
                in_flight -= 1
                if kind == "ok":
                    results.append(value)
                    idle.append(wid)
                    finished.append(task.shard)
                    bar.update(task.stop - task.start)
                    first_frame = first_frame or time.perf_counter()
                elif kind == "died":
                    # frames are deterministic: redoing the whole shard duplicates nothing
                    if attempts[task.shard] > MAX_ATTEMPTS:
                        error = error or VhgenError(
                            f"shard {task.shard} (frames {task.start}-{task.stop}): worker died "
                            f"{MAX_ATTEMPTS + 1} times; rerun with --resume")
                        continue
                    log.warning("worker died on shard %d (attempt %d), retrying on a new worker",
                                task.shard, attempts[task.shard])
                    queue.insert(0, task)
                    idle.append(pool.replace(wid))
                else:
                    idle.append(wid)
                    if isinstance(value, OSError):
                        err: VhgenError = StoreError(os_error_line(
                            value, out, f"cannot write shard {task.shard}"))
                    elif isinstance(value, VhgenError):
                        err = VhgenError(f"shard {task.shard}: {value}")
                    else:
                        raise value  # a bug: keep the worker's traceback
                    error = error or err
            fill()  # the workers first, then the driver's own reading
            for shard in finished:
                merger.add(shard)
    if error is not None:
        raise error
    return results, attempts, first_frame
