"""Carried things: bags (on the shoulder, on the back, in a hand) and objects held in a
hand (a cup, a phone, a box), bound rigidly to the bone that carries them.

Each is a closed mesh placed on the shaped body in its rest pose: a shoulder bag at the
hip (bound to the pelvis), a backpack on the upper back (the chest bone), a hand bag
hanging from the fingers along the hand's axis, and held things on the palm. The hand's
frame comes from the rig: its axis from the wrist to the fingertips, the thumb's side,
and the palm normal across them (a left palm faces forward when the thumb points left).
"""

from __future__ import annotations

import numpy as np

from vhgen.body.chart import HAND_L, HAND_R, LEG_L, LEG_R, TORSO
from vhgen.body.drape import Fit, Part, rigid_part
from vhgen.body.wardrobe import Carried
from vhgen.geom.primitives import box, frame, lathe

CARRIED_KINDS = ("shoulder_bag", "backpack", "hand_bag", "cup", "phone", "box")
SIDED = ("shoulder_bag", "hand_bag", "cup", "phone", "box")


def hand_frame(fit: Fit, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                              np.ndarray, str]:
    """Rest-pose palm centre (3,), unit finger direction, thumb side and palm normal, and
    the hand bone's name, for ``side`` "left" or "right" (the subject's own)."""
    rig = fit.rig
    s = "Left" if side == "left" else "Right"
    wrist = rig.heads[rig.index(f"{s}Hand")]
    tip = rig.tails[rig.index(f"{s}HandFinger1")]
    thumb = rig.heads[rig.index(f"{side[0].upper()}Thumb")]
    d = (tip - wrist) / np.linalg.norm(tip - wrist)
    lateral = (thumb - wrist) - d * float(np.dot(thumb - wrist, d))
    lateral /= max(np.linalg.norm(lateral), 1e-9)
    palm = np.cross(d, lateral) * (1.0 if side == "left" else -1.0)
    centre = wrist + 0.45 * (tip - wrist)
    return centre, d, lateral, palm, f"{s}Hand"


def _oriented(origin: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    return m


def carried_part(fit: Fit, item: Carried) -> Part:
    """The mesh of one carried thing (see :mod:`vhgen.body.wardrobe` for the parameters)."""
    kind = item.kind
    size = np.array([item.width_m, item.height_m, item.depth_m])
    rig = fit.rig
    if kind == "backpack":
        y = float(rig.heads[rig.index("LeftShoulder"), 1]) - size[1] / 2 - 0.03
        back = fit.region_skin((TORSO,))
        band = back[np.abs(back[:, 1] - y) < size[1] / 2]
        band = band[np.abs(band[:, 0]) < size[0] / 2]
        z = float(band[:, 2].min()) - size[2] / 2 - 0.01
        m = frame(np.array([0.0, y, z]), [0, 1.0, 0], [0, 0, 1.0])
        return rigid_part(kind, box(size, m), fit.bone("Spine1"), (TORSO,), True)
    side = item.side
    if side is None:
        raise ValueError(f"a carried {kind} needs a side")
    sign = 1.0 if side == "left" else -1.0
    if kind == "shoulder_bag":
        y = float(rig.heads[rig.index("LeftUpLeg"), 1]) + 0.02
        hips = fit.region_skin((TORSO, LEG_L, LEG_R))
        band = hips[np.abs(hips[:, 1] - y) < 0.05]
        x = sign * (float(np.abs(band[:, 0]).max()) + size[2] / 2 + 0.01)
        m = _oriented(np.array([x, y, 0.04]), np.array([0, 0, -sign]), np.array([0, 1.0, 0]),
                      np.array([sign, 0, 0]))
        return rigid_part(kind, box(size, m), fit.bone("Hips"), (TORSO, LEG_L, LEG_R), True)
    centre, d, lateral, palm, bone = hand_frame(fit, side)
    hand = (HAND_L,) if side == "left" else (HAND_R,)
    tip = rig.tails[rig.index(f"{'Left' if side == 'left' else 'Right'}HandFinger1")]
    if kind == "hand_bag":
        # hangs in line with the forearm below the fingers
        s = "Left" if side == "left" else "Right"
        arm = tip - rig.heads[rig.index(f"{s}ForeArm")]
        arm /= np.linalg.norm(arm)
        across = lateral - arm * float(np.dot(lateral, arm))
        across /= np.linalg.norm(across)
        at = tip + arm * (size[1] / 2 + 0.01)
        m = _oriented(at, across, arm, np.cross(across, arm))
        return rigid_part(kind, box(size, m), fit.bone(bone), hand, True)
    if kind == "phone":
        at = centre + palm * (size[2] / 2 + 0.012)
        return rigid_part(kind, box(size, _oriented(at, np.cross(d, palm), d, palm)),
                          fit.bone(bone), hand, True)
    if kind == "box":
        e = item.size_m
        dims = np.array([e, e * 0.8, e * 0.6])
        at = centre + palm * (dims[2] / 2 + 0.012)
        return rigid_part(kind, box(dims, _oriented(at, np.cross(d, palm), d, palm)),
                          fit.bone(bone), hand, True)
    if kind == "cup":
        r, h = item.radius_m, item.height_m
        profile = np.array([[0.0, -h / 2], [r * 0.8, -h / 2], [r, h / 2], [0.0, h / 2]])
        at = centre + palm * (r + 0.012)
        # the cup's axis runs across the palm, its fingers wrap round it
        m = _oriented(at, d, lateral, np.cross(d, lateral))
        return rigid_part(kind, lathe(profile, m, segments=14), fit.bone(bone), hand, True)
    raise ValueError(f"unknown carried kind {kind!r}")
