"""Which pool runs a job's workers: the one rule for frames and forests."""

from __future__ import annotations

from vhgen.errors import VhgenError

EXECUTORS = ("auto", "local", "ray")


def choose_executor(requested: str, address: str | None, *, gpus_per_worker: float = 0,
                    error: type[VhgenError] = VhgenError) -> str:
    """``local`` (worker processes of this machine) or ``ray``.

    ``auto``: Ray when there is a cluster to join (``--address`` or ``RAY_ADDRESS``) or
    GPU workers are asked for (Ray assigns each its GPU); otherwise the local pool, which
    starts in a fraction of the time a local Ray needs. Contradictions are ``error``s,
    one line naming the flag.
    """
    if requested not in EXECUTORS:
        raise error(f"--executor: {requested!r} is not one of {', '.join(EXECUTORS)}")
    if requested == "local":
        if address:
            raise error(f"--executor local runs on this machine; it cannot use the Ray "
                        f"cluster at {address} (drop --address / RAY_ADDRESS, or use "
                        "--executor ray)")
        if gpus_per_worker > 0:
            raise error("--executor local does not assign GPUs to workers; "
                        "render.gpus_per_worker needs --executor ray (or auto)")
        return "local"
    if requested == "ray":
        return "ray"
    return "ray" if address or gpus_per_worker > 0 else "local"
