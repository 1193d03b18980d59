"""Planes in depth points (float64, pure NumPy): the sensor's depth-noise model that
scales every distance to a plane, planes through point triples, and the RANSAC finder of
a scene's dominant plane.

Both plane searches of vhgen draw their hypotheses and scale their residuals here: the
floor of a real background (:func:`vhgen.scene.background.floor.estimate_floor`, which
scores hypotheses by its own floor rules: level, under the camera, nothing below it) and
the background planes of the segmentation stage (:class:`vhgen.forest.segment.Segmenter`,
through :func:`ransac_plane`).

Points are camera-frame (N, 3) float64 metres, z the depth along the optical axis.
"""

from __future__ import annotations

import numpy as np

# The depth noise of the real sensor on the shared OpenNI frames (docs/realism.md, "Real
# frames and realism"): axial noise of 1.44 mm and quantisation steps of 2.9 mm per m^2
# of depth, both growing as z^2. Callers scale them (a sigma, a tolerance of a few
# sigma and a step) through :func:`depth_noise`.
AXIAL_NOISE_PER_M2 = 0.00144
QUANT_STEP_PER_M2 = 0.0029


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


def ransac_plane(p: np.ndarray, rng: np.random.Generator, iterations: int,
                 tol_at_1m: float, tol_max: float, sample_size: int = 4000
                 ) -> tuple[np.ndarray, tuple[np.ndarray, float]]:
    """Inliers (bool over ``p`` (N, 3) float64 camera-frame points) of the plane with the
    most of them, and the plane (unit normal, offset: ``p @ normal = offset``):
    ``iterations`` planes through 3 random points, scored together on a random sample of
    ``sample_size`` points (distance below :func:`depth_noise` with ``tol_at_1m`` per
    m^2 from 0.3 m on, at most ``tol_max``), the best refitted by least squares on its
    inliers among all points. Draws from ``rng`` only: the same seed, the same plane."""
    n = len(p)

    def tolerance(q: np.ndarray) -> np.ndarray:
        return depth_noise(q[:, 2], tol_at_1m, near_m=0.3, most_m=tol_max)

    tol = tolerance(p)
    sample = p if n <= sample_size else p[rng.choice(n, sample_size, replace=False)]
    s_tol = tolerance(sample)
    tri = sample[rng.integers(0, len(sample), size=(iterations, 3))]
    normals, ok = planes_through(tri[:, 0], tri[:, 1], tri[:, 2])  # collinear: no plane
    if not ok.any():
        return np.zeros(n, bool), (np.array([0.0, 0.0, 1.0]), 0.0)
    normals = normals[ok]
    offsets = np.einsum("ij,ij->i", normals, tri[ok, 0])
    counts = (np.abs(sample @ normals.T - offsets) < s_tol[:, None]).sum(0)
    k = int(np.argmax(counts))
    normal, offset = normals[k], float(offsets[k])
    inl = np.abs(p @ normal - offset) < tol
    if inl.sum() >= 3:  # least-squares refit on the inliers (float64 SVD)
        q = p[inl]
        centre = q.mean(0)
        normal = np.linalg.svd((q - centre)[:: max(1, len(q) // 20000)],
                               full_matrices=False)[2][-1]
        offset = float(centre @ normal)
        inl = np.abs(p @ normal - offset) < tol
    return inl, (normal, offset)
