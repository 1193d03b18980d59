"""Tight garments as a displacement of the body surface: tops, jackets, trousers, collars,
shoes, and the hair and hat layers that lie on the scalp.

A garment layer is a thickness per body triangle (0 where it does not cover). Layers
stack: a triangle's thickness is the sum of the layers over it (a coat over a jumper
over trouser waistbands). Each body vertex moves out along its (smoothed) rest normal by
the largest thickness of its triangles, so a covered triangle lies wholly on the
garment's outer surface, and the uncovered triangles along a garment's edge become its
hem (a ring of triangles from the garment down to the skin, about one triangle wide).

The triangles, their labels and the mesh topology do not change: a garment pixel keeps
the label of the body triangle under it, exactly; the body stays one closed surface, so
the renderer still culls its far side; and the covered skin costs nothing because it is
the garment. Skinning is the body's own (the vertex keeps its joints and weights): the
offset turns with the blended bone rotation at that vertex, so a sleeve follows the arm
and never sinks under the skin it covers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vhgen.body.chart import (
    ARM_L,
    ARM_R,
    FOOT_L,
    FOOT_R,
    HAND_L,
    HAND_R,
    HEAD,
    LEG_L,
    LEG_R,
    NECK,
    TORSO,
    BodyChart,
    smooth,
)
from vhgen.body.contact import PRESS_LEFT, PRESS_RIGHT
from vhgen.body.wardrobe import Outfit

ARMS = (ARM_L, ARM_R, HAND_L, HAND_R)
LEGS = (LEG_L, LEG_R)
FEET = (FOOT_L, FOOT_R)


@dataclass(frozen=True, eq=False)
class Layer:
    """One garment's thickness per body triangle (T,) float64 metres (0 = not covered)."""

    name: str
    thickness: np.ndarray


def _smoothstep(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    s = np.clip((x - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
    return s * s * (3 - 2 * s)


def _nan_lt(a: np.ndarray, hi: float) -> np.ndarray:
    return np.nan_to_num(a, nan=np.inf) < hi


def _nan_gt(a: np.ndarray, lo: float) -> np.ndarray:
    return np.nan_to_num(a, nan=-np.inf) > lo


def upper_body(chart: BodyChart, sleeve: float, hem: float, collar: float,
               open_gap_m: float = 0.0) -> np.ndarray:
    """(T,) bool: a top's triangles. The torso (and the tops of the thighs) above height
    ``hem`` (chart height: 0 hip joints, 1 neck base), the arms down to ``sleeve`` (arm_t;
    <= 0 sleeveless, 1 the wrist), the neck up to ``collar`` (neck_t; 0 none, ~0.8 a
    turtleneck); ``open_gap_m`` > 0 leaves a vertical strip of that width open down the
    front (an open jacket or coat)."""
    r, h = chart.face_region, chart.face_height
    body = np.isin(r, (TORSO,) + LEGS) & (h > hem)
    arms = np.isin(r, ARMS) & _nan_lt(chart.face_arm_t, sleeve)
    neck = (r == NECK) & (chart.face_neck_t < collar)
    out = body | arms | neck
    if open_gap_m > 0:
        out &= ~(chart.face_front & (np.abs(chart.face_x) < open_gap_m / 2)
                 & np.isin(r, (TORSO, NECK) + LEGS))
    return out


def lower_body(chart: BodyChart, length: float, rise: float) -> np.ndarray:
    """(T,) bool: trousers or shorts: the legs down to ``length`` (leg_t; 1 = the ankle)
    and the torso below height ``rise`` (the waistband)."""
    r = chart.face_region
    legs = np.isin(r, LEGS) & _nan_lt(chart.face_leg_t, length)
    hips = (r == TORSO) & (chart.face_height < rise)
    return legs | hips


def feet(chart: BodyChart, height: float) -> np.ndarray:
    """(T,) bool: shoes or boots: the feet, and the legs below ``height`` (leg_t; 1 =
    the ankle, ~0.7 a boot to mid-calf)."""
    r = chart.face_region
    return np.isin(r, FEET) | (np.isin(r, LEGS) & _nan_gt(chart.face_leg_t, height))


def tight_layers(chart: BodyChart, outfit: Outfit) -> list[Layer]:
    """The tight layers of an outfit (see :mod:`vhgen.body.wardrobe` for the parameters),
    innermost first."""
    layers: list[Layer] = []
    t_faces = len(chart.face_region)

    def add(name: str, mask: np.ndarray, thickness: np.ndarray | float) -> None:
        layers.append(Layer(name, np.where(mask, thickness, 0.0) * np.ones(t_faces)))

    bottom = outfit.bottom
    if bottom is not None and bottom.kind in ("trousers", "shorts"):
        mask = lower_body(chart, bottom.length, bottom.rise)
        # wide legs flare from the knee down
        flare = bottom.width * _smoothstep(np.nan_to_num(chart.face_leg_t), 0.45, 1.0)
        add(bottom.kind, mask, bottom.thickness_m + flare)
    elif bottom is not None:  # a skirt: its waistband is tight, the rest hangs (drape)
        add("waistband", (chart.face_region == TORSO) & (chart.face_height < bottom.rise)
            & (chart.face_height > bottom.rise - 0.15), bottom.thickness_m)
    top = outfit.top
    if top is not None:
        # a dress's top ends at its skirt's waist
        hem = top.hem if top.kind != "dress" else (
            bottom.rise if bottom is not None else 0.3) - 0.1
        add(top.kind, upper_body(chart, top.sleeve, hem, top.collar), top.thickness_m)
    outer = outfit.outer
    if outer is not None:
        gap = outer.gap_m if outer.open else 0.0
        add(outer.kind, upper_body(chart, outer.sleeve, outer.hem, outer.collar, gap),
            outer.thickness_m)
    shoes = outfit.shoes
    if shoes is not None:
        add(shoes.kind, feet(chart, shoes.height), shoes.thickness_m)
    return layers


def face_thickness(layers: list[Layer], num_faces: int) -> np.ndarray:
    """(T,) summed thickness of the layers."""
    total = np.zeros(num_faces)
    for layer in layers:
        total += layer.thickness
    return total


def displacement(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
                 chart: BodyChart, thickness: np.ndarray, extra: np.ndarray | None = None,
                 bridge: int = 4) -> np.ndarray:
    """Per-vertex offsets (V, 3) float64 that put every vertex on the garments over it.

    thickness : (T,) per triangle (:func:`face_thickness`); extra : (V,) more offset per
    vertex (shoe soles); normals : (V, 3) unit rest normals of the shaped body. A vertex
    moves by the largest thickness of its triangles along its normal smoothed over a few
    rings (folds in creases stay small). ``bridge`` smoothing passes over fully covered
    vertices then let the cloth span the body's small hollows (navel, spine, between the
    toes) instead of following them, never bringing a vertex nearer the skin than 80%
    of its thickness.
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    # the largest thickness of each vertex's triangles (the last of each vertex's run
    # when sorted by vertex, then thickness)
    idx, val = f.reshape(-1), np.repeat(thickness, 3)
    order = np.lexsort((val, idx))
    last = np.flatnonzero(np.r_[idx[order][1:] != idx[order][:-1], True])
    vt = np.zeros(len(v))
    vt[idx[order][last]] = val[order][last]
    if extra is not None:
        vt = vt + extra
    moved = vt > 0
    if not moved.any():
        return np.zeros_like(v)
    n = smooth(normals, chart.mean_ring, 3)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    p = v + vt[:, None] * n
    if bridge:
        # only where every neighbour moved too, so hems keep their edge
        inner = (chart.mean_ring @ moved.astype(np.float64)) > 1 - 1e-9
        p = smooth(p, chart.mean_ring, bridge, inner)
        along = np.einsum("ij,ij->i", p - v, n)
        low = along < 0.8 * vt
        p[low] += ((0.8 * vt - along)[low])[:, None] * n[low]
    off = p - v
    off[~moved] = 0.0
    return off


def press_mask(chart: BodyChart) -> np.ndarray:
    """(V,) uint8 bits: which hand (:data:`~vhgen.body.contact.PRESS_LEFT`,
    :data:`~vhgen.body.contact.PRESS_RIGHT`) may press the garment at a vertex towards
    the skin (:mod:`vhgen.body.contact`): any but its own arm's."""
    r = chart.region
    mask = np.full(len(r), PRESS_LEFT | PRESS_RIGHT, np.uint8)
    mask[np.isin(r, (ARM_L, HAND_L))] = PRESS_RIGHT
    mask[np.isin(r, (ARM_R, HAND_R))] = PRESS_LEFT
    mask[r == HEAD] = PRESS_LEFT | PRESS_RIGHT
    return mask

