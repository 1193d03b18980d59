"""Which people the segmentation stage misses: found share by pose height and by view.

    python studies/people_found_by.py EVAL.json [EVAL.json ...] [--store STORE]

Reads the per-person rows of ``forest eval STORE --segment --json EVAL.json`` (store,
frame, instance, distance, found) and the store's manifest (``people``: each person's
``joints_cam`` and ``visible_fraction``; ``world_to_camera``), and prints, per JSON, the
share of people found

* by **height**: the highest joint above the floor (world y, the floor at 0), under 1 m
  (crouching, bending, sitting on the floor), 1-1.3 m, 1.3 m or more;
* by **view**: the share of the person's width in view from the camera at placement
  (``visible_fraction``: the floor-plan test of the scene's ``min_visible_fraction``),
  under 0.5, 0.5-0.7, 0.7-0.9, 0.9 or more; for every person and for those beyond 4.5 m.

``--store`` reads another copy of the store than the JSON names. Nothing is chosen here;
it says where the misses are (docs/forest_log.md, "People beyond 4.5 m").
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

HEIGHT_BINS = ((0.0, 1.0, "<1 m"), (1.0, 1.3, "1-1.3 m"), (1.3, np.inf, ">=1.3 m"))
VIEW_BINS = ((0.0, 0.5, "<0.5"), (0.5, 0.7, "0.5-0.7"), (0.7, 0.9, "0.7-0.9"),
             (0.9, np.inf, ">=0.9"))
FAR_M = 4.5


def person_facts(store: str) -> dict[tuple[int, int], tuple[float, float]]:
    """(frame, instance) -> (highest joint above the floor m, visible fraction)."""
    import pyarrow.parquet as pq

    path = Path(store) / "manifest.parquet"
    if not path.is_file():
        raise SystemExit(f"{store}: no manifest.parquet (a store of vhgen generate)")
    rows = pq.read_table(path, columns=["frame", "world_to_camera", "people"]).to_pylist()
    out = {}
    for row in rows:
        c2w = np.linalg.inv(np.asarray(row["world_to_camera"], np.float64).reshape(4, 4))
        for p in row["people"] or []:
            joints = np.asarray(p["joints_cam"], np.float64).reshape(-1, 3)
            world = joints @ c2w[:3, :3].T + c2w[:3, 3]
            view = p.get("visible_fraction")
            out[(int(row["frame"]), int(p["instance"]))] = (
                float(world[:, 1].max()), np.nan if view is None else float(view))
    return out


def shares(found: np.ndarray, values: np.ndarray, bins: tuple) -> str:
    cells = []
    for lo, hi, name in bins:
        m = (values >= lo) & (values < hi)
        n = int(m.sum())
        cells.append(f"{name}: {found[m].mean():.3f} ({int(found[m].sum())}/{n})" if n
                     else f"{name}: - (0)")
    return "  ".join(cells)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("evals", nargs="+", help="forest eval --json outputs")
    ap.add_argument("--store", help="the test store (default: the one each JSON names)")
    args = ap.parse_args()
    facts: dict[str, dict] = {}
    for name in args.evals:
        res = json.loads(Path(name).read_text())["people"]
        cols = res["instance_columns"]
        rows = res["instances"]
        if not rows:
            print(f"{name}: no per-person rows")
            continue
        at = {c: cols.index(c) for c in ("store", "frame", "instance", "distance_m", "found")}
        store = args.store or rows[0][at["store"]]
        if store not in facts:
            facts[store] = person_facts(store)
        known = [r for r in rows if (r[at["frame"]], r[at["instance"]]) in facts[store]]
        if len(known) < len(rows):
            print(f"{name}: {len(rows) - len(known)} people not in {store}'s manifest, left out")
        top = np.array([facts[store][(r[at["frame"]], r[at["instance"]])][0] for r in known])
        view = np.array([facts[store][(r[at["frame"]], r[at["instance"]])][1] for r in known])
        found = np.array([bool(r[at["found"]]) for r in known])
        far = np.array([r[at["distance_m"]] >= FAR_M for r in known])
        print(f"{name}: {found.sum()} of {len(found)} people found")
        print(f"  height  {shares(found, top, HEIGHT_BINS)}")
        print(f"  view    {shares(found, view, VIEW_BINS)}")
        print(f"  view, beyond {FAR_M:g} m  {shares(found[far], view[far], VIEW_BINS)}")


if __name__ == "__main__":
    main()
