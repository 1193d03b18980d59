"""Pose ground truth from a rendered frame (pure): 2D joints and per-joint visibility."""

from __future__ import annotations

import numpy as np

from vhgen.camera import Intrinsics, project

# A joint (a bone head, inside the body) counts as visible when the surface rendered at
# its pixel is this person's and lies at most this far in front of it: about the depth
# of flesh over a joint. A limb of the same person crossing in front (farther than this)
# or anyone / anything else at the pixel hides it.
VISIBILITY_TOLERANCE_M = 0.15


def joint_visibility(intr: Intrinsics, points_cam: np.ndarray, instance: int,
                     depth: np.ndarray, instances: np.ndarray,
                     tolerance_m: float = VISIBILITY_TOLERANCE_M) -> np.ndarray:
    """(J,) bool: in the image (the rounded pixel lies inside, z > 0) and not occluded:
    the rendered ``instances`` (H, W) at that pixel is ``instance`` and the rendered
    planar ``depth`` (H, W) metres is at least z - ``tolerance_m``."""
    uv = project(intr, points_cam)
    ok = np.isfinite(uv).all(1)
    px = np.where(ok[:, None], np.rint(np.nan_to_num(uv)), -1).astype(np.int64)
    ok &= (px[:, 0] >= 0) & (px[:, 0] < intr.width) & (px[:, 1] >= 0) & (px[:, 1] < intr.height)
    u, v = np.where(ok, px[:, 0], 0), np.where(ok, px[:, 1], 0)
    z = np.asarray(points_cam, np.float64)[:, 2]
    return ok & (instances[v, u] == instance) & (depth[v, u] >= z - tolerance_m)
