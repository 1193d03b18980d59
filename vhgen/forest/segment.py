"""People segmentation around the forest: large planes removed, the rest clustered in
2.5D and split at heads, a candidate kept as a person by a trained person stage (or when
the forest calls most of it a body part).

Depth people pipelines (PCL's ground-based people detection, its gpu/people organized
plane detector) do not label every pixel of a room: they remove the floor and the walls,
cluster what stands on the floor, and look at the clusters. This stage does the same
around a body-part forest, for one depth frame (H, W) uint16 mm and its intrinsics:

1. **planes** (float64): up to :attr:`Segmenter.max_planes` dominant planes found by
   RANSAC on the back-projected points, each holding at least :attr:`min_plane_fraction`
   of the remaining valid pixels, inliers within a distance that grows with depth as the
   sensor's noise and quantisation do (``plane_tol_m`` at 1 m, times z^2, at most
   ``plane_tol_max_m``: a person's front is rounder than that). A plane is background
   when its inliers reach at least ``min_patch_m`` along both of its axes (floors, walls,
   large table tops), unless most of its border is an occluding edge (what lies beyond
   it is farther by a depth step): people standing side by side at one distance put
   their coats' fronts on one plane too, but stand in front of the room, while a wall's
   or a floor's borders are corners and the nearer things in front of them; and unless
   the forest calls at least ``max_plane_body`` of its pixels a body part (a person's
   flat front, a coat or a torso with the arms raised, is a plane a metre across too,
   and the forest, trained to call walls and floors background, says whose it is). Of a
   background plane, a piece (8-connected) whose border steps back to something farther
   more often than forward to something nearer stays (``keep_fronts``): people side by
   side facing the camera put the middles of their chests on one plane wider than a
   metre, each piece a torso between the gaps beside it, with the people's own arms and
   legs around it, no occluding edge; a wall's or floor's pieces are bounded by the
   nearer things before them. The plane most nearly level below the camera is the
   **floor**;
2. **clusters**: 4-connected components of the other valid pixels, two neighbours joined
   when their depths differ by less than ``jump_m`` at 1 m (times z, a step the sensor
   sees as a discontinuity);
2b. **people in a cluster** (as ground-based people detectors do): the cluster's points
   on a height map over the floor (cells of ``cell_m``; without a floor, heights along
   the camera's up axis). Its heads are the local maxima at least ``min_head_m`` above
   the floor (without a floor: within ``head_band_m`` of the cluster's top) that stand out
   by ``min_prominence_m`` from the saddle towards every higher head (a hand held out on
   an arm does not), are ``min_head_width_m`` across within that depth of their top (a
   raised fist is narrower) and lie ``min_head_gap_m`` apart; a cluster with several heads is split
   between them, each point going to the nearest head on the floor (only clusters wider
   than ``min_split_width_m`` across: two people). Two people who touch are two
   candidates, not one too wide cluster;
3. **who is a person**: with a trained person stage (:mod:`vhgen.forest.person_stage`,
   stored in the forest's file), a candidate of at least ``min_pixels`` pixels is a
   person when the stage's trees, reading its :data:`FEATURES` (:meth:`Segmenter.features`:
   its size and shape in metres on the floor, and the forest's vote), give it at least
   ``min_person_prob`` and it is at least ``min_width_m`` wide. Without one, the
   **vote**: a candidate is a person when it has at least ``min_pixels`` pixels, its 3D
   extent is person-like (at most ``max_extent_m`` along its longest axis, at least
   ``min_extent_m``), and the forest gives at least ``min_body_fraction`` of its pixels
   a body part (optionally also: ``min_coherence``, the share of neighbouring body pixels
   with the same part, and ``min_parts`` parts present; both off by default: on build
   data they told people from other clusters no better than the body share);
4. **labels**: pixels outside person clusters become background (0); inside, a pixel the
   forest left as background takes the part of the nearest pixel it labelled;
   :meth:`Segmenter.instances` numbers the people kept (1, 2, ... left to right).

The geometric settings are a body's and the sensor's sizes (a head 0.2-0.3 m across,
shoulders 0.15-0.3 m below the top of the head, people at least 1 m tall standing, rooms'
walls and floors larger than 1 m), not values fitted to frames.

The result is a pure function of the depth, the intrinsics, the forest's labels and the
seed of the RANSAC draws.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vhgen.camera import Intrinsics, backproject
from vhgen.forest.person_stage import PersonStage
from vhgen.geom.normals import patch_normals, surface_shares
from vhgen.geom.planes import depth_noise as _depth_noise
from vhgen.geom.planes import find_plane as _find_plane
from vhgen.geom.planes import on_plane as _on_plane
from vhgen.geom.planes import plane_basis as _plane_basis
from vhgen.geom.planes import spread as _spread
from vhgen.geom.planes import triples as _triples

# where the forest's parts lie in the candidate (part_features): read by stages trained
# with them (forest person-stage --part-order), 0 for others; FEATURES' last columns
PART_FEATURES = ("part_order", "top_parts", "bottom_parts")
# what the candidate's surface normals say of its shape (vhgen.geom.normals.surface_shares):
# people are rounded, the things taken for them mostly flat pieces
SURFACE_FEATURES = ("smooth_share", "flat_share", "upright_share", "level_share")
# what the person stage (vhgen.forest.person_stage) sees of a candidate (Segmenter.features)
FEATURES = ("depth_m", "area_m2", "has_floor", "top_m", "bottom_m", "height_m",
            "width_m", "thickness_m", "head_width_m", "shoulder_width_m", "fill",
            "in_front", "at_image_edge", "body", "coherence", "parts", "behind",
            "column_height_m", "column_share", *SURFACE_FEATURES, *PART_FEATURES)
PART_COLUMNS = slice(len(FEATURES) - len(PART_FEATURES), None)
# the candidate's height (2nd to 98th percentile) in tenths, for where the forest's parts
# lie in it (Segmenter.part_histograms); its top fifth and lowest 30% for top_parts and
# bottom_parts
HEIGHT_BINS = 10
TOP_BINS = 8
BOTTOM_BINS = 3


@dataclass(frozen=True)
class Candidates:
    """A frame's person candidates (steps 1-2b): ``comp`` (H, W) int32 candidate ids (0 =
    none), ``count`` of them, the back-projected ``points`` (H, W, 3) float64 m, ``keep``
    (H, W) bool (valid and off the background planes) and the ``floor`` (unit normal up,
    offset; None when none was found)."""

    comp: np.ndarray
    count: int
    points: np.ndarray
    keep: np.ndarray
    floor: np.ndarray | None


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
    min_patch_m: float = 1.0
    keep_occluders: bool = True  # a plane standing in front of the room is not background
    # a plane the forest calls mostly a body part is a person's front, not background (the
    # majority; None: the forest has no say in step 1)
    max_plane_body: float | None = 0.5
    # the pieces of a background plane that stand in front of their surroundings are not
    # background (people side by side facing the camera: :meth:`_fronts`)
    keep_fronts: bool = True
    min_pixels: int = 300
    min_extent_m: float = 0.2
    max_extent_m: float = 2.4
    # a candidate's column: the candidates whose centres on the floor lie within this of
    # its own (PCL's HeadBasedSubclustering takes clusters 0.4 m apart on the floor for
    # one person's): a person cut in pieces by someone in front stands in one place
    column_m: float = 0.4
    # ``at_image_edge``: a candidate whose box comes within this of the box of the frame's
    # measured pixels is cut off by the frame (sensors leave a border unmeasured:
    # openni_525 measures rows 28-476 and columns 26-617 of 640 x 480, so the image's own
    # border is never reached); 2 px for the holes along an outline
    edge_px: int = 2
    split: bool = True  # step 2b; False: one candidate per cluster (the stage before)
    cell_m: float = 0.05
    min_head_m: float = 0.9
    head_band_m: float = 0.6
    min_prominence_m: float = 0.12
    min_head_gap_m: float = 0.3
    min_split_width_m: float = 0.7  # two people side by side at least; one is ~0.5
    min_head_width_m: float = 0.12  # a head 0.15-0.2 m across; a fist, a forearm ~0.08
    # chosen on build data, never on real check frames (`python
    # studies/segment_threshold.py FOREST --frames 100`: 100 synthetic frames of
    # people_room/people_real the forest did not train on; the recommended forest's
    # settings, 1120 frames, background_share 0.5): the largest fraction keeping at least
    # 95% of the person clusters' pixels. 0.5 keeps 95.8% and passes 3.0% of the other
    # clusters' pixels (0.8: 85.2% and 0.5%). A forest trained with background_share 0
    # calls more of everything a body part: for it 0.8 kept 97.5% and passed 6.8%.
    min_body_fraction: float = 0.5
    min_coherence: float = 0.0
    min_parts: int = 0
    # with a trained person stage (vhgen.forest.person_stage): its probability a candidate
    # is a person, classes weighted to equal total (not fitted: the even odds)
    min_person_prob: float = 0.5
    # and never a candidate narrower than any part of a body seen from any side (a forearm
    # ~0.08 m): curtain folds 0.02-0.03 m wide the forest calls a body part
    min_width_m: float = 0.05
    seed: int = 0

    def plane_tolerance(self, z: np.ndarray) -> np.ndarray:
        """(N,) float64 m: how far from a plane its inliers at depths ``z`` (N,) m lie,
        ``plane_tol_m`` times z^2 (z from 0.3 m on), at most ``plane_tol_max_m``."""
        return _depth_noise(z, self.plane_tol_m, near_m=0.3, most_m=self.plane_tol_max_m)

    def planes(self, points: np.ndarray, valid: np.ndarray,
               body: np.ndarray | None = None) -> np.ndarray:
        """(H, W) bool: pixels on the dominant planes' large patches (step 1)."""
        return self.find_planes(points, valid, body)[0]

    def find_planes(self, points: np.ndarray, valid: np.ndarray,
                    body: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Step 1: (H, W) bool of the background patches of the dominant planes, and the
        floor as (4,) float64 (unit normal pointing up, offset: height = p @ n - d), or
        None when no plane is level enough below the camera. ``body``: (H, W) bool, the
        pixels the forest calls a body part (None: the forest has no say)."""
        rng = np.random.default_rng(self.seed)
        on_plane = np.zeros(valid.shape, bool)
        left = valid.copy()
        n_valid = int(valid.sum())
        floor: np.ndarray | None = None
        best_level = np.cos(np.deg2rad(40.0))  # a floor seen by a camera pitched < 40 deg
        flat = points.reshape(-1, 3)
        for _ in range(self.max_planes):
            idx = np.flatnonzero(left)
            if len(idx) < max(3, self.min_plane_fraction * n_valid):
                break
            p = flat[idx]
            # the most inliers of plain RANSAC, refitted by least squares
            fit = _find_plane(p, self.plane_tolerance(p[:, 2]),
                              _triples(p, rng, self.ransac_iterations))
            if fit is None:
                break
            normal, offset, inliers = fit
            if inliers.sum() < self.min_plane_fraction * n_valid:
                break
            mask = np.zeros(valid.shape, bool)
            mask.reshape(-1)[idx[inliers]] = True
            left &= ~mask
            # background when its inliers spread along both in-plane axes (a floor, a
            # wall: even where quantisation at a distance cuts them into stripes)
            if _spread(p[inliers] @ _plane_basis(normal).T).min() < self.min_patch_m:
                continue
            if self.keep_occluders and _outline_share(mask, valid, points[..., 2],
                                                      self.jump_m, unmeasured=False) > 0.5:
                continue  # it stands in front of what surrounds it: people, not a wall
            if (body is not None and self.max_plane_body is not None
                    and body[mask].mean() >= self.max_plane_body):
                continue  # the forest calls it mostly a body part: a person's front
            # a background plane also takes its points that an earlier, kept plane held
            # (where a row of people's plane meets the floor)
            held = valid & ~on_plane & ~left & ~mask
            if held.any():
                q = points[held]
                more = np.zeros(valid.shape, bool)
                more[held] = _on_plane(q, self.plane_tolerance(q[:, 2]), normal, offset)
                mask |= more
            if self.keep_fronts:
                mask &= ~self._fronts(mask, valid, points[..., 2])
            on_plane |= mask
            # the floor: below the camera, its normal near the camera's up (-y)
            up = normal if normal[1] < 0 else -normal
            off = offset if normal[1] < 0 else -offset
            if -up[1] > best_level and off < 0:
                best_level = -up[1]
                floor = np.array([*up, off])
        return on_plane, floor

    def _fronts(self, mask: np.ndarray, valid: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(H, W) bool: the pieces of a background plane's ``mask`` that stand in front of
        what surrounds them. People standing side by side facing the camera put their
        chests on one plane a metre or more across, which the plane test takes for a
        wall; with the forest's vote weak on torsos (a real torso's more than a vhgen
        one's) nothing else keeps them. A piece (8-connected, at least ``min_pixels``) is
        a front when more of its border steps back to something farther than steps
        forward to something nearer (:func:`_outline_share`, the same depth step): a
        torso between the gaps beside it, not a wall or floor, which is bounded by the
        nearer things standing before it, corners and the frame."""
        from scipy import ndimage

        lab, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
        out = np.zeros(mask.shape, bool)
        for k, sl in enumerate(ndimage.find_objects(lab), start=1):
            if sl is None:
                continue
            # the piece's box and one pixel around it: its border pairs
            box = tuple(slice(max(s.start - 1, 0), s.stop + 1) for s in sl)
            piece = lab[box] == k
            if piece.sum() < self.min_pixels:
                continue
            far = _outline_share(piece, valid[box], z[box], self.jump_m, unmeasured=False)
            near = _outline_share(piece, valid[box], z[box], self.jump_m, unmeasured=False,
                                  nearer=True)
            if far > near:
                out[box] |= piece
        return out

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

    def candidates(self, depth_mm: np.ndarray, intr: Intrinsics,
                   labels: np.ndarray | None = None) -> Candidates:
        """Steps 1, 2 and 2b: the person candidates of a frame; the forest's ``labels``
        (H, W) have a say only on which planes are background (None: none)."""
        depth = np.asarray(depth_mm)
        valid = depth > 0
        z = depth.astype(np.float64) / 1000.0
        points = backproject(intr, z)
        body = None if labels is None else np.asarray(labels) > 0
        background, floor = self.find_planes(points, valid, body)
        keep = valid & ~background
        comp, n = self.clusters(z, keep)
        if self.split:
            comp, n = self.split_people(comp, n, points, floor)
        return Candidates(comp, n, points, keep, floor)

    def cluster_table(self, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray
                      ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Steps 1-2 and what step 3 decides on: the cluster image (H, W) int32 (0 = no
        cluster) and, per cluster id (index 0 unused), ``pixels``, ``body`` (the share the
        forest calls a body part), ``coherence`` (the share of neighbouring pairs of body
        pixels, right and below, that have the same part: whole parts, not confetti),
        ``parts`` (parts with at least 5% of its body pixels) and ``extent_m``."""
        labels = np.asarray(labels)
        cand = self.candidates(depth_mm, intr, labels)
        return cand.comp, self.table_of(cand.comp, cand.count, cand.points, labels,
                                        cand.keep)

    def table_of(self, comp: np.ndarray, n: int, points: np.ndarray, labels: np.ndarray,
                 keep: np.ndarray) -> dict[str, np.ndarray]:
        """The table of :meth:`cluster_table` for candidates ``comp`` (of :meth:`candidates`)."""
        from scipy import ndimage

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
        for c, sl in enumerate(ndimage.find_objects(comp), start=1):
            if sl is None or size[c] < self.min_pixels:
                continue
            m = comp[sl] == c
            counts = np.bincount(labels[sl][m & body[sl]])
            if counts.sum():
                parts[c] = int((counts[1:] >= 0.05 * counts.sum()).sum())
            extent[c] = _longest_extent(points[sl][m])
        return {"pixels": size, "body": called / np.maximum(size, 1),
                "coherence": same / np.maximum(pairs, 1), "parts": parts,
                "extent_m": extent}

    def features(self, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray,
                 part_heights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The candidates of a frame and what the person stage decides on: (H, W) int32
        candidate ids (0 = none) and (n + 1, len(FEATURES)) float64, as :meth:`describe`
        says (``part_heights`` as there)."""
        depth = np.asarray(depth_mm)
        cand = self.candidates(depth, intr, labels)
        return cand.comp, self.describe(cand, depth, intr, labels, part_heights=part_heights)

    def describe(self, cand: Candidates, depth_mm: np.ndarray, intr: Intrinsics,
                 labels: np.ndarray, use_floor: bool = True,
                 table: dict[str, np.ndarray] | None = None,
                 part_heights: np.ndarray | None = None) -> np.ndarray:
        """What the person stage decides on, per candidate of ``cand``: (n + 1,
        len(FEATURES)) float64 (row 0 and the rows of candidates below ``min_pixels`` are
        NaN: never a person). Heights are above the floor (without one, or without
        ``use_floor``: ``top_m`` is the candidate's height and ``bottom_m`` 0), widths
        are 5th-95th percentile spreads on the floor: overall, of the points within 0.2 m
        of the top (a head) and 0.2-0.5 m below it (shoulders); ``area_m2`` is the log of
        the surface seen; ``fill`` that surface over height times width; ``in_front`` the
        share of the outline whose outside is farther by a depth step or unmeasured;
        ``at_image_edge`` whether its box comes within ``edge_px`` of the box of the
        frame's measured pixels (cut off by the frame); ``body``, ``coherence`` and
        ``parts`` are the forest's, as in :meth:`cluster_table`;
        ``behind`` the share of the outline whose outside is nearer by a depth step
        (something stands in front of it); ``column_height_m`` the height from the lowest
        to the highest point of the candidates whose centres on the floor lie within
        ``column_m`` of this one's (itself and smaller ones included), and
        ``column_share`` its share of their pixels: a piece of a person seen past someone
        in front is short, but its column is as tall as the person. The
        :data:`SURFACE_FEATURES` say what its surface normals do
        (:func:`vhgen.geom.normals.surface_shares` over 5 cm patches): the share of its
        pixels with a normal, and of those the share within 15 deg of their dominant
        direction, facing sideways and facing up or down (a person is rounded; a chair,
        a door or a bookcase is flat pieces). ``part_order``,
        ``top_parts`` and ``bottom_parts`` say whether the forest's parts lie where they
        lie on a person (:func:`part_features`, given the stage's ``part_heights``; 0
        without them).
        ``use_floor=False`` describes the candidates as a frame whose floor was not found
        would (how the person stage learns to decide without one); ``table``: their
        :meth:`table_of`, when already computed (it does not depend on the floor)."""
        from scipy import ndimage

        depth = np.asarray(depth_mm)
        comp, points = cand.comp, cand.points
        if table is None:
            table = self.table_of(comp, cand.count, points, np.asarray(labels), cand.keep)
        out = np.full((cand.count + 1, len(FEATURES)), np.nan)
        valid = depth > 0
        rows, cols = np.flatnonzero(valid.any(1)), np.flatnonzero(valid.any(0))
        seen = ((rows[0], rows[-1] + 1, cols[0], cols[-1] + 1) if len(rows)
                else (0, depth.shape[0], 0, depth.shape[1]))
        floor = cand.floor if use_floor else None
        on_floor = floor is not None
        up, off = ((floor[:3], float(floor[3])) if floor is not None
                   else (np.array([0.0, -1.0, 0.0]), 0.0))
        basis = _plane_basis(up)
        pixel_m2 = 1.0 / (intr.fx * intr.fy)
        z_img = points[..., 2]
        n = cand.count + 1
        flat = comp.reshape(-1)
        inside = flat > 0
        ids = flat[inside]
        p_all = points.reshape(-1, 3)[inside]
        h_all = p_all @ up - off
        q_all = p_all @ basis.T
        size = np.bincount(ids, minlength=n).astype(np.float64)
        centre = np.stack([np.bincount(ids, weights=q_all[:, k], minlength=n)
                           for k in range(2)], 1) / np.maximum(size, 1)[:, None]
        top = np.full(n, -np.inf)
        bottom = np.full(n, np.inf)
        np.maximum.at(top, ids, h_all)
        np.minimum.at(bottom, ids, h_all)
        for c, sl in enumerate(ndimage.find_objects(comp), start=1):
            if sl is None or table["pixels"][c] < self.min_pixels:
                continue
            m = comp[sl] == c
            p = points[sl][m]
            z = p[:, 2]
            h = p @ up - off
            lo, hi = np.percentile(h, [2, 98])
            height = hi - lo
            q = p @ basis.T
            width = _spread(q).max()
            area = float((z * z).sum() * pixel_m2)
            head = h > hi - 0.2
            shoulders = (h > hi - 0.5) & ~head
            ys, xs = sl
            # the outline's pairs lie within one pixel of the candidate's box
            around = (slice(max(ys.start - 1, 0), ys.stop + 1),
                      slice(max(xs.start - 1, 0), xs.stop + 1))
            mine = comp[around] == c
            out[c] = (float(np.median(z)), np.log(max(area, 1e-6)), float(on_floor),
                      hi if on_floor else height, lo if on_floor else 0.0, height, width,
                      float(np.percentile(z, 95) - np.percentile(z, 5)),
                      _spread(q[head]).max() if head.sum() >= 3 else 0.0,
                      _spread(q[shoulders]).max() if shoulders.sum() >= 3 else 0.0,
                      area / max(height * width, 1e-6),
                      _outline_share(mine, valid[around], z_img[around],
                                     self.jump_m, unmeasured=True),
                      float(min(ys.start - seen[0], seen[1] - ys.stop, xs.start - seen[2],
                                seen[3] - xs.stop) < self.edge_px),
                      table["body"][c], table["coherence"][c], float(table["parts"][c]),
                      _outline_share(mine, valid[around], z_img[around],
                                     self.jump_m, unmeasured=False, nearer=True),
                      0.0, 0.0,  # the column's two, below
                      *surface_shares(patch_normals(points[around], mine, intr.fx), up, len(p)),
                      0.0, 0.0, 0.0)  # the parts', below
            top[c], bottom[c] = hi, lo
        # the column: every candidate whose centre on the floor is within column_m of
        # this one's (the small ones by their extreme heights, the others by the 2nd and
        # 98th percentiles above)
        big = np.flatnonzero(~np.isnan(out[:, 0]))
        if len(big):
            d2 = ((centre[big][:, None, :] - centre[None, 1:, :]) ** 2).sum(-1)
            near = d2 < self.column_m ** 2
            tops = np.where(near, top[None, 1:], -np.inf).max(1)
            bottoms = np.where(near, bottom[None, 1:], np.inf).min(1)
            out[big, FEATURES.index("column_height_m")] = tops - bottoms
            out[big, FEATURES.index("column_share")] = size[big] / (near * size[None, 1:]).sum(1)
            if part_heights is not None:
                hist = self.part_histograms(cand, labels, len(part_heights), use_floor)
                out[big, PART_COLUMNS] = part_features(hist[big], part_heights)
        return out

    def part_histograms(self, cand: Candidates, labels: np.ndarray, num_labels: int,
                        use_floor: bool = True) -> np.ndarray:
        """(n + 1, num_labels, HEIGHT_BINS) float64: per candidate of ``cand``, its pixels
        counted by the forest's label and by their height in the candidate (tenths of
        its 2nd to 98th percentile above the floor, clipped; without a floor, or without
        ``use_floor``, up in the camera), as :meth:`describe` measures heights. What
        :func:`learn_part_heights` learns from and :func:`part_features` reads."""
        from scipy import ndimage

        floor = cand.floor if use_floor else None
        up, off = ((floor[:3], float(floor[3])) if floor is not None
                   else (np.array([0.0, -1.0, 0.0]), 0.0))
        labels = np.asarray(labels)
        out = np.zeros((cand.count + 1, num_labels, HEIGHT_BINS))
        for c, sl in enumerate(ndimage.find_objects(cand.comp), start=1):
            if sl is None:
                continue
            m = cand.comp[sl] == c
            if m.sum() < self.min_pixels:
                continue
            h = cand.points[sl][m] @ up - off
            lo, hi = np.percentile(h, [2, 98])
            tenth = np.clip(((h - lo) / max(hi - lo, 1e-6) * HEIGHT_BINS).astype(np.int64),
                            0, HEIGHT_BINS - 1)
            lab = labels[sl][m].astype(np.int64)
            ok = lab < num_labels  # labels the stage has no height for: left out
            out[c] = np.bincount(lab[ok] * HEIGHT_BINS + tenth[ok],
                                 minlength=num_labels * HEIGHT_BINS).reshape(
                                     num_labels, HEIGHT_BINS)
        return out

    def people(self, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray,
               stage: PersonStage | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Step 3: the candidates (H, W) int32 and (n + 1,) bool, which are people: by
        the person ``stage`` when given (its probability at least ``min_person_prob``,
        and at least ``min_width_m`` wide), else by the forest's vote (:meth:`is_person`).
        Index 0 is False."""
        if stage is None:
            comp, table = self.cluster_table(depth_mm, intr, np.asarray(labels))
            return comp, self.is_person(table)
        comp, x, p = self.person_probability(depth_mm, intr, labels, stage)
        return comp, self.stage_calls(x, p)

    def stage_calls(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """(n + 1,) bool: the candidates of features ``x`` the stage calls people, given
        its probabilities ``p`` (:meth:`person_probability`): at least
        ``min_person_prob`` and at least ``min_width_m`` wide. Index 0 is False."""
        ok = p >= self.min_person_prob
        ok &= ~(x[:, FEATURES.index("width_m")] < self.min_width_m)  # NaN rows: the stage's 0
        ok[0] = False
        return ok

    def person_probability(self, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray,
                           stage: PersonStage) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The candidates (H, W) int32, their :data:`FEATURES` (n + 1, F) described with
        the ``stage``'s own part heights, and (n + 1,) the stage's probability of each
        (NaN rows: 0)."""
        comp, x = self.features(depth_mm, intr, labels, stage.part_heights)
        return comp, x, stage.predict_proba(x[:, feature_columns(stage.features)])

    def split_people(self, comp: np.ndarray, n: int, points: np.ndarray,
                     floor: np.ndarray | None) -> tuple[np.ndarray, int]:
        """Step 2b: ``comp`` with every cluster of several heads split between them;
        returns the new (H, W) int32 ids (0 = none) and their number."""
        from scipy import ndimage

        out = comp.copy()
        nxt = n + 1
        up = floor[:3] if floor is not None else np.array([0.0, -1.0, 0.0])
        basis = _plane_basis(up)
        for c, sl in enumerate(ndimage.find_objects(comp), start=1):
            if sl is None:
                continue
            m = comp[sl] == c
            if m.sum() < 2 * self.min_pixels:
                continue
            p = points[sl][m]
            h = p @ up - (floor[3] if floor is not None else 0.0)
            q = p @ basis.T
            if _spread(q).max() < self.min_split_width_m:
                continue  # one person wide: shoulders and raised hands are no heads
            heads = self._heads(q, h, floor is not None)
            if len(heads) < 2:
                continue
            d2 = ((q[:, None, :] - heads[None, :, :]) ** 2).sum(-1)
            near = np.argmin(d2, axis=1)
            ids = np.where(near == 0, c, nxt + near - 1).astype(np.int32)
            block = out[sl]
            block[m] = ids
            nxt += len(heads) - 1
        return out, nxt - 1

    def _heads(self, q: np.ndarray, h: np.ndarray, on_floor: bool) -> np.ndarray:
        """(k, 2) floor positions of the heads among points ``q`` (in-plane, m) of
        heights ``h`` (m): see step 2b."""
        from scipy import ndimage

        cell = self.cell_m
        ij = np.floor((q - q.min(0)) / cell).astype(np.int64)
        shape = tuple(ij.max(0) + 1)
        hmap = np.full(shape, -np.inf)
        np.maximum.at(hmap, (ij[:, 0], ij[:, 1]), h)
        radius = max(1, int(round(self.min_head_gap_m / 2 / cell)))
        size = 2 * radius + 1
        top = ndimage.maximum_filter(hmap, size=size, mode="constant", cval=-np.inf)
        floor_h = self.min_head_m if on_floor else float(h.max()) - self.head_band_m
        cand = np.argwhere((hmap == top) & (hmap >= floor_h))
        order = np.argsort(-hmap[cand[:, 0], cand[:, 1]])
        filled = np.where(np.isfinite(hmap), hmap, -1.0)  # gaps between people are low
        kept: list[np.ndarray] = []
        for k in order:
            a = cand[k]
            ha = hmap[a[0], a[1]]
            # a head is as wide as a head just below its top; a raised fist is not
            top_q = (a + 0.5) * cell + q.min(0)
            cap = (((q - top_q) ** 2).sum(1) < (self.min_head_gap_m / 1.5) ** 2) & (
                h > ha - self.min_prominence_m)
            if cap.sum() < 3 or _spread(q[cap]).max() < self.min_head_width_m:
                continue
            ok = True
            for b in kept:
                gap = np.hypot(*(a - b)) * cell
                if gap < self.min_head_gap_m:
                    ok = False
                    break
                steps = int(np.ceil(np.hypot(*(a - b)))) + 1
                line = np.rint(np.linspace(a, b, steps)).astype(np.int64)
                saddle = filled[line[:, 0], line[:, 1]].min()
                if ha - saddle < self.min_prominence_m:
                    ok = False
                    break
            if ok:
                kept.append(a)
        heads = []
        for a in kept:  # the head's centre: its points within a head's size of the top
            top_q = (a + 0.5) * cell + q.min(0)
            near = ((q - top_q) ** 2).sum(1) < (self.min_head_gap_m / 1.5) ** 2
            near &= h > hmap[a[0], a[1]] - 0.25
            heads.append(q[near].mean(0) if near.any() else top_q)
        return np.array(heads, np.float64).reshape(-1, 2)

    def instances(self, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray,
                  stage: PersonStage | None = None) -> np.ndarray:
        """(H, W) uint8: 0 = no person, k = the k-th person kept (numbered left to right
        by their mean column; at most 255); ``stage`` as in :meth:`people`."""
        comp, person = self.people(depth_mm, intr, labels, stage)
        ok = np.flatnonzero(person)
        n = len(person)
        pixels = np.bincount(comp.reshape(-1), minlength=n)
        cols = np.bincount(comp.reshape(-1), weights=np.tile(np.arange(comp.shape[1]),
                                                              comp.shape[0]), minlength=n)
        centre = cols[ok] / np.maximum(pixels[ok], 1)
        lut = np.zeros(n, np.uint8)
        lut[ok[np.argsort(centre, kind="stable")][:255]] = np.arange(1, min(len(ok), 255) + 1)
        return lut[comp]

    def is_person(self, table: dict[str, np.ndarray]) -> np.ndarray:
        """Step 3 over a :meth:`cluster_table`: (n + 1,) bool, index 0 False."""
        ok = ((table["pixels"] >= self.min_pixels) & (table["body"] >= self.min_body_fraction)
              & (table["extent_m"] >= self.min_extent_m)
              & (table["extent_m"] <= self.max_extent_m)
              & (table["coherence"] >= self.min_coherence)
              & (table["parts"] >= self.min_parts))
        ok[0] = False
        return ok

    def apply(self, depth_mm: np.ndarray, intr: Intrinsics, labels: np.ndarray,
              stage: PersonStage | None = None, people: np.ndarray | None = None
              ) -> np.ndarray:
        """The forest's ``labels`` (H, W) uint8 of the frame ``depth_mm`` after the stage
        (``stage`` as in :meth:`people`; ``people``: its :meth:`instances` when already
        computed)."""
        from scipy import ndimage

        labels = np.asarray(labels)
        if people is None:
            comp, person = self.people(depth_mm, intr, labels, stage)
            mask = person[comp]
        else:
            mask = np.asarray(people) > 0
        out = np.where(mask, labels, 0).astype(np.uint8)
        holes = mask & (out == 0)
        if holes.any() and (out > 0).any():
            # the nearest labelled pixel of each hole (in the image) gives its part
            _, (iy, ix) = ndimage.distance_transform_edt(out == 0, return_indices=True)
            out[holes] = out[iy[holes], ix[holes]]
        return out


def learn_part_heights(hist: np.ndarray, person: np.ndarray) -> np.ndarray:
    """(L,) float64: the typical height of each of the forest's parts in a person (0 =
    feet, 1 = top of the head): the mean height (tenths' centres) of the pixels the forest
    gives each label in the candidates ``hist`` (N, L, HEIGHT_BINS) that are people
    (``person`` (N,) bool). NaN for label 0 (background) and for labels never seen on a
    person. Learned from vhgen candidates; nothing here is chosen."""
    centres = (np.arange(HEIGHT_BINS) + 0.5) / HEIGHT_BINS
    sums = np.asarray(hist)[np.asarray(person, bool)].sum(0)
    total = sums.sum(1)
    out = np.full(sums.shape[0], np.nan)
    seen = total > 0
    out[seen] = (sums[seen] * centres).sum(1) / total[seen]
    out[0] = np.nan
    return out


def part_features(hist: np.ndarray, part_heights: np.ndarray) -> np.ndarray:
    """(N, 3) float64 from candidates' :meth:`Segmenter.part_histograms` rows ``hist``
    (N, L, HEIGHT_BINS) and the parts' typical heights (:func:`learn_part_heights`):
    ``part_order``, the correlation between the height of each pixel the forest calls a
    part and that part's typical height (a person: head over chest over legs; a coat
    stand or a plant the forest calls a body part in places: little order; 0 with fewer
    than 10 such pixels or no spread); ``top_parts``, the share of the candidate's top
    fifth called a part whose typical height is in the top fifth (a head, a neck);
    ``bottom_parts``, the share of its lowest 30% called a part typical there (feet,
    shins, knees). Pixels the forest calls background count in the shares, not in the
    order."""
    hist = np.asarray(hist, np.float64)
    typical = np.asarray(part_heights, np.float64)
    known = ~np.isnan(typical)
    t = np.where(known, typical, 0.0)
    centres = (np.arange(HEIGHT_BINS) + 0.5) / HEIGHT_BINS
    w = hist[:, known, :]
    tk = t[known][None, :, None]
    hb = centres[None, None, :]
    n = w.sum((1, 2))
    safe = np.maximum(n, 1.0)
    dt = tk - ((w * tk).sum((1, 2)) / safe)[:, None, None]
    dh = hb - ((w * hb).sum((1, 2)) / safe)[:, None, None]
    denom = np.sqrt((w * dt ** 2).sum((1, 2)) * (w * dh ** 2).sum((1, 2)))
    ok = (n >= 10) & (denom > 1e-12)
    order = np.where(ok, (w * dt * dh).sum((1, 2)) / np.where(ok, denom, 1.0), 0.0)
    upper = hist[:, :, TOP_BINS:]
    lower = hist[:, :, :BOTTOM_BINS]
    top = upper[:, known & (t >= TOP_BINS / HEIGHT_BINS)].sum((1, 2)) / np.maximum(
        upper.sum((1, 2)), 1.0)
    bottom = lower[:, known & (t < BOTTOM_BINS / HEIGHT_BINS)].sum((1, 2)) / np.maximum(
        lower.sum((1, 2)), 1.0)
    return np.stack([order, top, bottom], 1)


def feature_columns(names: tuple[str, ...]) -> list[int]:
    """The columns of :data:`FEATURES` a person stage trained on ``names`` reads (a stage
    of an older version reads fewer); ValueError naming a feature this version lacks."""
    unknown = [f for f in names if f not in FEATURES]
    if unknown:
        raise ValueError(f"person stage features {unknown} are not this version's "
                         f"{FEATURES}")
    return [FEATURES.index(f) for f in names]


def _outline_share(mask: np.ndarray, valid: np.ndarray, z: np.ndarray, jump_m: float,
                   unmeasured: bool, nearer: bool = False) -> float:
    """Of the 4-neighbour pairs across the border of ``mask``, the share whose outside
    pixel is farther by more than a depth step (``jump_m`` at 1 m, times z): high for
    something standing in front of a room (a row of people, a person), low for a wall or
    a floor, whose borders are corners or nearer things in front of them. ``unmeasured``:
    an outside pixel without a measurement counts as farther; else such pairs do not
    count at all. ``nearer``: the share whose outside pixel is nearer by a step instead
    (something stands in front of the mask; pairs without a measurement outside never
    count as nearer)."""
    far = total = 0
    for a, b, za, zb, va, vb in ((mask[:, :-1], mask[:, 1:], z[:, :-1], z[:, 1:],
                                  valid[:, :-1], valid[:, 1:]),
                                 (mask[:-1], mask[1:], z[:-1], z[1:], valid[:-1], valid[1:])):
        out_b = a & ~b & (vb | unmeasured)  # inside at a, outside at b
        out_a = b & ~a & (va | unmeasured)
        if nearer:  # the outside pixel nearer by a step: something in front of it
            far += int((out_b & vb & (za - zb > jump_m * zb)).sum())
            far += int((out_a & va & (zb - za > jump_m * za)).sum())
        else:
            far += int((out_b & (~vb | (zb - za > jump_m * za))).sum())
            far += int((out_a & (~va | (za - zb > jump_m * zb))).sum())
        total += int(out_b.sum() + out_a.sum())
    return far / total if total else 0.0


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
