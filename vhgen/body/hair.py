"""Hair and hats: a layer on the scalp (a displacement, see :mod:`vhgen.body.garments`)
plus volumes that stand off the head: long hair down the back, a ponytail, a bun, a cap's
brim, a brimmed hat.

The scalp is cut by a hairline drawn in the chart's head coordinates (height on the head
``head_h``, direction ``head_angle``), so it is the same on every avatar. Long hair hangs
from the back of the head as wide as MakeHuman's long-hair helper (``helper-hair``, a
group of the base mesh shaped with the body) and lies on the back below it. Volumes off
the head are bound rigidly to the head bone; long hair turns with the head at the top
and lies on the neck and back further down.
"""

from __future__ import annotations

import numpy as np

from vhgen.body.chart import HEAD, NECK, TORSO, BodyChart
from vhgen.body.drape import Fit, Part, curtain, rigid_part
from vhgen.body.wardrobe import Hair, Hat
from vhgen.geom.primitives import ellipsoid, frame, lathe, solid_sheet

HAIR_KINDS = ("short", "medium", "long", "ponytail", "bun")
HAT_KINDS = ("cap", "beanie", "brimmed")

# hairlines: head_h of the hair's edge by |head_angle| in degrees (front, temple, side
# above the ear, behind the ear, the nape); hair covers the scalp above
_HAIRLINES = {
    "short": ((0, 50, 90, 130, 180), (0.80, 0.74, 0.62, 0.40, 0.26)),
    "medium": ((0, 50, 90, 130, 180), (0.80, 0.70, 0.36, 0.08, -0.12)),
}
# how far down a hat reaches, the same way
_HATLINES = {
    "cap": ((0, 90, 180), (0.70, 0.62, 0.55)),
    "beanie": ((0, 90, 180), (0.66, 0.48, 0.38)),
}


def _line(chart: BodyChart, table: tuple[tuple[float, ...], tuple[float, ...]]
          ) -> np.ndarray:
    angle = np.degrees(np.abs(chart.face_head_angle))
    return np.interp(angle, table[0], table[1])


def _ramp(x: np.ndarray, width: float) -> np.ndarray:
    s = np.clip(x / width, 0.0, 1.0)
    return s * s * (3 - 2 * s)


def scalp_thickness(chart: BodyChart, hair: Hair | None, hat: Hat | None) -> np.ndarray:
    """(T,) thickness per body triangle of the hair on the scalp and the crown of a cap
    or beanie over it (0 elsewhere); thinning to nothing at the hairline."""
    total = np.zeros(len(chart.face_region))
    head = np.isin(chart.face_region, (HEAD, NECK))
    h = chart.face_head_h
    if hair is not None:
        table = _HAIRLINES["medium" if hair.kind in ("medium", "long") else "short"]
        total += np.where(head, hair.volume_m * _ramp(h - _line(chart, table), 0.12), 0.0)
    if hat is not None and hat.kind in _HATLINES:
        over = _ramp(h - _line(chart, _HATLINES[hat.kind]), 0.03)
        total += np.where(head, hat.thickness_m * over, 0.0)
    return total


def _head(fit: Fit) -> tuple[np.ndarray, float, float]:
    """The head's centre on its axis at the head joint's height (3,), the crown's height
    and the skull's radius at mid height."""
    skin = fit.region_skin((HEAD,))
    y0 = float(fit.rig.heads[fit.rig.index("Head"), 1])
    top = float(skin[:, 1].max())
    mid = skin[np.abs(skin[:, 1] - (y0 + 0.6 * (top - y0))) < 0.015]
    cz = 0.5 * (skin[:, 2].min() + skin[:, 2].max())
    radius = float(np.percentile(np.hypot(mid[:, 0], mid[:, 2] - cz), 90)) if len(mid) \
        else 0.09
    return np.array([0.0, y0, cz]), top, radius


def hair_parts(fit: Fit, guide: np.ndarray, hair: Hair) -> list[Part]:
    """The volumes of a hairstyle (none for short and medium hair, which are all scalp)."""
    center, top, radius = _head(fit)
    head_w = fit.bone("Head")
    labels = (HEAD, NECK, TORSO)
    if hair.kind == "long":
        y_top = center[1] + 0.35 * (top - center[1])
        nape = float(fit.rig.heads[fit.rig.index("Neck"), 1])
        skin = fit.region_skin((HEAD, NECK, TORSO))
        behind = guide[guide[:, 2] < center[2] + 0.02]  # the helper's strands down the back
        head = fit.region_skin((HEAD,))
        chin = float(head[:, 1].min())
        half = float(np.abs(head[head[:, 1] > y_top - 0.04][:, 0]).max()) + hair.volume_m
        outer, inner = curtain(skin, behind, np.array([half, chin]), y_top,
                               nape - hair.length_m, hair.volume_m)
        v, f = solid_sheet(outer, inner, wrap=False)
        # turns with the head at the top, lies on the neck and back below the nape
        a = np.clip((y_top - v[:, 1]) / max(y_top - nape + 0.05, 1e-3), 0.0, 1.0)[:, None]
        w = (1 - a) * head_w + a * fit.nearest_weights(v, (NECK, TORSO), k=6)
        return [Part("hair:long", v, f, w, labels)]
    if hair.kind == "ponytail":
        length, r = hair.length_m, hair.radius_m
        root = center + np.array([0.0, 0.55 * (top - center[1]), -radius - 0.3 * r])
        down = np.array([0.0, -1.0, -0.12])
        down = down / np.linalg.norm(down)
        v, f = ellipsoid(np.array([r, length / 2, r * 0.8]),
                         frame(root + down * (length / 2), down, [0, 0, -1.0]))
        # turns with the head at the tie, rests on the neck and back towards its end
        a = 0.7 * np.clip((v - root) @ down / length, 0.0, 1.0)[:, None]
        w = (1 - a) * head_w + a * fit.nearest_weights(v, (NECK, TORSO), k=6)
        return [Part("hair:ponytail", v, f, w, labels)]
    if hair.kind == "bun":
        r = hair.radius_m
        at = center + np.array([0.0, 0.72 * (top - center[1]), -radius - 0.35 * r])
        return [rigid_part("hair:bun", ellipsoid(np.array([r, r * 0.85, r * 0.8]),
                                                 frame(at, [0, 1.0, 0], [0, 0, 1.0])),
                           head_w, labels)]
    return []


def hat_parts(fit: Fit, hat: Hat, hair: Hair | None) -> list[Part]:
    """The parts of a hat that stand off the head: a cap's brim, a brimmed hat."""
    center, top, _ = _head(fit)
    head_w = fit.bone("Head")
    volume = hair.volume_m if hair is not None else 0.0
    skin = fit.region_skin((HEAD,))
    if hat.kind == "cap":
        brim = hat.brim_m
        y = center[1] + 0.7 * (top - center[1])
        front = float(skin[np.abs(skin[:, 1] - y) < 0.015][:, 2].max())
        # its back half under the crown, tipped down a little at the front
        at = np.array([0.0, y, front + volume + brim / 2 - 0.025])
        m = frame(at, [0, 1.0, 0.18], [0, 0, 1.0])
        return [rigid_part("hat:brim", ellipsoid(np.array([0.085, 0.007, brim / 2 + 0.03]), m,
                                                 segments=12, rings=3), head_w, (HEAD,))]
    if hat.kind == "brimmed":
        at = center + np.array([0.0, 0.62 * (top - center[1]), 0.0])
        band = skin[np.abs(skin[:, 1] - at[1]) < 0.015]
        rc = float(np.percentile(np.hypot(band[:, 0], band[:, 2] - center[2]), 85)) + volume
        rb = rc + hat.brim_m
        h = (top - at[1]) + volume + hat.crown_m
        profile = np.array([[0.0, -0.005], [rb, -0.005], [rb, 0.004], [rc, 0.004],
                            [rc, h], [rc * 0.85, h + 0.012], [0.0, h + 0.012]])
        return [rigid_part("hat:brimmed", lathe(profile, frame(at, [0, 1.0, 0], [0, 0, 1.0]),
                                                segments=20), head_w, (HEAD,))]
    return []

