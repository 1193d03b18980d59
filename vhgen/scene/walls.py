"""Room walls with openings (doors), as rectangles around the holes (pure NumPy)."""

from __future__ import annotations

import numpy as np

from vhgen.scene.geometry import WALL, StaticMesh, room_walls


def _free_rects(length: float, height: float, holes: list[tuple[float, float, float, float]]
                ) -> list[tuple[float, float, float, float]]:
    """Rectangles (s0, s1, y0, y1) that tile [0, length] x [0, height] minus the holes
    (s0, s1, y0, y1): the wall is cut into columns at every hole edge, and each column
    keeps the heights no hole of that column covers."""
    cuts = sorted({0.0, length, *(min(max(v, 0.0), length) for h in holes for v in h[:2])})
    out = []
    for s0, s1 in zip(cuts[:-1], cuts[1:], strict=True):
        if s1 - s0 <= 1e-9:
            continue
        blocked = sorted((max(h[2], 0.0), min(h[3], height)) for h in holes
                         if h[0] <= s0 + 1e-9 and h[1] >= s1 - 1e-9)
        y = 0.0
        for b0, b1 in blocked:
            if b0 > y:
                out.append((s0, s1, y, b0))
            y = max(y, b1)
        if y < height:
            out.append((s0, s1, y, height))
    return out


def walls_with_openings(corners_xz: np.ndarray, height: float,
                        openings: dict[int, list[tuple[float, float, float, float]]]
                        ) -> StaticMesh:
    """The 4 walls of :func:`~vhgen.scene.geometry.room_walls` with rectangular holes:
    ``openings`` maps a wall (corner k to k + 1) to holes (s0, s1, y0, y1), metres along
    the wall from corner k and above the floor. Without holes: exactly ``room_walls``."""
    if not any(openings.values()):
        return room_walls(corners_xz, height)
    c = np.asarray(corners_xz, np.float64)
    verts: list[list[float]] = []
    faces: list[list[int]] = []
    for k in range(4):
        a, b = c[k], c[(k + 1) % 4]
        length = float(np.hypot(*(b - a)))
        e = (b - a) / length
        for s0, s1, y0, y1 in _free_rects(length, height, openings.get(k, [])):
            p0, p1 = a + s0 * e, a + s1 * e
            base = len(verts)
            verts += [[p0[0], y0, p0[1]], [p1[0], y0, p1[1]], [p1[0], y1, p1[1]],
                      [p0[0], y1, p0[1]]]
            faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return StaticMesh("walls", np.array(verts), np.array(faces),
                      np.full(len(faces), WALL, np.uint8))
