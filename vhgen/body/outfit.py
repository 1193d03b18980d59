"""Dressing a body: an avatar's :class:`~vhgen.body.wardrobe.Outfit` (the typed records
:mod:`vhgen.body.wardrobe` draws and ``avatar_params`` records as plain data) turned into
geometry on its shaped body, once per avatar, on the CPU.

Tight garments, shoes, the hair on the scalp and hat crowns move the body's own vertices
(:mod:`vhgen.body.garments`); skirts, coat hems, a hood, long hair, ponytails, buns, hat
brims and carried things are closed meshes appended to the body's arrays
(:mod:`vhgen.body.drape`, :mod:`vhgen.body.hair`, :mod:`vhgen.body.carried`). Everything
is skinned by the body's rig on the GPU like the body.

Labels: a moved body triangle keeps its own label; an appended triangle takes the label
of the nearest body triangle of the regions it lies over (a skirt's front left panel the
left thigh's, long hair the neck's and upper back's), decided per triangle so part
boundaries stay crisp. A carried thing's triangles have label 0 and the scene class
``carried`` (or, when the config makes them part of the person, the label of the hand or
body part carrying them and the person's class): ``face_classes``.
"""

from __future__ import annotations

import numpy as np

from vhgen.body.carried import carried_part
from vhgen.body.chart import (
    LEG_L,
    LEG_R,
    NECK,
    TORSO,
    BodyChart,
    vertex_normals,
)
from vhgen.body.contact import PRESS_LEFT, PRESS_RIGHT, PUSH_LEGS
from vhgen.body.drape import Fit, Part, hanging_tube
from vhgen.body.garments import (
    FEET,
    displacement,
    face_thickness,
    press_mask,
    tight_layers,
)
from vhgen.body.hair import hair_parts, hat_parts, scalp_thickness
from vhgen.body.mesh import truncate_weights
from vhgen.body.wardrobe import Outfit
from vhgen.geom.primitives import ellipsoid, frame, solid_sheet

LEGS = (LEG_L, LEG_R)


def _dense(joints: np.ndarray, weights: np.ndarray, num_bones: int) -> np.ndarray:
    """(V, B) weights from (V, K) joints and weights (repeated joints add up)."""
    rows = np.repeat(np.arange(len(joints)), joints.shape[1])
    flat = np.bincount(rows * num_bones + joints.reshape(-1).astype(np.int64),
                       weights.reshape(-1), minlength=len(joints) * num_bones)
    return flat.reshape(len(joints), num_bones)


def _skirt_weights(fit: Fit, v: np.ndarray, y_top: float, half: float) -> np.ndarray:
    """Dense weights (N, B) of a hanging tube's vertices. Near the top, the skin's under
    it; below the hip joints more and more the legs': a panel in front of or behind a leg
    follows that leg (the thigh, and below the knee half the shin, as the knee pushes
    cloth), while the cloth between the legs follows both half and half, so in a stride
    it spans the gap like cloth does instead of splitting into two trouser legs."""
    rig = fit.rig
    hip_y = float(rig.heads[rig.index("LeftUpLeg"), 1])
    knee_y = float(rig.heads[rig.index("LeftLeg"), 1])
    ankle_y = float(rig.heads[rig.index("LeftFoot"), 1])
    top = fit.nearest_weights(v, (TORSO,) + LEGS, k=8)
    left = 1.0 / (1.0 + np.exp(-v[:, 0] / max(0.12 * half, 0.01)))[:, None]
    shin = 0.5 * np.clip((knee_y - v[:, 1]) / (knee_y - ankle_y), 0.0, 1.0)[:, None]
    leg = {s: (1 - shin) * fit.bone(f"{s}UpLeg") + shin * fit.bone(f"{s}Leg")
           for s in ("Left", "Right")}
    legs = left * leg["Left"] + (1 - left) * leg["Right"]
    a = 0.95 * np.clip((hip_y - v[:, 1]) / (0.6 * (hip_y - knee_y)), 0.0, 1.0)[:, None]
    low = (1 - a) * fit.bone("Hips") + a * legs
    b = np.clip((min(y_top, hip_y + 0.05) - v[:, 1]) / 0.15, 0.0, 1.0)[:, None]
    return (1 - b) * top + b * low


def _y_at_leg(fit: Fit, leg_t: float) -> float:
    """Rest height of the point ``leg_t`` along the left leg (1 = the ankle)."""
    rig = fit.rig
    nodes = rig.heads[[rig.index(n) for n in ("LeftUpLeg", "LeftLeg", "LeftFoot")]]
    seg = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
    s = np.clip(leg_t, 0.0, 1.0) * seg.sum()
    k = 0 if s <= seg[0] else 1
    f = (s - (0.0 if k == 0 else seg[0])) / seg[k]
    return float(nodes[k, 1] + f * (nodes[k + 1, 1] - nodes[k, 1]))


def _y_at_height(fit: Fit, h: float) -> float:
    rig = fit.rig
    hip_y = float(rig.heads[rig.index("LeftUpLeg"), 1])
    return hip_y + h * (float(rig.heads[rig.index("Neck"), 1]) - hip_y)


def _tube(fit: Fit, name: str, y_top: float, leg_t: float, ease: float, flare: float,
          gap_m: float = 0.0) -> Part:
    skin = fit.region_skin((TORSO,) + LEGS)
    y_bottom = _y_at_leg(fit, leg_t)
    gap = 0.0
    if gap_m > 0:
        front = skin[np.abs(skin[:, 1] - y_top) < 0.03]
        r = float(front[:, 2].max() - 0.5 * (front[:, 2].min() + front[:, 2].max()))
        gap = 2 * np.arctan2(gap_m / 2, max(r, 0.05))
    outer, inner, half, hull = hanging_tube(skin, y_top, y_bottom, ease, flare, cloth=0.006,
                                            gap_angle=gap)
    v, f = solid_sheet(outer, inner, wrap=gap == 0)
    anchor = np.concatenate([hull.reshape(-1, 3), hull.reshape(-1, 3)])
    return Part(name, v, f, _skirt_weights(fit, v, y_top, float(half.max())), (TORSO,) + LEGS,
                offsets=v - anchor)


def _hood(fit: Fit, thickness: float) -> Part:
    rig = fit.rig
    base = rig.heads[rig.index("Neck")]
    skin = fit.region_skin((TORSO, NECK))
    near = skin[(np.abs(skin[:, 1] - (base[1] - 0.04)) < 0.04) & (np.abs(skin[:, 0]) < 0.08)]
    z = float(near[:, 2].min()) - thickness - 0.035
    v, f = ellipsoid(np.array([0.15, 0.085, 0.045]),
                     frame(np.array([0.0, base[1] - 0.05, z]), [0, 1.0, 0.25], [0, 0, 1.0]))
    return Part("hood", v, f, fit.nearest_weights(v, (TORSO, NECK), k=12), (TORSO, NECK))


def outfit_parts(fit: Fit, outfit: Outfit, guide: np.ndarray) -> list[Part]:
    """The appended parts of an outfit, in a fixed order."""
    parts: list[Part] = []
    bottom, outer = outfit.bottom, outfit.outer
    if bottom is not None and bottom.kind == "skirt":
        parts.append(_tube(fit, "skirt", _y_at_height(fit, bottom.rise), bottom.length,
                           bottom.thickness_m, bottom.flare))
    if outer is not None and outer.kind == "coat":
        top_y = _y_at_height(fit, outer.hem + 0.15)
        parts.append(_tube(fit, "coat", top_y, outer.length, outer.thickness_m + 0.01,
                           outer.flare, outer.gap_m if outer.open else 0.0))
    if outer is not None and outer.hood:
        parts.append(_hood(fit, outer.thickness_m))
    hair, hat = outfit.hair, outfit.hat
    if hair is not None:
        parts += hair_parts(fit, guide, hair)
    if hat is not None:
        parts += hat_parts(fit, hat, hair)
    if outfit.carried is not None:
        parts.append(carried_part(fit, outfit.carried))
    return parts


def _soles(fit: Fit, sole: float) -> np.ndarray:
    """(V,) extra offset of the feet's undersides: a shoe's sole."""
    down = np.clip(-fit.normals[:, 1], 0.0, 1.0)
    return np.where(np.isin(fit.chart.region, FEET), sole * down ** 2, 0.0)


def _nearest_labels(fit: Fit, faces: np.ndarray, labels: np.ndarray, part: Part,
                    trees: dict) -> np.ndarray:
    """(m,) the label of the nearest body triangle of the part's regions to each of its
    triangles (rest pose, skin); ``trees`` caches the search trees by region set."""
    from scipy.spatial import cKDTree

    if part.regions not in trees:
        cand = np.flatnonzero(np.isin(fit.chart.face_region, part.regions))
        trees[part.regions] = (cand, cKDTree(fit.skin[faces[cand]].mean(axis=1)))
    cand, tree = trees[part.regions]
    _, near = tree.query(part.vertices[part.faces].mean(axis=1))
    return labels[cand[near]]


def dress_arrays(skin: np.ndarray, faces: np.ndarray, joints: np.ndarray, weights: np.ndarray,
                 labels: np.ndarray, fit: Fit, outfit: Outfit, guide: np.ndarray,
                 ) -> dict[str, np.ndarray]:
    """The body's arrays dressed in ``outfit``.

    skin (V, 3) shaped rest vertices whose first ``len(chart.region)`` are the body's;
    faces (T, 3) whose first ``len(chart.face_region)`` are the body's; joints, weights
    (V, K); labels (T,). Returns ``vertices`` (V', 3) (body vertices moved onto the
    garments, parts appended), ``faces`` (T', 3), ``joints``, ``weights`` (V', K),
    ``face_labels`` (T',) uint8, ``face_classes`` (T',) uint8 (0: the person's class),
    ``offsets`` (V', 3) (vertex - skin under it; 0 off the garments and on parts) and
    ``press`` (V',) uint8 (:func:`vhgen.body.garments.press_mask`; 0 where no offset).
    """
    chart: BodyChart = fit.chart
    nv, nf = len(chart.region), len(chart.face_region)
    body_faces = faces[:nf]
    thickness = face_thickness(tight_layers(chart, outfit), nf)
    thickness += scalp_thickness(chart, outfit.hair, outfit.hat)
    shoes = outfit.shoes
    extra = _soles(fit, shoes.sole_m) if shoes is not None else None
    off_body = displacement(skin[:nv], body_faces, fit.normals, chart, thickness, extra)
    offsets = np.zeros_like(skin)
    offsets[:nv] = off_body
    press = np.zeros(len(skin), np.uint8)
    press[:nv] = np.where(np.abs(off_body).sum(axis=1) > 0, press_mask(chart), 0)
    verts = [skin + offsets]
    all_faces = [faces]
    all_joints, all_weights = [joints], [weights]
    all_labels = [np.asarray(labels, np.uint8)]
    classes = [np.zeros(len(faces), np.uint8)]
    carried = outfit.carried
    n = len(skin)
    trees: dict = {}
    part_offsets, part_press = [], []
    for part in outfit_parts(fit, outfit, guide):
        verts.append(part.vertices)
        off = part.offsets if part.offsets is not None else np.zeros_like(part.vertices)
        part_offsets.append(off)
        # cloth a hand can press in, and that the legs push out (skirts, coat hems)
        part_press.append(np.where(np.abs(off).sum(axis=1) > 0,
                                   PRESS_LEFT | PRESS_RIGHT | PUSH_LEGS, 0))
        all_faces.append(part.faces + n)
        j, w = truncate_weights(part.weights, joints.shape[1])
        all_joints.append(j.astype(joints.dtype))
        all_weights.append(w)
        lab = _nearest_labels(fit, body_faces, np.asarray(labels), part, trees)
        cls = np.zeros(len(part.faces), np.uint8)
        if part.carried and carried is not None and not carried.as_person:
            lab = np.zeros_like(lab)
            cls[:] = int(carried.scene_class)
        elif part.carried:  # all of it the body part that carries it (the hand, not the wrist)
            lab = np.full_like(lab, np.bincount(lab).argmax())
        all_labels.append(lab.astype(np.uint8))
        classes.append(cls)
        n += len(part.vertices)
    out = {"vertices": np.concatenate(verts), "faces": np.concatenate(all_faces),
           "joints": np.concatenate(all_joints), "weights": np.concatenate(all_weights),
           "face_labels": np.concatenate(all_labels), "face_classes": np.concatenate(classes)}
    out["offsets"] = np.concatenate([offsets] + part_offsets)
    out["press"] = np.concatenate([press] + part_press).astype(np.uint8)
    return out


def make_fit(skin: np.ndarray, body_faces: np.ndarray, joints: np.ndarray,
             weights: np.ndarray, rig, chart: BodyChart) -> Fit:
    """The :class:`~vhgen.body.drape.Fit` of a shaped body (``skin`` (V, 3) of its body
    vertices, ``body_faces`` into them, its (V, K) joints and weights)."""
    nv = len(chart.region)
    return Fit(skin[:nv], vertex_normals(skin[:nv], body_faces), _dense(
        joints[:nv], weights[:nv], len(rig.names)), rig, chart)

