"""The fidelity scene suite: exact analytic frames (planes, tilted planes, step edges, thin
rods) and, through GL, a posed human in front of a wall.

Analytic objects are rectangles on planes z = z0 + s * X (s = tan of the tilt about the
vertical axis), bounded in X and Y; each pixel's ray is cast from the camera and, for the
projector view, from the projector at +baseline along x, so shadows are exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vhgen.body.avatar import build_body
from vhgen.body.labels import LabelScheme
from vhgen.body.skinning import bone_matrices, posed_heads
from vhgen.camera import CameraPose, Intrinsics, look_at, pixel_rays
from vhgen.errors import RenderError
from vhgen.mocap.bvh import read_bvh
from vhgen.mocap.retarget import build_retargeter, detect_dialect, load_all_maps
from vhgen.render.renderer import DepthLabelRenderer
from vhgen.render.scene_renderer import SceneRenderer
from vhgen.scene.description import FrameDescription, Person
from vhgen.scene.geometry import WALL, StaticMesh, quad


@dataclass(frozen=True)
class Rect:
    z0: float
    slope: float = 0.0  # dz/dX
    x: tuple[float, float] = (-np.inf, np.inf)
    y: tuple[float, float] = (-np.inf, np.inf)
    label: int = 1


@dataclass
class Frame:
    """A rendered frame: what the sensor model takes, plus the truth."""

    name: str
    kind: str
    depth: np.ndarray  # (H, W) float64 planar depth, 0 = no hit
    labels: np.ndarray  # (H, W) uint8 object ids
    incidence: np.ndarray  # (H, W) |cos|, surface normal vs viewing ray
    projector_depth: np.ndarray  # (H, W) as seen from the projector
    info: dict


def cast(intr: Intrinsics, rects: list[Rect], origin_x: float = 0.0):
    """Planar depth, labels and incidence (|cos| of the angle between surface normal and
    viewing ray) of ``rects`` seen from (origin_x, 0, 0)."""
    rays = pixel_rays(intr)
    dx, dy = rays[..., 0], rays[..., 1]
    depth = np.zeros(dx.shape)
    labels = np.zeros(dx.shape, np.uint8)
    incidence = np.zeros(dx.shape)
    unit = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    for r in rects:
        den = 1.0 - r.slope * dx
        t = np.where(np.abs(den) > 1e-12, (r.z0 + r.slope * origin_x) / np.where(
            np.abs(den) > 1e-12, den, 1.0), -1.0)
        xw = origin_x + t * dx
        yw = t * dy
        hit = (t > 0) & (xw >= r.x[0]) & (xw <= r.x[1]) & (yw >= r.y[0]) & (yw <= r.y[1])
        closer = hit & ((depth == 0) | (t < depth))
        depth = np.where(closer, t, depth)
        labels = np.where(closer, r.label, labels).astype(np.uint8)
        n = np.array([r.slope, 0.0, -1.0]) / np.hypot(r.slope, 1.0)
        incidence = np.where(closer, np.abs(unit @ n), incidence)
    return depth, labels, incidence


def analytic_frame(name: str, kind: str, intr: Intrinsics, baseline: float, rects: list[Rect],
                   **info) -> Frame:
    depth, labels, incidence = cast(intr, rects)
    proj, _, _ = cast(intr, rects, origin_x=baseline)
    return Frame(name, kind, depth, labels, incidence, proj, info)


def suite(intr: Intrinsics, baseline: float, quick: bool = False) -> list[Frame]:
    """The analytic scenes; ``quick`` keeps one of each kind."""
    f = intr.fx
    frames = []
    for z in ((2.0,) if quick else (0.8, 1.0, 1.5, 2.0, 3.0, 3.9)):
        frames.append(analytic_frame(f"plane {z} m", "plane", intr, baseline, [Rect(z)],
                                     z=z))
    for deg in (() if quick else (30.0, 60.0, 75.0)):
        frames.append(analytic_frame(f"plane 2 m tilted {deg:.0f} deg", "tilted", intr,
                                     baseline, [Rect(2.0, np.tan(np.deg2rad(deg)))],
                                     tilt_deg=deg, z=2.0))
    for zf, zb in (((1.0, 3.0),) if quick else ((1.0, 1.3), (1.0, 2.0), (1.0, 3.0),
                                               (2.0, 3.5))):
        frames.append(analytic_frame(
            f"step {zf}/{zb} m", "step", intr, baseline,
            [Rect(zb, label=1), Rect(zf, x=(0.0, np.inf), label=2)], z_front=zf, z_back=zb,
            edge_col=intr.cx, shadow_px=f * baseline * (1 / zf - 1 / zb)))
    widths = (2, 4, 8, 15) if quick else (1, 2, 4, 8, 15)
    rects = [Rect(3.0, label=1)]
    centers = np.linspace(-0.6, 0.6, len(widths))
    for k, (wpx, cxm) in enumerate(zip(widths, centers, strict=True)):
        half = wpx * 2.0 / f / 2
        rects.append(Rect(2.0, x=(cxm - half, cxm + half), y=(-0.5, 0.5), label=2 + k))
    frames.append(analytic_frame("thin rods 2 m on 3 m wall", "rods", intr, baseline, rects,
                                 widths_px=list(widths)))
    return frames


def human_frame(ctx, intr: Intrinsics, baseline: float, asset_dir, motion_path,
                frame: int = 100, distance: float = 2.5, wall: float | None = 3.5) -> Frame:
    """A posed MakeHuman body in front of a wall facing the camera at ``wall`` metres
    (``wall=None``: alone), drawn through the pipeline's render step
    (:class:`~vhgen.render.scene_renderer.SceneRenderer`): person and wall in one target."""
    body = build_body(asset_dir, LabelScheme.load("shotton31"))
    motion = read_bvh(motion_path)
    rt = build_retargeter(motion, body.rig, detect_dialect(motion, load_all_maps()))
    rot, root = rt.apply(motion, frames=np.array([frame]))
    root = root[0] - np.array([root[0, 0], 0.0, root[0, 2]])
    person = Person(1, 0, 0, bone_matrices(body.rig, rot[0], root),
                    posed_heads(body.rig, rot[0], root), np.zeros(3))
    w2c = look_at(np.array([0, 1.0, distance]), np.array([0, 0.9, 0]))
    static: tuple[StaticMesh, ...] = ()
    if wall is not None:  # a quad far wider than the view, at camera depth ``wall``
        c2w = np.linalg.inv(w2c)
        h = 50.0
        corners = np.array([[-h, -h, wall], [h, -h, wall], [h, h, wall], [-h, h, wall]])
        static = (quad(corners @ c2w[:3, :3].T + c2w[:3, 3], WALL, "wall"),)
    desc = FrameDescription(frame, 0, CameraPose(w2c, 0.0, distance, 1.0), (person,), static,
                            None, np.random.PCG64(0).state)
    ren = DepthLabelRenderer(ctx, intr, incidence=True)
    scene = SceneRenderer(ren, lambda _avatar: body)
    views = scene.render(desc, projector_baseline_m=baseline)
    scene.release()
    ren.release()
    cam, proj = views.camera, views.projector_depth
    if cam.incidence is None or proj is None:
        raise RenderError("the renderer returned no incidence or no projector view")
    name = f"human {distance} m" + (f", wall {wall} m" if wall is not None else " alone")
    return Frame(name, "human", cam.depth.astype(np.float64), cam.labels,
                 cam.incidence.astype(np.float32), proj.astype(np.float64),
                 {"motion": str(motion_path), "frame": frame})
