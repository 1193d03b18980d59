"""People segmentation around the forest: large planes removed, the rest clustered in
2.5D, a cluster kept as a person when the forest calls most of it a body part.

Depth people pipelines (PCL's ground-based people detection, its gpu/people organized
plane detector) do not label every pixel of a room: they remove the floor and the walls,
cluster what stands on the floor, and look at the clusters. This stage does the same
around a body-part forest, for one depth frame (H, W) uint16 mm and its intrinsics:

1. **planes** (float64): up to :attr:`Segmenter.max_planes` dominant planes found by
   RANSAC on the back-projected points, each holding at least :attr:`min_plane_fraction`
   of the remaining valid pixels, inliers within a distance that grows with depth as the
   sensor's noise and quantisation do (``plane_tol_m`` at 1 m, times z^2, at most
   ``plane_tol_max_m``: a person's front is rounder than that); they are floors, walls,
   tables' tops, and are background;
2. **clusters**: 4-connected components of the other valid pixels, two neighbours joined
   when their depths differ by less than ``jump_m`` at 1 m (times z, a step the sensor
   sees as a discontinuity);
3. **vote**: a cluster is a person when it has at least ``min_pixels`` pixels, its 3D
   extent is person-like (at most ``max_extent_m`` along its longest axis, at least
   ``min_extent_m``), and the forest gives at least ``min_body_fraction`` of its pixels a
   body part (optionally also: ``min_coherence``, the share of neighbouring body pixels
   with the same part, and ``min_parts`` parts present; both off by default: on build
   data they told people from other clusters no better than the body share);
4. **labels**: pixels outside person clusters become background (0); inside, a pixel the
   forest left as background takes the part of the nearest pixel it labelled.

The result is a pure function of the depth, the intrinsics, the forest's labels and the
seed of the RANSAC draws.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vhgen.camera import Intrinsics, backproject


@dataclass(frozen=True)
class Segmenter:
    """Settings of the segmentation stage (see the module docstring)."""

    max_planes: int = 4
    min_plane_fraction: float = 0.08
    # at 1 m, grows as z^2: about 3 sigma of the axial noise plus a quantisation step of the
    # real sensor (1.4 and 2.9 mm/m^2, docs/realism.md "Real frames and realism")
    plane_tol_m: float = 0.007
    plane_tol_max_m: float = 0.05
    ransac_iterations: int = 200
    jump_m: float = 0.05  # at 1 m; grows as z
    min_pixels: int = 300
    min_extent_m: float = 0.2
    max_extent_m: float = 2.4
    # chosen on build data, never on real check frames (`python
    # benchmarks/segment_threshold.py FOREST --frames 100`: 100 synthetic frames of
    # people_room/people_real the forest did not train on; the recommended forest's
    # settings, 1120 frames, background_share 0.5): the largest fraction keeping at least
    # 95% of the person clusters' pixels. 0.5 keeps 95.8% and passes 3.0% of the other
    # clusters' pixels (0.8: 85.2% and 0.5%). A forest trained with background_share 0
    # calls more of everything a body part: for it 0.8 kept 97.5% and passed 6.8%.
    min_body_fraction: float = 0.5
    min_coherence: float = 0.0
    min_parts: int = 0
    seed: int = 0

    def planes(self, points: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """(H, W) bool: pixels on the dominant planes (step 1)."""
        rng = np.random.default_rng(self.seed)
        on_plane = np.zeros(valid.shape, bool)
        left = valid.copy()
        n_valid = int(valid.sum())
        for _ in range(self.max_planes):
            idx = np.flatnonzero(left)
            if len(idx) < max(3, self.min_plane_fraction * n_valid):
                break
            p = points.reshape(-1, 3)[idx]
            inliers = _ransac_plane(p, rng, self.ransac_iterations, self.plane_tol_m,
                                    self.plane_tol_max_m)
            if inliers.sum() < self.min_plane_fraction * n_valid:
                break
            on_plane.reshape(-1)[idx[inliers]] = True
            left.reshape(-1)[idx[inliers]] = False
        return on_plane

    def clusters(self, depth_m: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, int]:
        """Components of the ``keep`` pixels, 4-neighbours joined across depth steps
        below ``jump_m * z`` (step 2): (H, W) int32 ids (0 = none) and their number."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        z = depth_m
        tol = self.jump_m * np.maximum(z, 1e-6)
        right = keep[:, :-1] & keep[:, 1:] & (np.abs(z[:, 1:] - z[:, :-1]) < tol[:, :-1])
        down = keep[:-1] & keep[1:] & (np.abs(z[1:] - z[:-1]) < tol[:-1])
        h, w = keep.shape
        nodes = np.flatnonzero(keep.reshape(-1))
        index = np.full(h * w, -1, np.int64)
        index[nodes] = np.arange(len(nodes))
        ids = index.reshape(h, w)
        a = np.concatenate([ids[:, :-1][right], ids[:-1][down]])
        b = np.concatenate([ids[:, 1:][right], ids[1:][down]])
        graph = coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(len(nodes),) * 2)
        n, comp = connected_components(graph, directed=False)
        out = np.zeros(h * w, np.int32)
        out[nodes] = comp + 1
        return out.reshape(h, w), int(n)

    def cluster_table(self, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray
                      ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Steps 1-2 and what step 3 decides on: the cluster image (H, W) int32 (0 = no
        cluster) and, per cluster id (index 0 unused), ``pixels``, ``body`` (the share the
        forest calls a body part), ``coherence`` (the share of neighbouring pairs of body
        pixels, right and below, that have the same part: whole parts, not confetti),
        ``parts`` (parts with at least 5% of its body pixels) and ``extent_m``."""
        depth = np.asarray(depth_mm)
        labels = np.asarray(labels)
        valid = depth > 0
        z = depth.astype(np.float64) / 1000.0
        points = backproject(intr, z)
        keep = valid & ~self.planes(points, valid)
        comp, n = self.clusters(z, keep)
        flat = comp.reshape(-1)
        body = (labels > 0) & keep
        size = np.bincount(flat, minlength=n + 1).astype(np.float64)
        called = np.bincount(flat, weights=body.reshape(-1), minlength=n + 1)
        pairs = np.zeros(n + 1)
        same = np.zeros(n + 1)
        for a, b, ca in ((labels[:, :-1], labels[:, 1:], comp[:, :-1]),
                         (labels[:-1], labels[1:], comp[:-1])):
            both = (a > 0) & (b > 0) & (ca > 0)
            pairs += np.bincount(ca[both], minlength=n + 1)
            same += np.bincount(ca[both & (a == b)], minlength=n + 1)
        parts = np.zeros(n + 1, np.int64)
        extent = np.zeros(n + 1)
        big = np.flatnonzero((size >= self.min_pixels) & (np.arange(n + 1) > 0))
        for c in big:
            m = comp == c
            counts = np.bincount(labels[m & body])
            if counts.sum():
                parts[c] = int((counts[1:] >= 0.05 * counts.sum()).sum())
            extent[c] = _longest_extent(points[m])
        table = {"pixels": size, "body": called / np.maximum(size, 1),
                 "coherence": same / np.maximum(pairs, 1), "parts": parts,
                 "extent_m": extent}
        return comp, table

    def is_person(self, table: dict[str, np.ndarray]) -> np.ndarray:
        """Step 3 over a :meth:`cluster_table`: (n + 1,) bool, index 0 False."""
        ok = ((table["pixels"] >= self.min_pixels) & (table["body"] >= self.min_body_fraction)
              & (table["extent_m"] >= self.min_extent_m)
              & (table["extent_m"] <= self.max_extent_m)
              & (table["coherence"] >= self.min_coherence)
              & (table["parts"] >= self.min_parts))
        ok[0] = False
        return ok

    def apply(self, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray
              ) -> np.ndarray:
        """The forest's ``labels`` (H, W) uint8 of the frame ``depth_mm`` after the stage."""
        from scipy import ndimage

        labels = np.asarray(labels)
        comp, table = self.cluster_table(depth_mm, intr, labels)
        mask = self.is_person(table)[comp]
        out = np.where(mask, labels, 0).astype(np.uint8)
        holes = mask & (out == 0)
        if holes.any() and (out > 0).any():
            # the nearest labelled pixel of each hole (in the image) gives its part
            _, (iy, ix) = ndimage.distance_transform_edt(out == 0, return_indices=True)
            out[holes] = out[iy[holes], ix[holes]]
        return out


def _ransac_plane(p: np.ndarray, rng: np.random.Generator, iterations: int,
                  tol_at_1m: float, tol_max: float, sample_size: int = 4000) -> np.ndarray:
    """Inliers (bool over ``p`` (N, 3) float64 camera-frame points) of the plane with the
    most of them: ``iterations`` planes through 3 random points, scored together on a
    random sample of ``sample_size`` points (distance below ``tol_at_1m * z^2``, at most
    ``tol_max``), the best refitted by least squares on its inliers among all points."""
    n = len(p)

    def tolerance(q: np.ndarray) -> np.ndarray:
        return np.minimum(tol_at_1m * np.maximum(q[:, 2], 0.3) ** 2, tol_max)

    tol = tolerance(p)
    sample = p if n <= sample_size else p[rng.choice(n, sample_size, replace=False)]
    s_tol = tolerance(sample)
    tri = sample[rng.integers(0, len(sample), size=(iterations, 3))]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9  # collinear draws give no plane
    if not ok.any():
        return np.zeros(n, bool)
    normals = normals[ok] / norms[ok, None]
    offsets = np.einsum("ij,ij->i", normals, tri[ok, 0])
    counts = (np.abs(sample @ normals.T - offsets) < s_tol[:, None]).sum(0)
    k = int(np.argmax(counts))
    inl = np.abs(p @ normals[k] - offsets[k]) < tol
    if inl.sum() >= 3:  # least-squares refit on the inliers (float64 SVD)
        q = p[inl]
        centre = q.mean(0)
        normal = np.linalg.svd((q - centre)[:: max(1, len(q) // 20000)],
                               full_matrices=False)[2][-1]
        inl = np.abs((p - centre) @ normal) < tol
    return inl


def _longest_extent(p: np.ndarray) -> float:
    """The spread (m) of points (N, 3) along their principal axis (5th-95th percentile,
    so a few stray pixels do not count)."""
    if len(p) < 3:
        return 0.0
    q = p - p.mean(0)
    axis = np.linalg.svd(q[:: max(1, len(q) // 5000)], full_matrices=False)[2][0]
    t = q @ axis
    lo, hi = np.percentile(t, [5, 95])
    return float(hi - lo)
