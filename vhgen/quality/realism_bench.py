"""`vhgen bench realism`: the realism statistics of real depth frames beside those of
vhgen stores, with one distance per statistic (see :mod:`vhgen.realism.compare`).

Real frames come through :mod:`vhgen.depthfile` (PCD, PNG; a bad file is one line and is
skipped); store frames through :mod:`vhgen.store`. Writes ``realism.json``,
``table.txt`` and ``realism.png`` into the output folder.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.errors import StoreError
from vhgen.realism.collect import real_stats
from vhgen.realism.compare import compare, table
from vhgen.realism.stats import FrameStats, frame_stats


def _say(msg: str) -> None:
    logging.getLogger("vhgen.quality").warning(msg)


def store_stats(store: str | Path, max_frames: int | None = None
                ) -> tuple[list[FrameStats], dict[str, Any]]:
    """Statistics of a vhgen store's frames (the first ``max_frames``, or every frame) and
    the store's sensor description (name, intrinsics)."""
    from vhgen.store import open_store
    from vhgen.store.zarr_store import read_attrs

    try:
        root = open_store(store)
        attrs = read_attrs(store)
        depth = root["depth"]
    except (OSError, KeyError, ValueError) as e:
        raise StoreError(f"{store}: not a readable vhgen store ({e})") from None
    sensor = attrs.get("sensor") or {}
    fx = float((sensor.get("intrinsics") or {}).get("fx", 0)) or None
    if fx is None:
        raise StoreError(f"{store}: the store's sensor attribute has no intrinsics")
    n = depth.shape[0] if max_frames is None else min(max_frames, depth.shape[0])
    return [frame_stats(np.asarray(depth[i]), fx) for i in range(n)], sensor


def bench_realism(real: Sequence[str], stores: Sequence[str], out: str | Path, *,
                  max_frames: int | None = None, fx: float | None = None,
                  warn: Callable[[str], None] = _say) -> dict[str, Any]:
    """Compare the real frames with every store; write realism.json, table.txt and
    realism.png into ``out``; return the results (with the text table under ``table``).
    StoreError when no real frame could be read."""
    got = real_stats(real, fx=fx, warn=warn)
    rs, used, real_fx = got.stats, got.files, got.fx
    if not rs:
        raise StoreError(f"no readable real depth frame in {', '.join(map(str, real))}")
    results: dict[str, Any] = {}
    sets: dict[str, list[FrameStats]] = {"real": rs}
    sensors: dict[str, Any] = {}
    for s in stores:
        ss, sensor = store_stats(s, max_frames)
        name = Path(s).name
        if name in results:
            name = str(s)
        sfx = (sensor.get("intrinsics") or {}).get("fx")
        if real_fx is not None and sfx is not None and abs(float(sfx) - real_fx) > 0.5:
            warn(f"{s}: sensor fx = {float(sfx):g} px, the real frames have "
                 f"{real_fx:g} px: pixel widths are not comparable (use a preset with the "
                 "real camera's focal length, e.g. openni_525)")
        results[name] = compare(rs, ss)
        sets[name] = ss
        sensors[name] = {"store": str(s), "sensor": sensor.get("name"), "frames": len(ss)}
    text = table(f"real ({len(rs)})", results)
    outp = Path(out)
    outp.mkdir(parents=True, exist_ok=True)
    from vhgen.realism.plots import plot_realism

    plot_realism(outp / "realism.png", sets)
    (outp / "table.txt").write_text(text + "\n")
    doc = {"real": {"files": used, "fx": real_fx}, "stores": sensors, "results": results}
    (outp / "realism.json").write_text(json.dumps(doc, indent=1, default=float))
    return {**doc, "table": text}
