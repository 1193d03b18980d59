"""Garments through the body over the shared corpus (real motion capture).

Poses of every clip of ``../shared/mocap/cmu`` (retargeted as ``generate`` does), dressed
avatars posed exactly as the garment program draws them
(:func:`vhgen.body.contact.dressed_positions`: skinning, hands pressing, legs pushing), and
a point-in-body test against the posed bare skin (parity of a ray's crossings).

Stated tolerances:

* tight garments (displaced skin): a garment vertex is never deeper inside the body than
  its own thickness (+1 mm). It is inside at all only where the skin it covers touches
  another part (an arm against the side, the thighs): the cloth there overlaps as it
  would be compressed. Vertices whose own skin is inside another part (the body's own
  interpenetration in a pose, which clothes cannot fix) are not counted.
* loose cloth and volumes (skirts, coat hems, hood, long hair, ponytail, bun, brims): no
  vertex deeper than 5 cm inside the body in any tested pose, and on average under 3% of
  them inside at all (a knee through a straight long skirt in a deep squat is the worst
  case). Vertices inside the body at rest are where a volume is fixed to it (a bun's
  root in the skull, a cap's brim under its crown) and are not counted.
"""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.body.avatar import _chart, build_avatar, build_body
from vhgen.body.chart import vertex_normals
from vhgen.body.contact import body_contacts, dressed_positions
from vhgen.body.skin_kernels import skin_points
from vhgen.body.skinning import bone_matrices
from vhgen.job_config import AvatarConfig, PosesConfig
from vhgen.mocap.retarget import load_all_maps
from vhgen.pipeline.plan import avatar_params
from vhgen.pipeline.poses import load_poses

TIGHT_TOL_M = 0.001  # beyond the garment's own thickness
LOOSE_TOL_M = 0.05
LOOSE_INSIDE_FRACTION = 0.03
POSES = 40

OUTFITS = [  # the loose kinds, on top of tight ones; parameters drawn from their ranges
    {"top": "jumper", "outer": "coat", "bottom": "trousers", "shoes": "boots",
     "hair": "long"},
    {"top": "dress", "hair": "ponytail", "shoes": "shoes"},
    {"top": "shirt", "outer": "jacket", "bottom": "skirt", "hair": "bun", "hat": "cap"},
]


def inside(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
           cell: float = 0.02) -> np.ndarray:
    """(N,) bool: each point is inside the closed mesh: odd number of crossings of a ray
    along +z (triangles bucketed on a 2 cm grid in x, y)."""
    p = np.asarray(points, np.float64)
    tri = np.asarray(vertices, np.float64)[np.asarray(faces)]
    lo = np.floor(tri[:, :, :2].min(1) / cell).astype(np.int64)
    hi = np.floor(tri[:, :, :2].max(1) / cell).astype(np.int64)
    origin = lo.min(0)
    lo, hi = lo - origin, hi - origin
    ncol = int(hi[:, 1].max()) + 2
    nx, ny = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    count = nx * ny
    t_idx = np.repeat(np.arange(len(tri)), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    code = (lo[t_idx, 0] + k // ny[t_idx]) * ncol + lo[t_idx, 1] + k % ny[t_idx]
    order = np.argsort(code, kind="stable")
    code, t_idx = code[order], t_idx[order]
    pc = np.floor(p[:, :2] / cell).astype(np.int64) - origin
    pcode = pc[:, 0] * ncol + pc[:, 1]
    start = np.searchsorted(code, pcode, "left")
    n = np.searchsorted(code, pcode, "right") - start
    pi = np.repeat(np.arange(len(p)), n)
    ti = t_idx[np.repeat(start, n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)]
    a, b, c, q = tri[ti, 0], tri[ti, 1], tri[ti, 2], p[pi]
    d = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    ok = np.abs(d) > 1e-18
    d = np.where(ok, d, 1.0)
    l1 = ((b[:, 1] - c[:, 1]) * (q[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (q[:, 1] - c[:, 1])) / d
    l2 = ((c[:, 1] - a[:, 1]) * (q[:, 0] - c[:, 0]) + (a[:, 0] - c[:, 0]) * (q[:, 1] - c[:, 1])) / d
    l3 = 1 - l1 - l2
    hit = ok & (l1 >= 0) & (l2 >= 0) & (l3 >= 0)
    hit &= l1 * a[:, 2] + l2 * b[:, 2] + l3 * c[:, 2] > q[:, 2]
    return np.bincount(pi[hit], minlength=len(p)) % 2 == 1


def test_inside_on_a_box():
    """The point-in-body test itself, on a known answer."""
    from vhgen.geom.primitives import box

    v, f = box(np.array([1.0, 1.0, 1.0]), np.eye(4))
    pts = np.array([[0.1, 0.23, 0], [0.49, 0.3, -0.2], [0.51, 0.1, 0], [0.1, 0.2, 0.6],
                    [0.1, 0.2, -0.7]])
    assert inside(pts, v, f).tolist() == [True, True, False, False, False]


@pytest.fixture(scope="module")
def poses(shared_mocap, asset_dir, shotton):
    base = build_body(asset_dir, shotton)
    files = sorted(str(p) for p in shared_mocap.glob("*.bvh"))
    ps = load_poses(files, base.rig, load_all_maps(), PosesConfig(frame_step=15, skip_first=1))
    pick = np.sort(np.random.default_rng(0).choice(ps.num_poses, POSES, replace=False))
    return ps.rotations[pick], ps.roots[pick], len(set(ps.motion_id[pick].tolist()))


@pytest.mark.parametrize("k", range(len(OUTFITS)))
def test_garments_stay_outside_the_body_over_the_corpus(poses, asset_dir, shotton, k):
    from vhgen.body.wardrobe import ITEMS, parse_outfit

    rotations, roots, clips = poses
    assert clips >= 10  # the poses come from most of the corpus
    d = {item: False for item in ITEMS}
    d.update({item: {"probability": 1.0, "kinds": [kind]} for item, kind in OUTFITS[k].items()})
    cfg = AvatarConfig(count=3, outfit=parse_outfit(d, None).with_class(5))
    body = build_avatar(asset_dir, shotton, avatar_params(21, k, cfg))
    chart = _chart(asset_dir, "cmu_mb")
    nv, nf = len(chart.region), len(chart.face_region)
    skin = body.vertices - body.offsets
    thick = np.linalg.norm(body.offsets, axis=1)
    tight = np.flatnonzero(thick[:nv] > 0)[::2]
    loose = np.arange(nv, len(body.vertices))
    loose = loose[~inside(body.vertices[loose], skin[:nv], body.faces[:nf])]  # roots
    contacts = body_contacts(body.rig, skin, body.joints)
    faces = body.faces[:nf]
    worst_tight, worst_loose, inside_fraction = -1.0, 0.0, []
    for rot, root in zip(rotations, roots, strict=True):
        m = bone_matrices(body.rig, rot, root)
        g = dressed_positions(body.vertices, body.offsets, body.press, body.joints,
                              body.weights, m, contacts)
        s = skin_points(skin, body.joints, body.weights, m)[:nv]
        n = vertex_normals(s, faces)
        from scipy.spatial import cKDTree

        tree = cKDTree(s)
        bad = tight[inside(g[tight], s, faces) & ~inside(s[tight] + 0.003 * n[tight], s, faces)]
        if len(bad):
            worst_tight = max(worst_tight, float((tree.query(g[bad])[0] - thick[bad]).max()))
        inn = inside(g[loose], s, faces)
        inside_fraction.append(inn.mean())
        if inn.any():
            worst_loose = max(worst_loose, float(tree.query(g[loose][inn])[0].max()))
    assert worst_tight <= TIGHT_TOL_M, worst_tight
    assert worst_loose <= LOOSE_TOL_M, worst_loose
    assert np.mean(inside_fraction) <= LOOSE_INSIDE_FRACTION, np.mean(inside_fraction)
