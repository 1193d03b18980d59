"""The sensor over a real background: synthetic pixels and their surroundings sensed as
in a room, real pixels keeping their real measurement and holes.

A composited frame is the real depth frame with people rendered into it (the renderer
keeps a person's pixel only where it is nearer than the real surface). Running the sensor
model on it as it is would re-sense the real pixels (noise on noise, holes on holes);
keeping them as they are would lose what the people do to them: the projector shadow a
person casts on the wall behind, the holes and splats the correlation window leaves on
both sides of a silhouette, the IR camera's occlusion band. :func:`simulate_over_real`
decides which real pixels the people change by running the sensor twice with the same
random draws: on the composite (pass A) and on the real frame alone (pass B). A real
pixel whose output differs between the two (it became a hole, or its value moved) takes
pass A's output; every other real pixel keeps the real frame's value, byte for byte.
Synthetic pixels take pass A's output. Since both passes use the same draws at the same
pixels, a difference can only come from the people; to rule out the last rounding
differences far away (the correlation window's summed-area tables span the image), only
pixels within :func:`reach_px` of a synthetic pixel may change.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from vhgen.sensor.effects import CorrelationWindow, Registration, SpeckleFilter
from vhgen.sensor.sensor_kernels import encode_raw11
from vhgen.sensor.simulator import FrameSensor, SensorOutput

# how far (px) any shipped effect but the shadow bands reaches from a pixel: the
# correlation window's half width and splat radius (at most 15 + 10 px) and lateral noise
REACH_PAD_PX = 32
REAL_HOLE = "real"  # hole cause of a real pixel the real sensor did not measure


def real_depth_m(depth_mm: np.ndarray) -> np.ndarray:
    """(H, W) float32 metres of a real uint16 mm frame (0 = no measurement): the one
    conversion both the renderer's depth test and the sensor passes use, so the two agree
    to the bit."""
    return (np.asarray(depth_mm, np.float64) / 1000.0).astype(np.float32)


def reach_px(model: FrameSensor, z_near_m: float) -> tuple[int, int]:
    """(rows, columns): how far from a surface at ``z_near_m`` or farther the shipped
    effects can change other pixels: the projector shadow (f b / z px) and the IR
    camera's occlusion band (f |offset| / z px) sideways, the correlation window and
    lateral noise (:data:`REACH_PAD_PX`) both ways."""
    cfg = model.cfg
    offset = sum(abs(e.ir_offset_m) for e in cfg.effects if isinstance(e, Registration))
    window = max([e.window // 2 + math.ceil(e.splat_radius_px) for e in cfg.effects
                  if isinstance(e, CorrelationWindow)], default=0)
    pad = max(REACH_PAD_PX, window + 8)
    side = cfg.intrinsics.fx * (cfg.baseline_m + offset) / max(z_near_m, 1e-3)
    return pad, pad + math.ceil(side)


def _near(mask: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """Pixels within ``rows`` rows and ``cols`` columns of a ``mask`` pixel (a box
    dilation, separable)."""
    from scipy import ndimage

    m = ndimage.maximum_filter1d(mask.view(np.uint8), 2 * cols + 1, axis=1)
    return ndimage.maximum_filter1d(m, 2 * rows + 1, axis=0).astype(bool)


def _islands(cfg, valid: np.ndarray, zone: np.ndarray) -> np.ndarray | None:
    """With a ``speckle_filter`` in the sensor: the valid islands of the composed frame
    that it would remove (4-connected, at most its area) lying wholly within ``zone``, or
    None. Real pixels the people's holes cut off from the rest become such islands when
    the sensor, in both passes, had already dropped their neighbours at a real edge (the
    real frame measured them): the device's output holds no islands, so they go too."""
    areas = [e.max_area_px for e in cfg.effects if isinstance(e, SpeckleFilter)]
    if not areas:
        return None
    from scipy import ndimage

    lab, n = ndimage.label(valid, structure=ndimage.generate_binary_structure(2, 1))
    if not n:
        return None
    small = np.bincount(lab.reshape(-1), minlength=n + 1) <= max(areas)
    small[np.unique(lab[~zone])] = False  # islands reaching out of the zone stay
    small[0] = False
    return small[lab]


def simulate_over_real(model: FrameSensor, depth: np.ndarray, rng: np.random.Generator | None,
                       *, real_mm: np.ndarray, labels: np.ndarray, real_label: int,
                       incidence: np.ndarray | None = None) -> SensorOutput:
    """The sensor on a composited frame (see the module docstring).

    depth : (H, W) float32 metres, the composite: the people where the renderer kept
        them, :func:`real_depth_m` of ``real_mm`` elsewhere (holes 0).
    real_mm : (H, W) uint16 the real frame. labels : (H, W) uint32 packed ids, where every
        real pixel (holes included) is ``real_label`` and no synthetic one is.
    incidence : the composite's (1 on real pixels: the real sensor has already dropped
        what it did not see), when the sensor needs it.
    rng : the frame's generator; pass B starts from a copy of its state.

    Returns the output with ``labels`` moved by pass A, holes by cause (a real pixel the
    real frame has no measurement for either under ``real``, the others under pass A's
    causes), and raw11 encoded from the composed disparity.
    """
    cfg = model.cfg
    labels = np.asarray(labels)
    real_mm = np.asarray(real_mm)
    synthetic = labels != real_label
    fb = cfg.intrinsics.fx * cfg.baseline_m
    if not synthetic.any():  # everyone hidden behind real surfaces: the real frame
        valid = real_mm > 0
        disp = np.zeros(real_mm.shape)
        np.divide(fb * 1000.0, real_mm, out=disp, where=valid)
        raw = encode_raw11(disp, valid, cfg.encoding.d_off) if cfg.encoding.raw11 else None
        return SensorOutput(real_mm.copy(), valid, labels.copy(), raw, disp,
                            {REAL_HOLE: int((~valid).sum())})
    rng_b = copy.deepcopy(rng)
    a = model.simulate(depth, rng, labels=labels, incidence=incidence)
    b = model.simulate(real_depth_m(real_mm), rng_b,
                       incidence=None if incidence is None else
                       np.ones(real_mm.shape, np.float32))
    assert a.labels is not None and a.hole_masks is not None
    z_near = float(np.asarray(depth)[synthetic].min(initial=np.inf))
    rows, cols = reach_px(model, z_near if z_near > 0 else 0.1)
    changed = (a.valid != b.valid) | (a.depth_mm != b.depth_mm)
    zone = _near(synthetic, rows, cols)
    keep = (a.labels == real_label) & ~(changed & zone)
    depth_mm = np.where(keep, real_mm, a.depth_mm)
    valid = depth_mm > 0
    islands = _islands(cfg, valid, zone)
    if islands is not None:
        depth_mm[islands] = 0
        valid &= ~islands
        keep &= ~islands
    disp = np.zeros(real_mm.shape)
    np.divide(fb * 1000.0, real_mm, out=disp, where=keep & valid)
    disp = np.where(keep, disp, a.disparity)
    raw = encode_raw11(disp, valid, cfg.encoding.d_off) if cfg.encoding.raw11 else None
    # a real pixel the real sensor did not measure either is the real frame's hole
    real_hole = (a.labels == real_label) & ~valid & (real_mm == 0)
    lost = ~valid & ~real_hole
    if islands is not None:
        lost &= ~islands
    holes = {c: int(np.count_nonzero(m & lost)) for c, m in a.hole_masks.items()}
    holes[REAL_HOLE] = int(np.count_nonzero(real_hole))
    if islands is not None:
        holes["speckle"] = holes.get("speckle", 0) + int(np.count_nonzero(islands))
    return SensorOutput(depth_mm, valid, a.labels, raw, disp, holes)
