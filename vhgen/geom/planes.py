"""Planes in depth points (float64, pure NumPy): the sensor's depth-noise model that
scales every distance to a plane, planes through point triples, and the one RANSAC plane
finder, :func:`find_plane`.

Both plane searches of vhgen run :func:`find_plane` with their own hypotheses, score,
refit and acceptance: the floor of a real background
(:func:`vhgen.scene.background.floor.estimate_floor`: hypotheses through up-facing points
that are level and under the camera, MSAC cost of the points facing along a plane with
points under it penalised, Tukey-weighted refits of the best distinct ones, accepted by
its floor rules) and the background planes of the segmentation stage
(:class:`vhgen.forest.segment.Segmenter`: plain :func:`triples`, the most inliers, a
least-squares refit). Both scale distances by :func:`depth_noise`.

Points are camera-frame (N, 3) float64 metres, z the depth along the optical axis; a
plane is a unit normal and an offset, ``p @ normal = offset``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np

# The depth noise of the real sensor on the shared OpenNI frames (docs/realism.md, "Real
# frames and realism"): axial noise of 1.44 mm and quantisation steps of 2.9 mm per m^2
# of depth, both growing as z^2. Callers scale them (a sigma, a tolerance of a few
# sigma and a step) through :func:`depth_noise`.
AXIAL_NOISE_PER_M2 = 0.00144
QUANT_STEP_PER_M2 = 0.0029
# a hypothesis within 1 deg and 2 cm of one refitted already refits to the same plane
SAME_COS = math.cos(math.radians(1.0))
SAME_M = 0.02


def depth_noise(z: np.ndarray, per_m2: float, base_m: float = 0.0, near_m: float = 0.0,
                most_m: float = np.inf) -> np.ndarray:
    """The depth-dependent scale of a distance to a plane, (N,) float64 metres:
    ``base_m + per_m2 * max(z, near_m)^2``, at most ``most_m``, for depths ``z`` (N,) m.

    The one noise model of plane finding: the sensor's noise and quantisation grow as
    z^2 (:data:`AXIAL_NOISE_PER_M2`, :data:`QUANT_STEP_PER_M2`); ``base_m`` is what does
    not shrink near the camera, ``near_m`` the depth below which it stops shrinking,
    ``most_m`` a cap (a person's front is rounder than a far plane's noise)."""
    return np.minimum(base_m + per_m2 * np.maximum(z, near_m) ** 2, most_m)


def planes_through(a: np.ndarray, b: np.ndarray, c: np.ndarray, min_norm: float = 1e-9
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (K, 3) of the planes through point triples ``a``, ``b``, ``c`` (K, 3)
    each (``(b - a) x (c - a)``, normalised), and ``ok`` (K,) bool: the triple spans a
    plane (the cross product longer than ``min_norm``); where not, the normal is the
    unnormalised cross product (to be dropped by ``ok``)."""
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > min_norm
    return n / np.where(ok, norm, 1.0)[:, None], ok


def plane_basis(normal: np.ndarray) -> np.ndarray:
    """(2, 3): two orthonormal axes of the plane with unit ``normal`` (the first one
    along the camera's x where it can be)."""
    x = np.array([1.0, 0.0, 0.0])
    if abs(normal @ x) > 0.9:
        x = np.array([0.0, 0.0, 1.0])
    e1 = x - (x @ normal) * normal
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(normal, e1)])


def spread(q: np.ndarray) -> np.ndarray:
    """5th-95th percentile range of points ``q`` (k, 2) along each of their principal
    axes (m)."""
    c = q - q.mean(0)
    axes = np.linalg.svd(c[:: max(1, len(c) // 5000)], full_matrices=False)[2]
    t = c @ axes.T
    lo, hi = np.percentile(t, [5, 95], axis=0)
    return hi - lo


class Hypotheses(NamedTuple):
    """Candidate planes (unit normals (K, 3) float64, offsets (K,)) and ``sample``, the
    indices of the points they are ranked on (None: all of them)."""

    normal: np.ndarray
    offset: np.ndarray
    sample: np.ndarray | None


def triples(p: np.ndarray, rng: np.random.Generator, count: int, sample_size: int = 4000
            ) -> Hypotheses:
    """Plain RANSAC hypotheses of points ``p`` (N, 3): a random sample of ``sample_size``
    of them (all when there are no more), then ``count`` planes through 3 random points of
    the sample (collinear triples dropped), to be ranked on that sample. Draws from
    ``rng`` only: the same seed, the same planes."""
    sample = None if len(p) <= sample_size else rng.choice(len(p), sample_size, replace=False)
    pts = p if sample is None else p[sample]
    tri = pts[rng.integers(0, len(pts), size=(count, 3))]
    normals, ok = planes_through(tri[:, 0], tri[:, 1], tri[:, 2])
    normals = normals[ok]
    return Hypotheses(normals, np.einsum("ij,ij->i", normals, tri[ok, 0]), sample)


def on_plane(p: np.ndarray, scale: np.ndarray, normal: np.ndarray, offset: float,
             cut: float = 1.0, facing: np.ndarray | None = None, facing_deg: float = 90.0
             ) -> np.ndarray:
    """(N,) bool: the points ``p`` (N, 3) on the plane: their distance to it within
    ``cut`` times their ``scale`` (N,) (:func:`depth_noise`) and, with ``facing`` (N, 3)
    local surface normals, their surface within ``facing_deg`` of the plane's normal."""
    on = np.abs((p @ normal - offset) / scale) < cut
    if facing is not None:
        on &= np.abs(facing @ normal) >= math.cos(math.radians(facing_deg))
    return on


def find_plane(p: np.ndarray, scale: np.ndarray, hypotheses: Hypotheses, *,
               cut: float = 1.0, facing: np.ndarray | None = None, facing_deg: float = 90.0,
               score: Literal["count", "msac"] = "count", below_penalty: float = 0.0,
               refit: Literal["lsq", "tukey"] = "lsq", up: np.ndarray | None = None,
               tries: int = 1, accept: Callable[[np.ndarray, float], bool] | None = None
               ) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The best plane among ``hypotheses`` of points ``p`` (N, 3) float64, refitted on all
    of them: (unit normal (3,), offset, :func:`on_plane` (N,) bool), or None when there
    are no hypotheses or ``accept`` takes none.

    A point's residual is its distance to a plane over its ``scale`` (N,) (the sensor's
    noise, :func:`depth_noise`); it is on the plane within ``cut`` when its surface faces
    along it (with ``facing``: local normals (N, 3), within ``facing_deg``). The
    hypotheses are ranked on their sample by ``score``: ``count``, the most points on the
    plane; ``msac``, the least sum of squared residuals truncated at ``cut`` (a point off
    the plane or not facing along it costs ``cut^2``; one more than ``cut`` below it,
    against the normal, costs ``below_penalty`` outliers more). The best ``tries`` distinct
    ones (not within 1 deg and 2 cm of one tried already) are refitted on all the points,
    by ``refit``: ``lsq``, least squares on the points on the plane; ``tukey``,
    Tukey-weighted least squares of the points facing along it, iterated to convergence
    (a refitted normal turned to face ``up`` when given); a refitted plane that
    ``accept`` (normal, offset) refuses is dropped, and of several the one that ``score``
    ranks best on all the points wins. Pure: the draws are the hypotheses' (as in
    :func:`triples`)."""
    normals, offsets, sample = hypotheses
    if not len(offsets):
        return None
    cos_facing = math.cos(math.radians(facing_deg))
    sp, ss, sf = p, scale, facing
    if sample is not None:
        sp, ss, sf = p[sample], scale[sample], None if facing is None else facing[sample]
    # MSAC 64 hypotheses at a time (five (n, K) float temporaries; a floor ranks ~1000)
    blocks = 1 if score == "count" else -(-len(offsets) // 64)
    cost = np.concatenate([_cost(sp, ss, sf, n, o, cut, cos_facing, score, below_penalty)
                           for n, o in zip(np.array_split(normals, blocks),
                                           np.array_split(offsets, blocks), strict=True)])
    tried: list[tuple[np.ndarray, float]] = []
    fits: list[tuple[np.ndarray, float]] = []
    for k in np.argsort(cost, kind="stable"):
        if len(tried) == tries:
            break
        if any(float(normals[k] @ m) > SAME_COS and abs(offsets[k] - g) < SAME_M
               for m, g in tried):
            continue
        tried.append((normals[k], float(offsets[k])))
        fit = (_tukey if refit == "tukey" else _least_squares)(
            p, scale, facing, normals[k], float(offsets[k]), cut, facing_deg, up)
        if accept is None or accept(*fit):
            fits.append(fit)
    if not fits:
        return None
    normal, offset = fits[0]
    if len(fits) > 1:  # the least cost on all the points (the first of equal ones)
        normal, offset = min(fits, key=lambda f: float(_cost(
            p, scale, facing, f[0][None], np.array([f[1]]), cut, cos_facing, score,
            below_penalty)[0]))
    return normal, offset, on_plane(p, scale, normal, offset, cut, facing, facing_deg)


def _cost(p: np.ndarray, scale: np.ndarray, facing: np.ndarray | None, n: np.ndarray,
          d: np.ndarray, cut: float, cos_facing: float, score: str, below_penalty: float
          ) -> np.ndarray:
    """(K,) cost of planes ``n`` (K, 3), ``d`` (K,) on points ``p`` (see
    :func:`find_plane`), the lower the better: ``count``, minus the points on a plane;
    ``msac``, truncated squared residuals."""
    r = (p @ n.T - d) / scale[:, None]
    faces = True if facing is None else np.abs(facing @ n.T) >= cos_facing
    if score == "count":
        return -((np.abs(r) < cut) & faces).sum(0)
    return (np.where(faces, np.minimum(r * r, cut * cut), cut * cut)
            + np.where(r < -cut, cut * cut * below_penalty, 0.0)).sum(0)


def _least_squares(p: np.ndarray, scale: np.ndarray, facing: np.ndarray | None,
                   n: np.ndarray, d: float, cut: float, facing_deg: float,
                   up: np.ndarray | None) -> tuple[np.ndarray, float]:
    """Least squares (float64 SVD) of the plane on the points on the plane ``n``, ``d``
    (:func:`on_plane`; itself when fewer than 3)."""
    on = on_plane(p, scale, n, d, cut, facing, facing_deg)
    if on.sum() < 3:
        return n, d
    q = p[on]
    centre = q.mean(0)
    n = np.linalg.svd((q - centre)[:: max(1, len(q) // 20000)], full_matrices=False)[2][-1]
    n = -n if up is not None and n @ up < 0 else n
    return n, float(centre @ n)


def _tukey(p: np.ndarray, scale: np.ndarray, facing: np.ndarray | None, n: np.ndarray,
           d: float, cut: float, facing_deg: float, up: np.ndarray | None
           ) -> tuple[np.ndarray, float]:
    """Tukey-weighted least squares of the plane on the points facing along it, iterated
    to convergence from the plane ``n``, ``d``."""
    cos_facing = math.cos(math.radians(facing_deg))
    # only points near the hypothesis can ever weigh (the plane moves little)
    near = np.abs(p @ n - d) < 3 * cut * scale
    p, scale = p[near], scale[near]
    facing = None if facing is None else facing[near]
    for _ in range(30):
        u = (p @ n - d) / scale / cut
        weigh = np.abs(u) < 1
        if facing is not None:
            weigh &= np.abs(facing @ n) >= cos_facing
        w = np.where(weigh, (1 - u * u) ** 2, 0.0) / scale ** 2
        if w.sum() <= 0:
            break
        c = (p * w[:, None]).sum(0) / w.sum()
        m = ((p - c) * w[:, None]).T @ (p - c)
        n2 = np.linalg.eigh(m)[1][:, 0]
        n2 = -n2 if up is not None and n2 @ up < 0 else n2
        d2 = float(n2 @ c)
        done = np.abs(n2 - n).max() < 1e-8 and abs(d2 - d) < 1e-8
        n, d = n2, d2
        if done:
            break
    return n, d
