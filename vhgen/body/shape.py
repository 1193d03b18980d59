"""MakeHuman macro modifiers: gender, age, muscle, weight, height, proportions, ethnic mix.

The MPFB2 assets carry MakeHuman's macro targets (``targets/macrodetails``): offsets of
every base-mesh vertex (joint cubes included, so the skeleton follows) at sample points
of the macro variables. A body is the base mesh plus a weighted sum of targets; a
target's weight is the product of its variables' weights, as in MakeHuman 1.1
(``apps/human.py``, age system "A8"):

* gender g: female = 1 - g, male = g;
* age a (0 = 1 year, 0.1875 = 11, 0.5 = 25, 1 = 90): below 0.5 baby = max(0, 1 - 5.333 a),
  young = max(0, 3.2 (a - 0.1875)), child = max(0, min(1, 5.333 a) - young); from 0.5
  old = 2a - 1, young = 1 - old;
* muscle, weight: min = max(0, 1 - 2v), max = max(0, 2v - 1), average = 1 - min - max;
* height: minheight = max(0, 1 - 2h), maxheight = max(0, 2h - 1) (average has no target);
* proportions: uncommon = max(0, 1 - 2p), ideal = max(0, 2p - 1) (regular has no target);
* ethnic mix (african, asian, caucasian) normalised to sum 1.

Targets: ``{race}-{gender}-{age}``, ``universal-{gender}-{age}-{muscle}-{weight}``,
``height/{gender}-{age}-{muscle}-{weight}-{min|max}height`` and
``proportions/{gender}-{age}-{muscle}-{weight}-{uncommon|ideal}proportions``. Sample
points the assets lack (no baby proportions) contribute nothing, as in MakeHuman.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import logging
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from vhgen.assets import MACRO_TARGETS, vhgen_home
from vhgen.errors import AssetError, ConfigError

log = logging.getLogger(__name__)

MIN_AGE, MID_AGE, MAX_AGE = 1.0, 25.0, 90.0
RACES = ("african", "asian", "caucasian")


@dataclass(frozen=True)
class Shape:
    """Macro modifier values, MakeHuman's ranges ([0, 1]; age via :func:`age_from_years`)."""

    gender: float = 0.5
    age: float = 0.5
    muscle: float = 0.5
    weight: float = 0.5
    height: float = 0.5
    proportions: float = 0.5
    african: float = 1 / 3
    asian: float = 1 / 3
    caucasian: float = 1 / 3

    def __post_init__(self):
        for k, v in asdict(self).items():
            if not (np.isfinite(v) and 0.0 <= v <= 1.0):
                raise ConfigError(None, f"shape.{k}", f"must be in [0, 1], got {v!r}")
        if self.african + self.asian + self.caucasian <= 0:
            raise ConfigError(None, "shape.african/asian/caucasian", "all zero")

    def to_dict(self) -> dict:
        """The values plus ``age_years`` (informative; :meth:`from_dict` ignores it)."""
        d = asdict(self)
        d["age_years"] = years_from_age(self.age)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Shape:
        """Rebuild from :meth:`to_dict` output, e.g. a manifest's ``avatar_params.shape``."""
        return cls(**{k: float(v) for k, v in d.items() if k != "age_years"})


def age_from_years(years: float) -> float:
    """MakeHuman's age value for an age in years (1..90)."""
    years = float(np.clip(years, MIN_AGE, MAX_AGE))
    if years < MID_AGE:
        return (years - MIN_AGE) / ((MID_AGE - MIN_AGE) * 2)
    return (years - MID_AGE) / ((MAX_AGE - MID_AGE) * 2) + 0.5


def years_from_age(age: float) -> float:
    if age < 0.5:
        return MIN_AGE + (MID_AGE - MIN_AGE) * 2 * age
    return MID_AGE + (MAX_AGE - MID_AGE) * 2 * (age - 0.5)


def _three(v: float, lo: str, mid: str, hi: str) -> dict[str, float]:
    mx = max(0.0, v * 2 - 1)
    mn = max(0.0, 1 - v * 2)
    return {lo: mn, mid: 1 - mn - mx, hi: mx}


def variable_weights(s: Shape) -> dict[str, dict[str, float]]:
    """Weight of every sample point of every macro variable."""
    a = s.age
    if a < 0.5:
        young = max(0.0, (a - 0.1875) * 3.2)
        age = {"baby": max(0.0, 1 - a * 5.333), "child": max(0.0, min(1.0, 5.333 * a) - young),
               "young": young, "old": 0.0}
    else:
        old = max(0.0, a * 2 - 1)
        age = {"baby": 0.0, "child": 0.0, "young": 1 - old, "old": old}
    total = s.african + s.asian + s.caucasian
    return {
        "gender": {"female": 1 - s.gender, "male": s.gender},
        "age": age,
        "muscle": _three(s.muscle, "minmuscle", "averagemuscle", "maxmuscle"),
        "weight": _three(s.weight, "minweight", "averageweight", "maxweight"),
        "height": {"minheight": max(0.0, 1 - 2 * s.height),
                   "maxheight": max(0.0, 2 * s.height - 1)},
        "proportions": {"uncommonproportions": max(0.0, 1 - 2 * s.proportions),
                        "idealproportions": max(0.0, 2 * s.proportions - 1)},
        "race": {r: getattr(s, r) / total for r in RACES},
    }


def target_weights(s: Shape) -> dict[str, float]:
    """Target name (relative to targets/macrodetails, no suffix) -> weight, weights > 0."""
    w = variable_weights(s)
    out: dict[str, float] = {}

    def add(name: str, value: float) -> None:
        if value > 0:
            out[name] = out.get(name, 0.0) + value

    for g, wg in w["gender"].items():
        for a, wa in w["age"].items():
            for r, wr in w["race"].items():
                add(f"{r}-{g}-{a}", wr * wg * wa)
            for m, wm in w["muscle"].items():
                for wt, ww in w["weight"].items():
                    base = wg * wa * wm * ww
                    add(f"universal-{g}-{a}-{m}-{wt}", base)
                    for h, wh in w["height"].items():
                        add(f"height/{g}-{a}-{m}-{wt}-{h}", base * wh)
                    for p, wp in w["proportions"].items():
                        add(f"proportions/{g}-{a}-{m}-{wt}-{p}", base * wp)
    return out


class MacroTargets:
    """All macro targets of an asset folder, parsed once into a memory-mapped cache.

    Cache: ``$VHGEN_HOME/cache/macrotargets-<hash>.{idx.npy,d.npy,json}`` (hash of the
    target files' names and sizes): every target's vertex indices (int32) and offsets
    (float32, as in the files) concatenated, and a JSON index name -> [start, stop,
    indices distinct]. Each file is written atomically, the index last, so concurrent
    workers never see a partial cache. Memory-mapped: workers share the pages, and a body
    reads only the targets its shape blends (re-reading an .npz member per body cost
    ~20 ms; holding them all in memory, 170 MB per worker).
    """

    def __init__(self, asset_dir: Path, cache_dir: Path | None = None):
        self.root = Path(asset_dir) / MACRO_TARGETS
        files = sorted(self.root.rglob("*.target.gz"))
        if not files:
            raise AssetError(f"no macro targets under {self.root}; run 'vhgen assets fetch'")
        h = hashlib.sha1()
        for f in files:
            h.update(f"{f.relative_to(self.root)}:{f.stat().st_size}".encode())
        cache_dir = Path(cache_dir) if cache_dir else vhgen_home() / "cache"
        self.cache = cache_dir / f"macrotargets-{h.hexdigest()[:16]}"
        index = self.cache.with_suffix(".json")
        if not index.is_file():
            self._build(files)
        self._index: dict[str, list] = json.loads(index.read_text())
        self._idx = np.load(self.cache.with_suffix(".idx.npy"), mmap_mode="r")
        self._d = np.load(self.cache.with_suffix(".d.npy"), mmap_mode="r")

    def _build(self, files: list[Path]) -> None:
        idx, d, index, n = [], [], {}, 0
        for f in files:
            name = str(f.relative_to(self.root))[: -len(".target.gz")]
            raw = gzip.decompress(f.read_bytes()).split()
            a = np.array(raw, dtype=np.float64).reshape(-1, 4) if raw else np.zeros((0, 4))
            i = a[:, 0].astype(np.int32)
            idx.append(i)
            d.append(a[:, 1:].astype(np.float32))
            index[name] = [n, n + len(a), bool(len(np.unique(i)) == len(i))]
            n += len(a)
        self.cache.parent.mkdir(parents=True, exist_ok=True)
        for suffix, arr in ((".idx.npy", np.concatenate(idx)), (".d.npy", np.concatenate(d))):
            tmp = self.cache.with_name(f"{self.cache.name}.{os.getpid()}.tmp{suffix}")
            np.save(tmp, arr)
            os.replace(tmp, self.cache.with_suffix(suffix))
        tmp = self.cache.with_name(f"{self.cache.name}.{os.getpid()}.tmp.json")
        tmp.write_text(json.dumps(index))
        os.replace(tmp, self.cache.with_suffix(".json"))
        self.cache.with_suffix(".npz").unlink(missing_ok=True)  # vhgen <= 0.x's format
        log.info("cached %d macro targets in %s.*", len(files), self.cache)

    def offsets(self, shape: Shape, num_vertices: int) -> np.ndarray:
        """(V, 3) float64 vertex offsets in OBJ units (decimetres) for ``shape``."""
        out = np.zeros((num_vertices, 3), dtype=np.float64)
        for name, w in target_weights(shape).items():
            entry = self._index.get(name)
            if entry is None:
                continue  # sample point absent from the assets (e.g. baby proportions)
            a, b, distinct = entry
            idx = self._idx[a:b]
            d = w * self._d[a:b].astype(np.float64)
            if distinct:  # a plain scatter-add is exact when no index repeats
                out[idx] += d
            else:
                np.add.at(out, idx, d)
        return out


@dataclass(frozen=True)
class ShapeSampler:
    """Seeded avatar shapes; every variable uniform in its range, ethnic mix Dirichlet.

    Ranges are MakeHuman values in [0, 1] except ``age_years``.
    """

    gender: tuple[float, float] = (0.0, 1.0)
    age_years: tuple[float, float] = (18.0, 70.0)
    muscle: tuple[float, float] = (0.2, 0.8)
    weight: tuple[float, float] = (0.2, 0.9)
    height: tuple[float, float] = (0.3, 0.7)  # MakeHuman spans 1.36-2.45 m (young male)
    proportions: tuple[float, float] = (0.3, 1.0)
    ethnic_concentration: float = 1.0  # Dirichlet alpha for (african, asian, caucasian)

    def sample(self, rng: np.random.Generator) -> Shape:
        race = rng.dirichlet([self.ethnic_concentration] * 3)
        return Shape(gender=float(rng.uniform(*self.gender)),
                     age=age_from_years(float(rng.uniform(*self.age_years))),
                     muscle=float(rng.uniform(*self.muscle)),
                     weight=float(rng.uniform(*self.weight)),
                     height=float(rng.uniform(*self.height)),
                     proportions=float(rng.uniform(*self.proportions)),
                     african=float(race[0]), asian=float(race[1]), caucasian=float(race[2]))
