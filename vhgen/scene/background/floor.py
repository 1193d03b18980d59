"""The floor of a real depth frame and its free floor (pure).

:func:`estimate_floor`: the floor plane, found on the back-projected points (float64) by
the plane finder of :mod:`vhgen.geom.planes` with the floor's hypotheses (level, under the
camera), cost, refit and rules (nothing under it) and the sensor's depth noise as the
residual scale; :func:`free_floor`: the grid of floor cells a person may stand on, and
how much room each has. Both run once per background, when the job's backgrounds
are read (:mod:`vhgen.scene.background.load`).

World frame of a background (:meth:`FloorPlane.world_to_camera`): y up and y = 0 the real
floor; the camera at (0, h, 0), h its height above the floor, with its optical axis
projected onto the floor along +z. The camera's pitch and roll are the floor's tilt.
"""

from __future__ import annotations

import math

import numpy as np

from vhgen.camera import Intrinsics, project
from vhgen.errors import BackgroundError
from vhgen.geom.planes import Hypotheses, depth_noise, find_plane, planes_through
from vhgen.scene.background.background_frame import FloorPlane

# -- the floor --------------------------------------------------------------------------
FLOOR_STEP_PX = 4  # the plane is fitted on every 4th pixel of every 4th row (~15k points)
HYPOTHESES = 1000  # RANSAC: planes through 3 points, drawn with a fixed seed
REFINED = 8  # the best distinct hypotheses refined (Tukey IRLS), compared by their cost
SCORE_POINTS = 4000  # hypotheses are ranked on this many of the points
# residual scale of a floor point, sigma(z) = SIGMA_M + SIGMA_Z2 z^2 (metres), the noise
# model of vhgen.geom.planes.depth_noise: the depth noise grows with z^2 (1.44 mm/m^2 axial
# noise and 2.9 mm/m^2 quantisation steps on the shared OpenNI frames, docs/realism.md
# "Real frames and realism"); on capture0001-0003 the floor points' residuals have a
# standard deviation of 0.8 sigma
SIGMA_M = 0.006
SIGMA_Z2 = 0.0015
CUT = 3.0  # a point within CUT sigma of the plane is on it
# ... and its surface faces along the plane's normal, within FACING_DEG (the normal from
# the points NORMAL_SPAN samples to each side): a slanted plane through the floor and the
# front of a table holds points of both, but the table's front faces the camera
FACING_DEG = 30.0
NORMAL_SPAN = 2
# nothing stands under a floor: a point more than CUT sigma below a candidate costs
# BELOW_PENALTY outliers, and a plane with more than MAX_BELOW of the points under it is
# not the floor (a table top, a stair tread with the floor in view below it)
BELOW_PENALTY = 3.0
MAX_BELOW = 0.002
MIN_FLOOR_FRACTION = 0.03  # of the measured points: less is not a floor to stand on
MAX_TILT_DEG = 45.0  # the floor's normal within this of the image's up direction
CAMERA_HEIGHT_M = (0.2, 3.0)

# -- the free floor ---------------------------------------------------------------------
CELL_M = 0.05  # floor grid cell
OBSTACLE_TOP_M = 2.2  # points up to this height over the floor are in a person's way
MIN_OBSTACLE_POINTS = 3  # per cell: fewer are taken for noise of the floor
GRID_HALF_WIDTH_M = 8.0
GRID_DEPTH_M = 12.0


def _points(depth_mm: np.ndarray, intr: Intrinsics, step: int = 1) -> np.ndarray:
    """(N, 3) float64 camera-frame points of the measured pixels of every ``step``-th row
    and column."""
    d = np.asarray(depth_mm)[::step, ::step]
    v, u = np.nonzero(d)
    z = d[v, u].astype(np.float64) / 1000.0
    return np.stack([(u * step - intr.cx) * z / intr.fx, (v * step - intr.cy) * z / intr.fy,
                     z], -1)


def _sigma(points: np.ndarray) -> np.ndarray:
    return depth_noise(points[:, 2], SIGMA_Z2, base_m=SIGMA_M)


def _normals(depth_mm: np.ndarray, intr: Intrinsics, step: int) -> tuple[np.ndarray,
                                                                          np.ndarray]:
    """The points of every ``step``-th pixel (N, 3) float64 camera frame and their local
    surface normals (N, 3), from the points NORMAL_SPAN samples away on each side (NaN
    where a neighbour has no measurement)."""
    d = np.asarray(depth_mm)[::step, ::step].astype(np.float64) / 1000.0
    v, u = np.indices(d.shape) * step
    grid = np.stack([(u - intr.cx) * d / intr.fx, (v - intr.cy) * d / intr.fy, d], -1)
    grid[d == 0] = np.nan
    k = NORMAL_SPAN
    normals = np.full(grid.shape, np.nan)
    normals[k:-k, k:-k] = np.cross(grid[k:-k, 2 * k:] - grid[k:-k, :-2 * k],
                                   grid[2 * k:, k:-k] - grid[:-2 * k, k:-k])
    with np.errstate(invalid="ignore", divide="ignore"):
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    ok = d > 0
    return grid[ok], normals[ok]


def _hypotheses(p: np.ndarray, facing: np.ndarray, rng: np.random.Generator,
                path: str) -> Hypotheses:
    """HYPOTHESES planes through three points facing up-ish (within MAX_TILT_DEG +
    FACING_DEG), kept when level (within MAX_TILT_DEG) and CAMERA_HEIGHT_M under the
    camera, to be ranked on SCORE_POINTS of the points (a fixed sample)."""
    up = np.flatnonzero(np.abs(facing[:, 1]) >= math.cos(math.radians(
        min(89.0, MAX_TILT_DEG + FACING_DEG))))
    if len(up) < 3:
        raise BackgroundError(path, "no floor: no surface under the camera faces up")
    idx = up[rng.integers(len(up), size=(HYPOTHESES, 3))]
    a, b, c = p[idx[:, 0]], p[idx[:, 1]], p[idx[:, 2]]
    n, ok = planes_through(a, b, c, min_norm=1e-12)
    h = -(n * a).sum(1)  # the camera's height over the plane
    n *= np.where(h < 0, -1.0, 1.0)[:, None]  # the camera on the positive side
    h = np.abs(h)
    ok &= ((-n[:, 1] >= math.cos(math.radians(MAX_TILT_DEG)))
           & (h >= CAMERA_HEIGHT_M[0]) & (h <= CAMERA_HEIGHT_M[1]))
    keep = np.flatnonzero(ok)
    if not len(keep):
        raise BackgroundError(path, f"no floor: no plane within {MAX_TILT_DEG:g} deg of "
                              f"level {CAMERA_HEIGHT_M[0]}-{CAMERA_HEIGHT_M[1]} m under "
                              "the camera")
    return Hypotheses(n[keep], -h[keep], rng.permutation(len(p))[:SCORE_POINTS])


def estimate_floor(depth_mm: np.ndarray, intr: Intrinsics,
                   path: str = "<frame>") -> FloorPlane:
    """The floor plane of a real depth frame (H, W) uint16 mm (0 = no measurement).

    RANSAC in float64 on the points of every FLOOR_STEP_PX-th pixel
    (:func:`vhgen.geom.planes.find_plane`): HYPOTHESES planes through three points (a
    fixed seed: the same file gives the same floor), kept when their normal is within
    MAX_TILT_DEG of the image's up direction with the camera CAMERA_HEIGHT_M above them;
    the REFINED cheapest distinct ones (MSAC cost on SCORE_POINTS of the points, points
    under the plane penalised, points whose surface does not face along the plane
    outliers) are refined by Tukey-weighted least squares on all the points, and the
    cheapest refined plane that is still level under the camera with at most MAX_BELOW
    of the points under it wins. BackgroundError naming ``path`` when no plane qualifies
    or the best holds less than MIN_FLOOR_FRACTION of the points.
    """
    p, facing = _normals(depth_mm, intr, FLOOR_STEP_PX)
    if len(p) < 100:
        raise BackgroundError(path, f"no floor: only {len(p)} measured points")
    facing = np.nan_to_num(facing)  # no normal (an edge): faces nothing
    sigma = _sigma(p)
    worst_below = 0.0

    def floor_like(n: np.ndarray, offset: float) -> bool:
        nonlocal worst_below
        h = -offset  # the camera's height over the plane
        below = float(((p @ n + h) / sigma < -CUT).mean())
        if (below > MAX_BELOW or not -n[1] >= math.cos(math.radians(MAX_TILT_DEG))
                or not CAMERA_HEIGHT_M[0] <= h <= CAMERA_HEIGHT_M[1]):
            worst_below = max(worst_below, below)
            return False
        return True

    fit = find_plane(p, sigma, _hypotheses(p, facing, np.random.default_rng(0), path),
                     cut=CUT, facing=facing, facing_deg=FACING_DEG, score="msac",
                     below_penalty=BELOW_PENALTY, refit="tukey", up=np.array([0.0, -1.0, 0.0]),
                     tries=REFINED, accept=floor_like)
    if fit is None:
        raise BackgroundError(path, f"no floor: every level plane under the camera has "
                              f"measured points under it (up to {100 * worst_below:.1f}%; "
                              f"a floor has at most {100 * MAX_BELOW:.1f}%)")
    nk, offset, on = fit
    hk = -offset
    frac = float(on.mean())
    if frac < MIN_FLOOR_FRACTION:
        raise BackgroundError(path, f"no floor: the best level plane under the camera "
                              f"holds {100 * frac:.1f}% of the measured points (at least "
                              f"{100 * MIN_FLOOR_FRACTION:.0f}% needed)")
    rms = float(np.sqrt(np.mean((p[on] @ nk + hk) ** 2)))
    return FloorPlane((float(nk[0]), float(nk[1]), float(nk[2])), float(hk), frac, rms)


# -- the free floor ---------------------------------------------------------------------
def free_floor(depth_mm: np.ndarray, intr: Intrinsics,
               floor: FloorPlane) -> tuple[np.ndarray, np.ndarray]:
    """Where a person may stand: the floor seen with nothing standing on it.

    Every measured point is put in the background's world frame and binned on a CELL_M
    grid of the floor (x, z): floor points (within CUT sigma of y = 0) and obstacle points
    (above that, up to OBSTACLE_TOP_M). A cell is free when it holds floor points and
    fewer than MIN_OBSTACLE_POINTS obstacle points; so is the floor nearer than the view
    reaches (:func:`_out_of_view`). Other cells seen by no point are not free (what is
    behind a sofa's front is unknown, most likely more sofa), except single gaps between
    free cells (small holes of the sensor); free slivers narrower than 3 cells are not.
    Returns the grid origin (2,) float64 (x, z of cell [0, 0]'s centre) and the
    clearance (Z, X) uint8 cm: the radius of the largest disc about each free cell's
    centre that holds only free cells and cells beside the view (0 off the free floor;
    capped at 2.55 m).
    """
    from scipy import ndimage

    pts = _points(depth_mm, intr)
    w2c = floor.world_to_camera()
    world = (pts - w2c[:3, 3]) @ w2c[:3, :3]  # camera -> world: R^T (X - t)
    y = world[:, 1]
    tol = CUT * _sigma(pts)
    on_floor = np.abs(y) <= tol
    obstacle = (y > tol) & (y <= OBSTACLE_TOP_M)
    x, z = world[:, 0], world[:, 2]
    inside = ((on_floor | obstacle) & (np.abs(x) <= GRID_HALF_WIDTH_M) & (z >= 0)
              & (z <= GRID_DEPTH_M))
    if not inside.any():
        return np.zeros(2), np.zeros((1, 1), np.uint8)
    ix = np.floor(x[inside] / CELL_M).astype(np.int64)
    iz = np.floor(z[inside] / CELL_M).astype(np.int64)
    # from the camera's foot (the floor below the view may be free), one empty cell of
    # border around
    x0, z0 = int(ix.min()) - 1, -1
    nx, nz = int(ix.max()) - x0 + 2, int(iz.max()) - z0 + 2
    cell = (iz - z0) * nx + (ix - x0)
    n_floor = np.bincount(cell[on_floor[inside]], minlength=nx * nz).reshape(nz, nx)
    n_obst = np.bincount(cell[obstacle[inside]], minlength=nx * nz).reshape(nz, nx)
    blocked = n_obst >= MIN_OBSTACLE_POINTS
    origin = np.array([(x0 + 0.5) * CELL_M, (z0 + 0.5) * CELL_M])
    below, beside = _out_of_view(depth_mm, intr, w2c, origin, (nz, nx))
    free = ((n_floor > 0) | below) & ~blocked
    # a cell seen by no point between free ones (a hole of the sensor) is free too
    square = np.ones((3, 3), bool)
    free |= ndimage.binary_closing(free, square) & (n_floor == 0) & ~blocked
    # and slivers less than 3 cells wide are not (the noise of the floor points at a
    # wall's foot puts some beyond it)
    free = ndimage.binary_opening(free, square)
    # a footprint may reach out of the view sideways; its centre stays on free floor
    passable = free | (beside & ~blocked)
    passable[[0, -1], :] = False
    passable[:, [0, -1]] = False
    # distance from a cell's centre to the nearest point of a cell that is not passable
    edt = ndimage.distance_transform_edt(passable)
    clear = np.where(free, np.maximum(edt - math.sqrt(0.5), 0.0) * CELL_M, 0.0)
    return origin, np.minimum(np.floor(clear * 100.0), 255).astype(np.uint8)


def _out_of_view(depth_mm: np.ndarray, intr: Intrinsics, w2c: np.ndarray, origin: np.ndarray,
                 shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(Z, X) bool each, floor cells in front of the camera out of the measured view:
    ``below``, under the lowest row holding a measurement, between the first and last
    measured columns (floor nearer than the view reaches: nothing seen stands on it, since
    whatever stood there and rose into the view would be an obstacle of the cells it
    stands on, so a person may stand there, its feet out of view, as in real frames of
    people near a camera); ``beside``, left of the first or right of the last measured
    column (a person's footprint may reach there: whatever stands there is out of view,
    and so is any part of the person it could meet)."""
    rows = np.flatnonzero(np.asarray(depth_mm).any(1))
    cols = np.flatnonzero(np.asarray(depth_mm).any(0))
    if not len(rows):
        return np.zeros(shape, bool), np.zeros(shape, bool)
    zz, xx = np.indices(shape)
    floor_pts = np.stack([origin[0] + xx * CELL_M, np.zeros(shape), origin[1] + zz * CELL_M], -1)
    cam = floor_pts @ w2c[:3, :3].T + w2c[:3, 3]
    uv = project(intr, cam)
    with np.errstate(invalid="ignore"):
        inside = (uv[..., 0] >= cols[0] - 0.5) & (uv[..., 0] <= cols[-1] + 0.5)
        front = np.isfinite(uv[..., 0])
        return (uv[..., 1] > rows[-1] + 0.5) & inside, front & ~inside


def reachable(origin: np.ndarray, clearance: np.ndarray, reach: tuple[float, float]
               ) -> np.ndarray:
    """(Z, X) bool: cells whose centre is within ``reach`` (m, on the floor) of the
    camera's foot (x = z = 0)."""
    zz, xx = np.indices(clearance.shape)
    d = np.hypot(origin[0] + xx * CELL_M, origin[1] + zz * CELL_M)
    return (d >= reach[0]) & (d <= reach[1])
