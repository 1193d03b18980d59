"""Props: parametric furniture built with trimesh, or any mesh file trimesh reads.

Every prop is a :class:`PropShape` in its own frame: standing on y = 0, centred on the
y axis in x and z, metres. Sizes are drawn from the given generator (the scene stream).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.errors import ConfigError
from vhgen.geom.primitives import centred_cylinder, cube

PARAMETRIC = ("box", "table", "chair", "sofa", "door", "cylinder")


@dataclass(frozen=True, eq=False)
class PropShape:
    """A prop's mesh in its own frame: vertices (V, 3) float64 (floor at y = 0, centred
    in x/z), faces (T, 3) int64, and the radius of its footprint circle about the y axis."""

    kind: str
    vertices: np.ndarray
    faces: np.ndarray

    @property
    def radius(self) -> float:
        return float(np.hypot(self.vertices[:, 0], self.vertices[:, 2]).max())


_Mesh = tuple[np.ndarray, np.ndarray]  # vertices (V, 3), faces (T, 3)


def _boxes(parts: list[tuple[tuple[float, float, float], tuple[float, float, float]]]
           ) -> _Mesh:
    """Concatenated boxes, each (extents, centre), from the unit cube (plain NumPy: a box
    is 12 triangles, and building them with trimesh per frame costs milliseconds)."""
    unit = cube()
    verts = [unit.vertices * np.asarray(e) + np.asarray(c) for e, c in parts]
    faces = [unit.faces + 8 * k for k in range(len(parts))]
    return np.concatenate(verts), np.concatenate(faces)


def _legs(w: float, d: float, leg: float, h: float) -> list:
    x, z = w / 2 - leg / 2, d / 2 - leg / 2
    return [((leg, h, leg), (sx * x, h / 2, sz * z)) for sx in (-1, 1) for sz in (-1, 1)]


def parametric(kind: str, rng: np.random.Generator) -> PropShape:
    """A parametric prop with sizes drawn from ``rng`` (always 4 draws)."""
    u = rng.uniform(size=4)

    def lerp(k: int, lo: float, hi: float) -> float:
        return float(lo + u[k] * (hi - lo))

    if kind == "box":
        m = _boxes([((lerp(0, 0.3, 0.9), lerp(1, 0.3, 1.0), lerp(2, 0.3, 0.8)), (0, 0, 0))])
    elif kind == "table":
        w, d, h = lerp(0, 0.8, 1.6), lerp(1, 0.6, 0.9), lerp(2, 0.7, 0.8)
        m = _boxes([((w, 0.04, d), (0, h - 0.02, 0))] + _legs(w, d, 0.06, h - 0.04))
    elif kind == "chair":
        w, s, back = lerp(0, 0.42, 0.5), lerp(1, 0.42, 0.48), lerp(2, 0.4, 0.5)
        m = _boxes([((w, 0.05, w), (0, s - 0.025, 0)),
                    ((w, back, 0.04), (0, s + back / 2, -w / 2 + 0.02))] + _legs(w, w, 0.04,
                                                                                  s - 0.05))
    elif kind == "sofa":
        w, d, seat = lerp(0, 1.4, 2.2), lerp(1, 0.8, 1.0), lerp(2, 0.4, 0.48)
        arm, back = 0.18, lerp(3, 0.35, 0.5)
        m = _boxes([((w, seat, d), (0, seat / 2, 0)),
                    ((w, back, 0.2), (0, seat + back / 2, -d / 2 + 0.1)),
                    ((arm, 0.2, d), (-w / 2 + arm / 2, seat + 0.1, 0)),
                    ((arm, 0.2, d), (w / 2 - arm / 2, seat + 0.1, 0))])
    elif kind == "door":  # a door leaf standing open in the room, with its frame
        w, h = lerp(0, 0.8, 0.95), lerp(1, 1.95, 2.1)
        m = _boxes([((w, h, 0.04), (0, h / 2, 0)), ((0.08, h + 0.08, 0.1), (-w / 2 - 0.04,
                                                                         h / 2 + 0.04, 0)),
                    ((0.08, h + 0.08, 0.1), (w / 2 + 0.04, h / 2 + 0.04, 0)),
                    ((w, 0.08, 0.1), (0, h + 0.04, 0))])
    elif kind == "cylinder":
        r, h = lerp(0, 0.1, 0.35), lerp(1, 0.4, 1.2)
        unit = centred_cylinder()
        m = (unit.vertices * np.array([r, h, r]), unit.faces)
    else:
        raise ValueError(f"unknown prop kind {kind!r}")
    return _stand(kind, np.asarray(m[0], np.float64), np.asarray(m[1], np.int64))


def _stand(kind: str, v: np.ndarray, f: np.ndarray) -> PropShape:
    """Put the lowest point on y = 0 and centre the footprint's bounding box on x = z = 0."""
    lo, hi = v.min(0), v.max(0)
    return PropShape(kind, v - np.array([(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2]), f)


def load_mesh(path: str | Path, scale: float, source, field: str) -> PropShape:
    """A mesh file (any format trimesh reads) as a prop, scaled; errors name the field."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(source, field, f"prop mesh {p} does not exist")
    try:
        import trimesh

        m: Any = trimesh.load(str(p), force="mesh")
        v = np.asarray(m.vertices, np.float64) * scale
        f = np.asarray(m.faces, np.int64)
    except Exception as e:  # trimesh raises many types for unreadable files
        raise ConfigError(source, field, f"trimesh cannot read {p}: {e}") from None
    if len(f) == 0 or not np.isfinite(v).all():
        raise ConfigError(source, field, f"{p} has no triangles (or non-finite vertices)")
    return _stand(p.name, v, f)
