"""People on a real background's free floor, per frame (pure, from the frame's scene
stream): :func:`layout_background` draws a background of the job's
(:mod:`vhgen.scene.background.load`) and places the people on its free floor, in view past
its real surfaces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from vhgen.camera import CameraPose, Intrinsics, pitch_roll_deg, project
from vhgen.errors import BackgroundError
from vhgen.scene.background.background_frame import PlacedBackground
from vhgen.scene.background.floor import CELL_M, reachable
from vhgen.scene.background.load import Backgrounds
from vhgen.scene.description import Person
from vhgen.scene.placement import GAP_M, PLACEMENT_TRIES, Disc, all_visible, yaw_transform
from vhgen.scene.scene_config import SceneConfig
from vhgen.scene.truth import VISIBILITY_TOLERANCE_M

if TYPE_CHECKING:
    from vhgen.scene.layout import People

BACKGROUND_DRAWS = 8  # backgrounds tried for the plan's person before another is drawn
SUBSTITUTES = 8  # people drawn in its place when it fits no background drawn


@dataclass(frozen=True, eq=False)
class BackgroundLayout:
    """What a background frame holds: the background, its camera, the people placed on
    its floor (instance order), what did not fit, and the plan's person when another took
    its place (``planned``: avatar id and pose index; None when it was placed)."""

    background: PlacedBackground
    camera: CameraPose
    people: tuple[Person, ...]
    dropped: dict[str, int] = field(default_factory=dict)
    planned: tuple[int, int] | None = None


def real_visible_fraction(intr: Intrinsics, joints_cam: np.ndarray,
                          depth_mm: np.ndarray) -> float:
    """The fraction of joints (J, 3 camera frame) in the image and not behind a real
    surface: the real depth at the joint's pixel is no measurement, or at least z -
    VISIBILITY_TOLERANCE_M (the test of :func:`vhgen.scene.truth.joint_visibility`)."""
    uv = project(intr, joints_cam)
    ok = np.isfinite(uv).all(1)
    px = np.where(ok[:, None], np.rint(np.nan_to_num(uv)), -1).astype(np.int64)
    ok &= (px[:, 0] >= 0) & (px[:, 0] < intr.width) & (px[:, 1] >= 0) & (px[:, 1] < intr.height)
    real = depth_mm[np.where(ok, px[:, 1], 0), np.where(ok, px[:, 0], 0)] / 1000.0
    clear = (real == 0) | (real >= joints_cam[:, 2] - VISIBILITY_TOLERANCE_M)
    return float((ok & clear).mean())


class _Floor:
    """One background's free floor during a frame's placement."""

    def __init__(self, bgs: Backgrounds, index: int, intr: Intrinsics,
                 reach: tuple[float, float], min_visible: float):
        self.bg = bgs.get(index)
        self.intr = intr
        self.w2c = self.bg.floor.world_to_camera()
        self.origin = bgs.origins[index]
        self.clearance = bgs.clearance[index]
        self.reachable = reachable(self.origin, self.clearance, reach)
        self.min_visible = min_visible
        self.discs: list[Disc] = []

    def place(self, rng: np.random.Generator, local: Person, heading: float,
              instance: int) -> Person | None:
        """``local`` (posed at the origin, with its footprint) turned by ``heading`` and
        put on a free spot: its footprint within the free floor and GAP_M clear of the
        people already placed, at least ``min_visible`` of its joints in view past real
        surfaces, and every person at least ``min_visible`` of its width in view past the
        others (:func:`vhgen.scene.placement.visible_fraction`). PLACEMENT_TRIES spots are
        drawn among the cells that fit and tried in order; None when none passes."""
        fp = local.footprint
        assert fp is not None
        jitter = math.sqrt(0.5) * CELL_M  # a spot moves up to this far from its cell centre
        fits = self.reachable & (self.clearance >= math.ceil((fp.r + GAP_M + jitter) * 100))
        zz, xx = np.nonzero(fits)
        cx = self.origin[0] + xx * CELL_M
        cz = self.origin[1] + zz * CELL_M
        for d in self.discs:
            far = np.hypot(cx - d.x, cz - d.z) >= fp.r + d.r + GAP_M + jitter
            cx, cz = cx[far], cz[far]
        if not len(cx):
            return None
        pick = rng.integers(len(cx), size=PLACEMENT_TRIES)
        offset = rng.uniform(-0.5, 0.5, size=(PLACEMENT_TRIES, 2)) * CELL_M
        eye = np.zeros(2)
        centre = yaw_transform(0.0, -fp.x, -fp.z)
        for k, (dx, dz) in zip(pick, offset, strict=True):
            spot = Disc(float(cx[k] + dx), float(cz[k] + dz), fp.r)
            t = yaw_transform(heading, spot.x, spot.z) @ centre
            joints = local.joints @ t[:3, :3].T + t[:3, 3]
            cam = joints @ self.w2c[:3, :3].T + self.w2c[:3, 3]
            if real_visible_fraction(self.intr, cam, self.bg.depth_mm) < self.min_visible:
                continue
            everyone = [*self.discs, spot]
            if not all_visible(eye, everyone, len(everyone), self.min_visible):
                continue
            self.discs.append(spot)
            return Person(instance, local.avatar_id, local.pose_index, t @ local.bones,
                          joints, local.offset, t, spot)
        return None


def layout_background(rng: np.random.Generator, scene: SceneConfig, bgs: Backgrounds,
                      intr: Intrinsics, reach: tuple[float, float], first: Person,
                      people_from: People) -> BackgroundLayout:
    """One background frame, from the scene stream ``rng``: the number of people, then
    the background and the plan's person ``first`` (posed at the origin, with its
    footprint) on its free floor, up to BACKGROUND_DRAWS backgrounds (a heading each);
    when it fits none, up to SUBSTITUTES people drawn from ``people_from`` take its place
    (it counts as dropped); then each further person as
    :func:`vhgen.scene.layout.layout_scene` draws them (avatar, pose, heading), on the
    same background, or dropped and counted. ``reach``: the people's distance from the
    camera on the floor (m)."""
    n_people = int(rng.integers(scene.people[0], scene.people[1] + 1))
    dropped = {"people": 0, "props": 0}
    planned = None
    floor, placed = None, None
    for k in range(SUBSTITUTES + 1):
        local, draws = first, BACKGROUND_DRAWS
        if k:  # the plan's person fits no background drawn: another takes its place
            a = int(rng.integers(people_from.num_avatars))
            pose = int(rng.integers(people_from.num_poses))
            local, draws = people_from.pose(1, a, pose), 2
        for _ in range(draws):
            floor = _Floor(bgs, int(rng.integers(len(bgs))), intr, reach,
                           scene.min_visible_fraction)
            placed = floor.place(rng, local, float(rng.uniform(-np.pi, np.pi)), 1)
            if placed is not None:
                break
        if placed is not None:
            if k:
                dropped["people"] += 1
                planned = (first.avatar_id, first.pose_index)
            break
    if placed is None or floor is None:
        raise BackgroundError("scene.backgrounds", f"no person fits the free floor "
                              f"{reach[0]:g}-{reach[1]:g} m from the camera "
                              f"(camera.distance_m) of {BACKGROUND_DRAWS + 2 * SUBSTITUTES} "
                              "backgrounds drawn for the plan's person and "
                              f"{SUBSTITUTES} others")
    people = [placed]
    for k in range(2, n_people + 1):
        a = int(rng.integers(people_from.num_avatars))
        pose = int(rng.integers(people_from.num_poses))
        heading = float(rng.uniform(-np.pi, np.pi))
        p = floor.place(rng, people_from.pose(k, a, pose), heading, len(people) + 1)
        if p is None:
            dropped["people"] += 1
        else:
            people.append(p)
    w2c = floor.w2c
    pitch, roll = pitch_roll_deg(w2c)
    fp = people[0].footprint
    assert fp is not None
    camera = CameraPose(w2c, float(np.degrees(np.arctan2(fp.x, fp.z))),
                        float(np.hypot(fp.x, fp.z)), floor.bg.floor.height_m, pitch, roll)
    return BackgroundLayout(floor.bg, camera, tuple(people), dropped, planned)
