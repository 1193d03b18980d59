"""Ray actors behind the interface of :class:`~vhgen.executor.local.LocalPool` (the one
module of vhgen that starts or joins Ray; :mod:`vhgen.dataset` uses Ray Data).

Actors are not restarted by Ray: the caller replaces a dead actor itself (``replace``)
and resubmits what it was running, so a restart never depends on constructor arguments
Ray kept. Large set-up inputs go into the object store once and reach every actor
zero-copy.
"""

from __future__ import annotations

import logging
import os
from typing import Any

from vhgen.errors import VhgenError

log = logging.getLogger(__name__)


def _ray_env(local: bool) -> None:
    """Environment for Ray, set before it starts (the workers of a local Ray inherit it),
    and Ray's notices that do not concern a vhgen user hidden (shown with --verbose)."""
    if local:
        # a new local Ray turns token authentication on and warns about it unless the
        # mode is set: keep it on, explicitly, which is what silences the warning
        os.environ.setdefault("RAY_AUTH_MODE", "token")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if not logging.getLogger("vhgen").isEnabledFor(logging.DEBUG):
        # joining a cluster with a token in ~/.ray warns the same way (Ray's own module
        # logger: only its warnings about the authentication mode are hidden)
        logging.getLogger("ray._private.authentication.authentication_token_setup").setLevel(
            logging.ERROR)


def _ray_init(num_cpus: int, address: str | None) -> bool:
    """Join the cluster at ``address`` or start a local Ray of ``num_cpus``; False when
    Ray was already initialised (then it is not ours to stop)."""
    import ray

    if ray.is_initialized():
        return False
    level = logging.INFO if logging.getLogger("vhgen").isEnabledFor(logging.DEBUG) \
        else logging.ERROR
    if address:
        ray.init(address=address, logging_level=level)
    else:
        ray.init(num_cpus=num_cpus, include_dashboard=False, logging_level=level,
                 log_to_driver=True)
    return True


def _shutdown_local_ray(ray: Any) -> None:
    """ray.shutdown() of the Ray this process started, without its 1 s stall.

    Ray stops its processes one by one, each given up to 1 s to exit after SIGTERM; the
    autoscaler monitor of a local head always uses the whole second (measured: 1.01 s of
    a 1.25 s shutdown). It holds no state of ours, so it is killed first. Ray's private
    node handle is used defensively: if it changes, this is a plain ray.shutdown().
    """
    try:
        node = ray._private.worker._global_node
        for info in node.all_processes.get("monitor", []):
            info.process.kill()
    except (AttributeError, KeyError, OSError):
        pass
    ray.shutdown()


class RayPool:
    """Workers of class ``worker_cls`` as Ray actors (see :meth:`connect`)."""

    def __init__(self, ray: Any, started: bool, worker_cls: type, options: dict[str, Any]):
        self.ray = ray
        self.started = started  # this process started the (local) Ray
        self.actor_cls = ray.remote(**options, max_restarts=0,
                                    max_task_retries=0)(worker_cls)
        self.workers: dict[int, Any] = {}
        self.pending: dict[Any, tuple[int, Any]] = {}
        self._inits: dict[int, tuple] = {}
        self._next_id = 0
        self._setup: tuple | None = None

    @classmethod
    def connect(cls, worker_cls: type, *, address: str | None, local_cpus: int,
                options: Any = None) -> RayPool:
        """Join the cluster at ``address`` (or start a local Ray of ``local_cpus``) and
        make the pool. ``options``: the actor's Ray options (``num_cpus``, ``num_gpus``),
        or a function of the local Ray's ``cluster_resources()`` (None when joining a
        cluster) returning them, so a request the machine cannot meet fails at once."""
        _ray_env(local=not address)
        import ray

        started = _ray_init(local_cpus, address)
        try:
            opts = options(ray.cluster_resources() if started else None) \
                if callable(options) else dict(options or {"num_cpus": 1})
            return cls(ray, started, worker_cls, opts)
        except BaseException:
            if started:
                _shutdown_local_ray(ray)
            raise

    def start(self, inits: list[tuple]) -> list[int]:
        """One actor per tuple of constructor arguments; returns their ids at once."""
        return [self._new(tuple(init)) for init in inits]

    def _new(self, init: tuple) -> int:
        wid = self._next_id
        self._next_id += 1
        self.workers[wid] = self.actor_cls.remote(*init)
        self._inits[wid] = init
        return wid

    def setup(self, method: str, *args: Any) -> list[Any]:
        """``method(*args)`` on every actor (the inputs in the object store once, each
        a top-level reference that reaches the actor as a zero-copy value); replayed on
        replacements. A worker's VhgenError is raised as itself."""
        refs = [self.ray.put(a) for a in args]
        self._setup = (method, refs)
        return self._all(method, refs)

    def map(self, method: str, *args: Any) -> list[Any]:
        """``method(*args)`` on every actor (large arrays put once), results in order."""
        import numpy as np

        refs = [self.ray.put(a) if isinstance(a, np.ndarray) and a.nbytes > 4096 else a
                for a in args]
        return self._all(method, refs)

    def _all(self, method: str, args: list[Any]) -> list[Any]:
        ray = self.ray
        try:
            return ray.get([getattr(a, method).remote(*args) for a in self.workers.values()])
        except ray.exceptions.RayTaskError as e:
            if isinstance(getattr(e, "cause", None), VhgenError):
                raise e.cause from None
            raise

    def stop(self, wids: list[int]) -> None:
        for wid in wids:
            self.ray.kill(self.workers.pop(wid))

    def release(self) -> None:
        """Let the actors go (the work is done); Ray itself is stopped by close()."""
        for a in self.workers.values():
            self.ray.kill(a)
        self.workers.clear()

    def close(self) -> None:
        self.release()
        if self.started:
            self.started = False
            _shutdown_local_ray(self.ray)

    def replace(self, wid: int) -> int:
        """A new actor in place of the dead one ``wid``, its set-up queued; returns at
        once (a call submitted to it fails as ``died`` if it dies setting up)."""
        self.workers.pop(wid, None)
        new = self._new(self._inits.pop(wid))
        if self._setup is not None:  # queued before any call on the same actor
            method, refs = self._setup
            getattr(self.workers[new], method).remote(*refs)
        return new

    def submit(self, wid: int, task: Any, method: str, *args: Any) -> None:
        self.pending[getattr(self.workers[wid], method).remote(*args)] = (wid, task)

    def wait(self, timeout: float | None = None) -> list[tuple[int, Any, str, Any]]:
        """As :meth:`LocalPool.wait <vhgen.executor.local.LocalPool.wait>`."""
        ray = self.ray
        if not self.pending:
            return []
        ready, _ = ray.wait(list(self.pending), num_returns=1, timeout=timeout)
        out = []
        for ref in ready:
            wid, task = self.pending.pop(ref)
            try:
                out.append((wid, task, "ok", ray.get(ref)))
            except ray.exceptions.RayActorError:
                # the process died (OOM kill, segfault, node loss)
                out.append((wid, task, "died", None))
            except ray.exceptions.RayTaskError as e:
                cause = getattr(e, "cause", None)
                # a user-facing cause is answered by the caller; anything else is a bug
                # whose Ray error keeps the worker's traceback
                out.append((wid, task, "error",
                            cause if isinstance(cause, (OSError, VhgenError)) else e))
        return out
