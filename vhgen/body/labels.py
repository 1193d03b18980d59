"""Body-part label schemes: declared as data, resolved to one label per triangle.

A scheme (``configs/labels/*.yaml``) lists parts in label order (label 1 is the first
part; 0 is background). Each part has a colour and selectors; a triangle gets the first
part one of whose selectors matches it. A selector matches on

* ``bones``: the triangle's dominant bone (largest weight summed over its 3 vertices);
* ``t``: ``[lo, hi)``, the position of the triangle's rest centroid projected on that
  bone's head->tail axis (0 at the head, 1 at the tail; may run outside [0, 1]);
* ``side``: ``left`` or ``right`` of the subject (x > 0 is the subject's own left);
* ``vertices``: an explicit list of base-mesh vertex indices (MakeHuman's numbering in
  ``base.obj``, 0-based), or ``vertex_group``: an MPFB2 vertex group name; a triangle
  matches when all three of its vertices are in the set. ``bones`` may then be omitted.

Labels are per triangle so a label image never blends two parts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.body.mesh import Rig
from vhgen.errors import ConfigError
from vhgen.yamlio import check_keys, find_config, load_yaml


@dataclass(frozen=True)
class Selector:
    bones: tuple[str, ...] = ()
    t: tuple[float, float] = (-np.inf, np.inf)
    side: str | None = None
    vertices: tuple[int, ...] = ()
    vertex_group: str | None = None


@dataclass(frozen=True)
class Part:
    name: str
    color: tuple[int, int, int]
    selectors: tuple[Selector, ...]


@dataclass(frozen=True)
class LabelScheme:
    name: str
    parts: tuple[Part, ...]
    source: str | None = None

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parts]

    @property
    def palette(self) -> np.ndarray:
        """(K+1, 3) uint8 colours, row 0 = background (black)."""
        return np.array([(0, 0, 0)] + [p.color for p in self.parts], dtype=np.uint8)

    @classmethod
    def load(cls, name_or_path: str | Path) -> LabelScheme:
        path = find_config("labels", name_or_path)
        d = load_yaml(path)
        check_keys(d, {"name", "description", "parts"}, {"name", "parts"}, path, "")
        parts = []
        if not isinstance(d["parts"], list) or not d["parts"]:
            raise ConfigError(path, "parts", "must be a non-empty list")
        if len(d["parts"]) > 255:
            raise ConfigError(path, "parts", f"{len(d['parts'])} parts; labels are uint8 (<=255)")
        for i, p in enumerate(d["parts"]):
            where = f"parts[{i}]."
            check_keys(p, {"name", "color", "select"}, {"name", "color", "select"}, path, where)
            col = p["color"]
            if (not isinstance(col, list) or len(col) != 3
                    or not all(isinstance(c, int) and 0 <= c <= 255 for c in col)):
                raise ConfigError(path, where + "color",
                                  f"must be [r, g, b] in 0..255, got {col!r}")
            sels = []
            for k, s in enumerate(p["select"]):
                w = f"{where}select[{k}]."
                check_keys(s, {"bones", "t", "side", "vertices", "vertex_group"}, set(), path, w)
                if not any(k in s for k in ("bones", "vertices", "vertex_group")):
                    raise ConfigError(path, w + "bones",
                                      "a selector needs bones, vertices or vertex_group")
                verts = s.get("vertices", [])
                if not isinstance(verts, list) or not all(
                        isinstance(v, int) and v >= 0 for v in verts):
                    raise ConfigError(path, w + "vertices",
                                      "must be a list of non-negative vertex indices")
                t = s.get("t", [None, None])
                if not isinstance(t, list) or len(t) != 2:
                    raise ConfigError(path, w + "t", f"must be [lo, hi], got {t!r}")
                lo = -np.inf if t[0] is None else float(t[0])
                hi = np.inf if t[1] is None else float(t[1])
                side = s.get("side")
                if side not in (None, "left", "right"):
                    raise ConfigError(path, w + "side", f"must be left or right, got {side!r}")
                sels.append(Selector(tuple(s.get("bones", ())), (lo, hi), side, tuple(verts),
                                     s.get("vertex_group")))
            parts.append(Part(str(p["name"]), tuple(col), tuple(sels)))
        names = [p.name for p in parts]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ConfigError(path, "parts", f"duplicate part names: {sorted(dup)}")
        return cls(str(d["name"]), tuple(parts), str(path))

    def assign(self, rig: Rig, vertices: np.ndarray, faces: np.ndarray,
               weights: np.ndarray, vertex_groups: dict[str, np.ndarray] | None = None
               ) -> np.ndarray:
        """Label (1..K) of every triangle; raises if a bone is unknown or a face unlabelled.

        vertices : (V, 3) rest positions, all base-mesh vertices (so explicit vertex
        indices mean base.obj's); faces : (T, 3) into them; weights : (V, B) dense.
        """
        for p in self.parts:
            for s in p.selectors:
                bad = [b for b in s.bones if b not in rig.names]
                if bad:
                    raise ConfigError(self.source, f"parts.{p.name}.select.bones",
                                      f"bones not in the rig: {', '.join(bad)}")
        face_w = weights[faces].sum(axis=1)  # (T, B)
        dominant = np.argmax(face_w, axis=1)
        centroid = vertices[faces].mean(axis=1)
        axis = rig.tails - rig.heads
        axis_len2 = np.maximum(np.einsum("bi,bi->b", axis, axis), 1e-18)
        t = np.einsum("ti,ti->t", centroid - rig.heads[dominant], axis[dominant]) / \
            axis_len2[dominant]
        left = centroid[:, 0] >= 0.0
        labels = np.zeros(len(faces), dtype=np.uint8)
        for label, p in enumerate(self.parts, start=1):
            for s in p.selectors:
                m = labels == 0
                if s.bones:
                    bone_ids = [rig.index(b) for b in s.bones]
                    m &= np.isin(dominant, bone_ids) & (t >= s.t[0]) & (t < s.t[1])
                if s.vertices or s.vertex_group:
                    chosen = np.zeros(len(vertices), bool)
                    chosen[[v for v in s.vertices if v < len(vertices)]] = True
                    if s.vertex_group:
                        if not vertex_groups or s.vertex_group not in vertex_groups:
                            raise ConfigError(self.source, f"parts.{p.name}.select.vertex_group",
                                              f"unknown vertex group {s.vertex_group!r}")
                        chosen[vertex_groups[s.vertex_group]] = True
                    m &= chosen[faces].all(axis=1)
                if s.side == "left":
                    m &= left
                elif s.side == "right":
                    m &= ~left
                labels[m] = label
        missing = labels == 0
        if missing.any():
            bones = sorted({rig.names[b] for b in dominant[missing]})
            raise ConfigError(self.source, "parts",
                              f"{int(missing.sum())} triangles match no part "
                              f"(dominant bones: {', '.join(bones)})")
        return labels
