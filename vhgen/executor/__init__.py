"""Where work runs: worker objects in this process (:class:`InlinePool`), in child
processes of this machine (:class:`~vhgen.executor.local.LocalPool`) or on Ray actors
(:class:`~vhgen.executor.raypool.RayPool`), behind one interface: ``start`` constructs
one worker per tuple of arguments, ``setup`` hands all of them the same inputs (replayed
on a replacement), ``map`` calls all of them, ``submit``/``wait`` run one call at a time
per worker, ``replace`` stands in a new worker for a dead one. The frame job
(:mod:`vhgen.pipeline.driver`) and forest training (:mod:`vhgen.forest.training`) both
distribute through it. Nothing here knows what the workers do.
"""

from __future__ import annotations

from typing import Any


class InlinePool:
    """Workers in this process (no parallelism of its own: a worker may use threads).
    Has ``start``/``setup``/``map``/``close``; nothing can die here, so no ``replace``."""

    def __init__(self, worker_cls: type):
        self.worker_cls = worker_cls
        self.workers: dict[int, Any] = {}

    @classmethod
    def holding(cls, workers: list[Any]) -> InlinePool:
        """A pool of workers already built (of any class)."""
        pool = cls(object)
        pool.workers = dict(enumerate(workers))
        return pool

    def start(self, inits: list[tuple]) -> list[int]:
        first = len(self.workers)
        for k, init in enumerate(inits):
            self.workers[first + k] = self.worker_cls(*init)
        return list(range(first, first + len(inits)))

    def setup(self, method: str, *args: Any) -> list[Any]:
        return self.map(method, *args)

    def map(self, method: str, *args: Any) -> list[Any]:
        return [getattr(w, method)(*args) for w in self.workers.values()]

    def release(self) -> None:
        self.workers.clear()

    def close(self) -> None:
        self.release()
