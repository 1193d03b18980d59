"""A frame worker with injected faults, for the fault tests (production never imports it).

:func:`run_faulty` runs a job whose workers are :class:`FaultyWorker`; the faults reach
the workers' processes (local children, or the actors of the local Ray the job starts)
through the environment variable :data:`ENV` (JSON), read when a worker is constructed:

- ``die_once``: shards; the worker process exits (as a killed one would) the first time
  one of them is attempted;
- ``write_error``: (errno, shards); writing those shards fails with that OSError;
- ``setup_error``: a message; the set-up fails with a RenderError;
- ``crash``: shards; a plain bug (RuntimeError) on those shards;
- ``gl_lost_once``: shards; the GL context fails (``moderngl.Error``) at the second frame
  (at the second batch where the worker sends frames in batches, the first one still in
  flight) the first time one of them is attempted, as a GPU reset or a lost device would.

With ``die_once``, faults of a replacement worker (one setting up after a ``die_once``
death): ``die_in_setup`` (n) kills the process in its set-up the first n times;
``replacement_setup_error`` (a message) makes its set-up fail with a RenderError;
``replacement_waits_for`` (paths) holds its set-up until these files exist.
"""

from __future__ import annotations

import json
import os
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from vhgen.errors import RenderError
from vhgen.job_config import JobConfig
from vhgen.pipeline.driver import RunSummary, run_job
from vhgen.pipeline.frames import ShardResult
from vhgen.pipeline.worker import FrameWorker

ENV = "VHGEN_TEST_FAULTS"


class FaultyWorker(FrameWorker):
    """:class:`FrameWorker` with the faults of :data:`ENV` injected."""

    def __init__(self, cfg: JobConfig):
        self.faults: dict[str, Any] = json.loads(os.environ.get(ENV, "{}"))
        if "setup_error" in self.faults:
            self.cfg = cfg
            self.gen = None
            self.setup_error = RenderError(self.faults["setup_error"])
            return
        super().__init__(cfg)

    def load(self, *args: Any, **kw: Any) -> str:
        if "markers" in self.faults and any(Path(self.faults["markers"]).glob("failed-*")):
            try:
                self._replacement_faults(Path(self.faults["markers"]))
            except RenderError as e:
                self.setup_error = e  # as FrameWorker.load keeps its own: run() raises it
                raise
        return super().load(*args, **kw)

    def _replacement_faults(self, folder: Path) -> None:
        f = self.faults
        if "replacement_setup_error" in f:
            raise RenderError(f["replacement_setup_error"])
        waits = [Path(p) for p in f.get("replacement_waits_for", ())]
        deadline = time.monotonic() + 30.0
        while not all(p.exists() for p in waits):
            if time.monotonic() > deadline:
                raise RenderError(f"waited 30 s in set-up for {[str(p) for p in waits]}")
            time.sleep(0.05)
        for k in range(f.get("die_in_setup", 0)):
            try:  # O_EXCL: two replacements loading at once never both take the same turn
                (folder / f"setup-died-{k}").open("x").close()
            except FileExistsError:
                continue
            os._exit(1)  # as a GL driver crash or an OOM kill in the set-up would

    def run(self, store: str, shard: int, start: int, stop: int) -> ShardResult:
        f = self.faults
        if shard in f.get("die_once", ()):
            # die as a killed process would, the first time this shard is attempted
            marker = Path(f["markers"]) / f"failed-{shard}"
            if not marker.exists():
                marker.touch()
                os._exit(1)
        if shard in f.get("gl_lost_once", ()) and self.gen is not None:
            marker = Path(f["markers"]) / f"gl-lost-{shard}"
            if not marker.exists():
                marker.touch()
                import moderngl

                # frames one by one: at the second frame; in batches (the GL sensor's
                # render.batch_frames): at the second batch, the first still in flight
                name = "_submit" if self.gen.batch > 0 else "render"
                real, calls = getattr(self.gen, name), []

                def failing_step(*args: Any) -> Any:
                    calls.append(args)
                    if len(calls) == 2:
                        raise moderngl.Error("GL_CONTEXT_LOST (injected)")
                    return real(*args)

                setattr(self.gen, name, failing_step)
        if shard in f.get("crash", ()):
            raise RuntimeError(f"injected bug on shard {shard}")
        if "write_error" in f and shard in f["write_error"][1]:
            import vhgen.pipeline.frames as frames

            code = f["write_error"][0]
            real = frames.write_shard

            def failing(path: str | Path, *args: Any, **kw: Any) -> None:
                raise OSError(code, os.strerror(code), str(Path(path) / "depth"))

            frames.write_shard = failing
            try:
                return super().run(store, shard, start, stop)
            finally:
                frames.write_shard = real
        return super().run(store, shard, start, stop)


@contextmanager
def faults_in_env(faults: dict[str, Any], markers: Path):
    """Set :data:`ENV` for the workers started inside (sets as lists, a marker folder)."""
    markers.mkdir(parents=True, exist_ok=True)
    spec = {k: sorted(v) if isinstance(v, (set, frozenset)) else v for k, v in faults.items()}
    if "write_error" in spec:
        spec["write_error"] = [spec["write_error"][0], sorted(spec["write_error"][1])]
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(ENV, json.dumps({**spec, "markers": str(markers)}))
        yield


def run_faulty(cfg: JobConfig, out: Path, faults: dict[str, Any], **kw: Any) -> RunSummary:
    """``run_job`` with :class:`FaultyWorker` s that inject ``faults``."""
    out = Path(out)
    with faults_in_env(faults, out.parent / f".{out.name}.faults"):
        return run_job(cfg, out, worker=FaultyWorker, **kw)
