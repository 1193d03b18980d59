"""Where garments meet the body in a pose: hands press cloth in, legs push skirts out.

Garments are built once per avatar in the rest pose and skinned with it, so in a pose a
hand that rests on a coat would sink into it (the coat stands off the skin by its
thickness), and a knee in a stride or a squat would come out through a skirt. The
renderer's garment program (``vhgen/render/shaders/skin.vert``) corrects both per vertex
and per frame, with these shapes posed by the frame's bones:

* each hand is a flattened capsule along the palm: a garment vertex near it is moved
  back towards the skin under it (``offsets``: the vertex minus that skin point), no
  further than the hand's underside; a sleeve is never pressed by its own hand;
* each thigh and shin is a tapered capsule fitted to the avatar's skin: a loose cloth
  vertex inside one is moved out to its surface plus the cloth's thickness (unless a
  hand presses it).

:func:`dressed_positions` is the same computation in float64 NumPy (the reference the
tests measure; the shader must draw what it computes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vhgen.body.mesh import Rig

PRESS_LEFT, PRESS_RIGHT, PUSH_LEGS = 1, 2, 4  # bits of a vertex's contact mask
LEG_BONES = ("LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg")
CLOTH_MARGIN_M = 0.008  # how far outside a leg's capsule pushed cloth ends up
LEG_PERCENTILE = 60  # a leg capsule's radius: this percentile of its skin's distance


@dataclass(frozen=True, eq=False)
class Contacts:
    """The contact shapes of one avatar, rest pose, the body's frame (metres).

    Hands (left, right): ``hand_bones`` (2,), segment ``hand_a`` -> ``hand_b`` (2, 3)
    along the palm, unit ``hand_lateral`` (2, 3) across it (towards the thumb), half
    thickness ``hand_radius`` (2,) and ``hand_width`` (2,), half width over half
    thickness. Legs (:data:`LEG_BONES`): ``leg_bones`` (4,), axis ``leg_a`` -> ``leg_b``
    (4, 3), radius at each end ``leg_ra``, ``leg_rb`` (4,).
    """

    hand_bones: np.ndarray
    hand_a: np.ndarray
    hand_b: np.ndarray
    hand_lateral: np.ndarray
    hand_radius: np.ndarray
    hand_width: np.ndarray
    leg_bones: np.ndarray
    leg_a: np.ndarray
    leg_b: np.ndarray
    leg_ra: np.ndarray
    leg_rb: np.ndarray

    def posed(self, matrices: np.ndarray) -> dict[str, np.ndarray]:
        """The shapes moved by (B, 4, 4) bone matrices: ``hand_a``, ``hand_b``,
        ``hand_lateral``, ``leg_a``, ``leg_b`` in the matrices' frame, float64 (one
        product for all twelve points and two directions: it runs once per draw)."""
        m = np.asarray(matrices, np.float64)
        bones = np.concatenate([self.hand_bones, self.hand_bones, self.hand_bones,
                                self.leg_bones, self.leg_bones])
        pts = np.concatenate([self.hand_a, self.hand_b, self.hand_lateral, self.leg_a,
                              self.leg_b])
        w = np.ones(len(pts))
        w[4:6] = 0.0  # the lateral axes are directions
        mb = m[bones]
        out = (mb[:, :3, :3] @ pts[:, :, None])[:, :, 0] + mb[:, :3, 3] * w[:, None]
        return {"hand_a": out[0:2], "hand_b": out[2:4], "hand_lateral": out[4:6],
                "leg_a": out[6:10], "leg_b": out[10:14]}


def body_contacts(rig: Rig, skin: np.ndarray, joints: np.ndarray) -> Contacts:
    """The contact shapes of a body: hands from its rig (sized by each hand's length,
    wrist to fingertip: ~2 cm half thickness and ~4.5 cm half width for a 12.5 cm hand),
    legs from its ``skin`` (V, 3) rest positions and (V, K) ``joints`` (the first is the
    dominant bone): each leg bone's capsule has, at each end, the :data:`LEG_PERCENTILE` of its
    skin's distance from the bone (smaller than the leg, so cloth resting on the skin is
    left alone)."""
    hb, ha, hbb, lat, rad = [], [], [], [], []
    for s, t in (("Left", "L"), ("Right", "R")):
        wrist = rig.heads[rig.index(f"{s}Hand")]
        tip = rig.tails[rig.index(f"{s}HandFinger1")]
        thumb = rig.heads[rig.index(f"{t}Thumb")]
        axis = tip - wrist
        length = float(np.linalg.norm(axis))
        d = axis / length
        side = (thumb - wrist) - d * float(np.dot(thumb - wrist, d))
        hb.append(rig.index(f"{s}Hand"))
        ha.append(wrist + 0.2 * axis)
        hbb.append(wrist + 0.75 * axis)
        lat.append(side / max(float(np.linalg.norm(side)), 1e-9))
        rad.append(0.16 * length)
    lb, la, lbb, ra, rb = [], [], [], [], []
    dominant = np.asarray(joints)[:, 0]
    for name in LEG_BONES:
        k = rig.index(name)
        a, b = rig.heads[k], rig.tails[k]
        ab = b - a
        pts = skin[dominant == k]
        s = np.clip((pts - a) @ ab / float(ab @ ab), 0.0, 1.0)
        dist = np.linalg.norm(pts - (a + s[:, None] * ab), axis=1)
        lo, hi = dist[s < 0.3], dist[s > 0.7]
        lb.append(k)
        la.append(a)
        lbb.append(b)
        ra.append(float(np.percentile(lo, LEG_PERCENTILE)) if len(lo) else 0.0)
        rb.append(float(np.percentile(hi, LEG_PERCENTILE)) if len(hi) else 0.0)
    return Contacts(np.array(hb), np.array(ha), np.array(hbb), np.array(lat), np.array(rad),
                    np.full(2, 2.3), np.array(lb), np.array(la), np.array(lbb), np.array(ra),
                    np.array(rb))


def hand_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, lateral: np.ndarray,
                  width: float) -> np.ndarray:
    """(N,) distance of points (N, 3) from the segment a -> b, with the component along
    ``lateral`` divided by ``width`` (a flattened capsule's "radius" units)."""
    ab = b - a
    s = np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    q = p - (a + s[:, None] * ab)
    across = q @ lateral
    normal = q - across[:, None] * lateral
    return np.sqrt(np.einsum("ij,ij->i", normal, normal) + (across / width) ** 2)


def push_out(p: np.ndarray, a: np.ndarray, b: np.ndarray, ra: float, rb: float
             ) -> np.ndarray:
    """Points (N, 3) inside the tapered capsule a -> b (radius ``ra`` at a, ``rb`` at b,
    plus :data:`CLOTH_MARGIN_M`) moved out to its surface along the radius."""
    ab = b - a
    s = np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    c = a + s[:, None] * ab
    q = p - c
    d = np.linalg.norm(q, axis=1)
    r = ra + (rb - ra) * s + CLOTH_MARGIN_M
    out = np.where((d < r)[:, None], c + q * (r / np.maximum(d, 1e-6))[:, None], p)
    return out


def dressed_positions(vertices: np.ndarray, offsets: np.ndarray, mask: np.ndarray,
                      joints: np.ndarray, weights: np.ndarray, matrices: np.ndarray,
                      contacts: Contacts) -> np.ndarray:
    """Where the garment program draws a dressed body's vertices (V, 3) float64 with
    linear blend skinning by (B, 4, 4) ``matrices``: skin = vertices - offsets skinned,
    offsets turned by the blended rotation, pressed in by the hands and pushed out of the
    legs as ``mask`` (V,) allows (see the module)."""
    from vhgen.body.skin_kernels import skin_points

    m = np.asarray(matrices, np.float64)
    skin = skin_points(np.asarray(vertices, np.float64) - offsets, joints, weights, m)
    blend = np.einsum("vk,vkij->vij", weights, m[joints, :3, :3])
    off = np.einsum("vij,vj->vi", blend, offsets)
    t = np.linalg.norm(offsets, axis=1)
    posed = contacts.posed(m)
    scale = np.ones(len(skin))
    has = t > 0
    for k, bit in enumerate((PRESS_LEFT, PRESS_RIGHT)):
        sel = has & ((mask & bit) != 0)
        d = hand_distance(skin[sel], posed["hand_a"][k], posed["hand_b"][k],
                          posed["hand_lateral"][k], float(contacts.hand_width[k]))
        scale[sel] = np.minimum(scale[sel], np.clip(
            (d - contacts.hand_radius[k]) / t[sel], 0.0, 1.0))
    p = skin + scale[:, None] * off
    sel = ((mask & PUSH_LEGS) != 0) & (scale >= 1.0)  # a hand pressing the cloth keeps it in
    for k in range(len(contacts.leg_bones)):
        p[sel] = push_out(p[sel], posed["leg_a"][k], posed["leg_b"][k],
                          float(contacts.leg_ra[k]), float(contacts.leg_rb[k]))
    return p
