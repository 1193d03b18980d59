"""Clutter items: a kind's item built from its parameters, and the job's variant library
(pure; the scene stream's generator).

:func:`sample_params` draws an item's sizes within its kind's ranges
(:mod:`vhgen.scene.clutter.kinds`), :func:`build` runs the kind's builder
(:mod:`vhgen.scene.clutter.builders`) on them into a :class:`ClutterShape` (the same mesh
every time: the manifest's parameters rebuild it), and :func:`variant` keeps the job's
shapes of each kind, built once per worker.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property, lru_cache
from types import MappingProxyType

import numpy as np

from vhgen.scene.clutter.kinds import clutter_kind, kind_index
from vhgen.scene.meshkit import Kit
from vhgen.scene.solids import rect


@dataclass(frozen=True, eq=False)
class ClutterShape:
    """A clutter item in its own frame (see :mod:`vhgen.scene.clutter.builders`): vertices
    (V, 3) float64, faces (T, 3) int64, per-face roles (T,) uint8 (meshkit BODY, OBJECT,
    WALL, FLOOR) and groups (T,) uint8; ``solids``: per group (polygon (P, 2) (x, z),
    y0, y1, inside); ``opening``: (x0, x1, y0, y1) of the hole a door cuts in its wall,
    or None; ``params``: what :func:`build` takes to rebuild it."""

    kind: str
    params: Mapping[str, float]
    vertices: np.ndarray
    faces: np.ndarray
    roles: np.ndarray
    groups: np.ndarray
    solids: tuple[tuple[np.ndarray, float, float, bool], ...]
    opening: tuple[float, float, float, float] | None = None

    @cached_property
    def inner_box(self) -> np.ndarray:
        """(2, 2) [[x min, z min], [x max, z max]] of its footprints inside the room."""
        p = np.concatenate([q for q, _, _, inside in self.solids if inside])
        return np.stack([p.min(0), p.max(0)])

    @property
    def x_extent(self) -> tuple[float, float]:
        """(lo, hi) x of its footprints inside the room (along the wall)."""
        return float(self.inner_box[0, 0]), float(self.inner_box[1, 0])

    @property
    def centre(self) -> np.ndarray:
        """(x, z) of the middle of its footprints inside the room."""
        return self.inner_box.mean(0)

    @cached_property
    def inner_heights(self) -> tuple[float, float]:
        """The lowest and highest point of its footprints inside the room."""
        return (min(y0 for _, y0, _, inside in self.solids if inside),
                max(y1 for _, _, y1, inside in self.solids if inside))

    @cached_property
    def top(self) -> float:
        return max(s[2] for s in self.solids)

    @cached_property
    def solid_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                   np.ndarray]:
        """Its footprints as arrays: corners (S, P, 2) (the first ``counts[j]`` of each,
        the rest zero), counts (S,) int64, y0 and y1 (S,) float64, inside (S,) bool."""
        size = max(len(q) for q, *_ in self.solids)
        corners = np.zeros((len(self.solids), size, 2))
        for j, (q, *_) in enumerate(self.solids):
            corners[j, :len(q)] = q
        out = (corners, np.array([len(q) for q, *_ in self.solids], np.int64),
               np.array([s[1] for s in self.solids], np.float64),
               np.array([s[2] for s in self.solids], np.float64),
               np.array([s[3] for s in self.solids], bool))
        for a in out:
            a.setflags(write=False)
        return out


def sample_params(kind: str, rng: np.random.Generator, fill: float) -> dict[str, float]:
    """The kind's top-level sizes, uniform in its record's ranges (one draw each, from the
    scene stream), the frame's ``fill`` (how full its surfaces are) and a ``seed`` for its
    details."""
    ranges = clutter_kind(kind).ranges
    u = rng.uniform(size=len(ranges))
    p = {k: float(lo + ui * (hi - lo)) for (k, (lo, hi)), ui in zip(ranges.items(), u,
                                                                     strict=True)}
    p["fill"] = float(fill)
    p["seed"] = int(rng.integers(2 ** 62))
    return p


def build(kind: str, params: Mapping[str, float]) -> ClutterShape:
    """The item of ``kind`` with ``params`` (as :func:`sample_params` draws them, or as
    the manifest records them): the same mesh every time."""
    rec = clutter_kind(kind)
    p = dict(params)
    kit = Kit()
    explicit = rec.builder(kit, p, np.random.default_rng(int(p["seed"]))) or []
    v, f, roles, groups = kit.build()
    if rec.centred:  # about the y axis: its box centred in x, its back on z = 0
        lo, hi = v.min(0), v.max(0)
        v = v - np.array([(lo[0] + hi[0]) / 2, 0.0, lo[2]])
    solids = []
    for gid in range(int(groups.max()) + 1 if len(groups) else 0):
        if gid < len(explicit):
            poly, y0, y1, inside = explicit[gid]
            solids.append((np.asarray(poly, np.float64), float(y0), float(y1), bool(inside)))
            continue
        idx = np.unique(f[groups == gid])
        if not len(idx):
            continue
        lo, hi = v[idx].min(0), v[idx].max(0)
        solids.append((rect(lo[0], hi[0], lo[2], hi[2]), float(lo[1]), float(hi[1]), True))
    opening = rec.opening(p) if rec.opening is not None else None
    for a in (v, f, roles, groups):
        a.setflags(write=False)
    return ClutterShape(kind, MappingProxyType(p), v, f, roles, groups, tuple(solids),
                        opening)


@lru_cache(maxsize=4096)
def variant(kind: str, fill: tuple[float, float], library_seed: int, index: int
            ) -> ClutterShape:
    """Variant ``index`` of ``kind`` in the job's library (``library_seed``): its
    parameters (sizes, ``fill`` drawn from its range, details) come from a generator of
    its own, so a worker builds each variant once and keeps it; the parameters rebuild it
    with :func:`build`. A frame draws which variants it shows."""
    rng = np.random.default_rng([library_seed, kind_index(kind), index])
    return build(kind, sample_params(kind, rng, float(rng.uniform(*fill))))


def smallest(kind: str) -> ClutterShape:
    """The kind at the low end of every range (its smallest size), for load-time checks."""
    p: dict[str, float] = {k: lo for k, (lo, _hi) in clutter_kind(kind).ranges.items()}
    p.update(fill=0.0, seed=0)
    return build(kind, p)
