"""Where frame workers run (local processes or Ray actors), what each Ray actor asks
for and which GL context it opens (CPU or GPU worker).

Kept apart from the driver so the choice is a small pure function the driver calls:
``render: {gpus_per_worker: g}`` in the scene config makes every actor request ``g`` GPUs
from Ray (a fraction shares a GPU between actors) and open the EGL device of the GPU Ray
gave it; 0 (the default) renders wherever EGL/OSMesa points, llvmpipe on CPUs.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from vhgen.errors import VhgenError
from vhgen.executor.choice import EXECUTORS as EXECUTORS
from vhgen.executor.choice import choose_executor as choose
from vhgen.job_config import JobConfig


def actor_options(cfg: JobConfig, local_resources: Mapping[str, float] | None = None
                  ) -> dict[str, Any]:
    """Ray resource options of one frame actor: ``num_cpus`` and, for GPU workers,
    ``num_gpus``.

    local_resources : ``ray.cluster_resources()`` when the driver started Ray itself on this
        machine; then a GPU request the machine cannot meet is an error at once instead of
        actors waiting forever (an existing cluster may still be scaling up: not checked).
    """
    opts: dict[str, Any] = {"num_cpus": 1}
    g = cfg.gpus_per_worker
    if g > 0:
        opts["num_gpus"] = g
        have = float((local_resources or {}).get("GPU", 0.0))
        if local_resources is not None and have < g:
            raise VhgenError(f"render.gpus_per_worker is {g} but this machine's Ray sees "
                             f"{have:g} GPUs; set it to 0 to render on the CPU, or pass "
                             "--address of a cluster with GPU workers")
    return opts


def worker_context(cfg: JobConfig, cuda_visible_devices: str | None) -> Any:
    """The GL context a frame actor renders with, or None for the default one.

    For GPU workers (``gpus_per_worker > 0``): the EGL device matching
    ``cuda_visible_devices`` (the actor's CUDA_VISIBLE_DEVICES, as Ray set it), refusing
    software renderers (see :func:`vhgen.render.context.create_gpu_context`).
    """
    if cfg.gpus_per_worker <= 0:
        return None
    from vhgen.render.context import create_gpu_context

    return create_gpu_context(cuda_visible_devices)




def choose_executor(requested: str, address: str | None, cfg: JobConfig) -> str:
    """The frame job's executor (:func:`vhgen.executor.choice.choose_executor`, with the
    config's GPUs per worker)."""
    return choose(requested, address, gpus_per_worker=cfg.gpus_per_worker)
