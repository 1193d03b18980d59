"""A person beside a person: would calling a candidate that touches a called person a
person at lower odds (hysteresis) find more of a line of people, and at what cost?

    python studies/beside_a_person.py FOREST.npz STORE [STORE ...] [--frames 320]
        [--vote 1,0.7] [--level-tops] [--p-star P | --prior-frames 320]

For a forest with a person stage (``forest person-stage``): a candidate the stage gives
less than its even odds but at least ``p*`` is called a person when it touches (4-neighbours
in the image) a candidate the stage calls a person whose median depth is within 0.5 m of
its own (``--level-tops``: and whose top, ``top_m``, is within 0.3 m of its own). ``p*``
is ``--p-star``, or measured on the stage's own training stores (the forest file names
them; ``--prior-frames`` of the frames the stage drew, seeded as it drew them): p* =
1 / (1 + r), r the odds of a person among candidates touching a person (by the truth) at
that depth over the odds among all candidates. Prints, per store and vote factor (the
people's candidates' ``body`` times the factor: ``0.7`` is a real person's weaker vote),
found, pixel precision overall / alone / at 1-2 m, frames over 3% of their background
called, false people a frame and every one of 4-6 found, without and with the rule
(docs/forest_log.md, "A person beside a person"). Nothing is chosen here.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

DEPTH_M = 0.5  # a body's depth: people side by side stand within it
TOP_M = 0.3  # adults' heads stand 1.5-1.9 m above the floor


def beside(x: np.ndarray, pairs: np.ndarray, called: np.ndarray, level: bool) -> np.ndarray:
    """(n + 1,) bool: candidates that touch a ``called`` one within DEPTH_M (and TOP_M)."""
    from vhgen.forest.segment import FEATURES

    d, t = FEATURES.index("depth_m"), FEATURES.index("top_m")
    u, v = pairs[:, 0], pairs[:, 1]
    near = called[v] & (np.abs(x[u, d] - x[v, d]) < DEPTH_M)
    if level:
        near &= np.abs(x[u, t] - x[v, t]) < TOP_M
    out = np.zeros(len(x), bool)
    out[u[near]] = True
    out[0] = False
    return out


def frames_of(store: str, n: int):
    from vhgen.forest.data import store_info
    from vhgen.store.zarr_store import open_store, read_frames

    info = store_info(store)
    idx = np.arange(min(n, info.num_frames), dtype=np.int64)
    got = read_frames(open_store(store), ("depth", "instances"), idx, info.frames_per_shard)
    return info, got["depth"], got["instances"]


def measure_p_star(forest, level: bool, frames: int) -> float:
    from vhgen.forest.data import store_info
    from vhgen.forest.from_stores import person_stage_frames, read_frames
    from vhgen.forest.persons import neighbour_pairs
    from vhgen.forest.segment import Segmenter
    from vhgen.forest.trees import predictors_at_focal

    meta = forest.meta["person_stage"]
    chosen = person_stage_frames(forest, meta["stores"], meta["frames"], meta["seed"])
    pick = np.random.default_rng(0).choice(len(chosen), min(frames, len(chosen)), replace=False)
    chosen = [chosen[i] for i in sorted(pick.tolist())]
    at = predictors_at_focal(forest)
    infos = {p: store_info(p) for p in {t[0] for t in chosen}}
    seg = Segmenter()
    n_all = n_all_p = n_near = n_near_p = 0
    for s in range(0, len(chosen), 16):
        part = chosen[s:s + 16]
        depth, truth = read_frames(part)
        for i, (path, _, _) in enumerate(part):
            info = infos[path]
            labels = at(info.fx, info.fy).predict(depth[i])
            cand = seg.candidates(depth[i], info.intrinsics, labels)
            x = seg.describe(cand, depth[i], info.intrinsics, labels)
            size = np.bincount(cand.comp.ravel(), minlength=len(x))
            person = np.bincount(cand.comp.ravel(), weights=(truth[i] > 0).ravel(),
                                 minlength=len(x)) >= 0.5 * size
            big = ~np.isnan(x).any(1)
            near = beside(x, neighbour_pairs(cand.comp), person & big, level) & big
            n_all += int(big.sum())
            n_all_p += int((person & big).sum())
            n_near += int(near.sum())
            n_near_p += int((person & near).sum())
    q0, q = n_all_p / n_all, n_near_p / max(n_near, 1)
    r = (q / (1 - q)) / (q0 / (1 - q0)) if q < 1 else np.inf
    print(f"prior: {n_all_p} people of {n_all} candidates; {n_near_p} of the {n_near} "
          f"touching a person: r {r:.1f}, p* {1 / (1 + r):.4f}")
    return float(1 / (1 + r))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("forest")
    ap.add_argument("stores", nargs="+")
    ap.add_argument("--frames", type=int, default=320)
    ap.add_argument("--vote", default="1,0.7")
    ap.add_argument("--level-tops", action="store_true")
    ap.add_argument("--p-star", type=float)
    ap.add_argument("--prior-frames", type=int, default=320)
    a = ap.parse_args()

    from vhgen.forest.persons import PeopleScore, frame_people, neighbour_pairs
    from vhgen.forest.segment import FEATURES, Segmenter
    from vhgen.forest.trees import Forest, predictors_at_focal

    forest = Forest.load(a.forest)
    stage = forest.person_stage
    if stage is None:
        sys.exit(f"{a.forest}: no person stage (train one with `vhgen forest person-stage`)")
    p_star = a.p_star if a.p_star is not None else measure_p_star(forest, a.level_tops,
                                                                  a.prior_frames)
    seg = Segmenter()
    body = FEATURES.index("body")
    at = predictors_at_focal(forest)
    for store in a.stores:
        info, depth, inst = frames_of(store, a.frames)
        labels = at(info.fx, info.fy).predict(depth)
        rows = []
        for i in range(len(depth)):
            cand = seg.candidates(depth[i], info.intrinsics, labels[i])
            x = seg.describe(cand, depth[i], info.intrinsics, labels[i],
                             part_heights=stage.part_heights)
            size = np.bincount(cand.comp.ravel(), minlength=len(x))
            person = np.bincount(cand.comp.ravel(), weights=(inst[i] > 0).ravel(),
                                 minlength=len(x)) >= 0.5 * size
            rows.append((cand.comp, x, person, neighbour_pairs(cand.comp)))
        for factor in (float(v) for v in a.vote.split(",")):
            for rule in (False, True):
                score = PeopleScore()
                for i, (comp, x, person, pairs) in enumerate(rows):
                    xv = x.copy()
                    xv[person, body] *= factor
                    p = stage.predict_proba(xv)
                    ok = seg.stage_calls(x, p)
                    if rule:  # below the stage's odds, as wide as it asks
                        ok |= beside(x, pairs, ok, a.level_tops) & seg.stage_calls(
                            x, np.where(p >= p_star, 1.0, 0.0))
                    ids = np.where(ok[comp], comp, 0).astype(np.int32)
                    score.add(frame_people(ids, depth[i], inst[i]), (store, i))
                res = score.result()
                o = res["overall"]
                g = {r["bin"]: r for r in res["by_group"]}
                d = {r["bin"]: r for r in res["by_distance"]}

                def f(v: float | None) -> str:
                    return "-" if v is None else f"{v:.4f}"
                print(f"{Path(store).name} vote x{factor:g} {'beside' if rule else 'stage '}: "
                      f"found {o['found']}/{o['people']} precision {f(o['precision'])} "
                      f"alone {f(g['1']['precision'])} 1-2 m {f(d['1-2']['precision'])} "
                      f"bg>3% {o['background_over']} false/frame {f(o['false_per_frame'])} "
                      f"every one of 4-6 {f(g['4-6']['everyone_found'])}", flush=True)


if __name__ == "__main__":
    main()
