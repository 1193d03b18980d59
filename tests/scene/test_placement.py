"""Placement: people and props never intersect, over many seeds, checked on the meshes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from vhgen.body.skinning import skin_vertices
from vhgen.job_config import JobConfig
from vhgen.scene.placement import Disc, all_visible, inside, visible_fraction

SCENE = """
name: t
seed: 3
motions: [builtin:demo]
avatars: {count: 3}
poses: {frame_step: 20}
scene:
  floor: true
  room: {width_m: [3.5, 6], depth_m: [4.5, 6]}
  people: [2, 4]
  props: {count: [3, 5], occlusion: [0.5, 1.0]}
"""


def _hull(xz: np.ndarray) -> np.ndarray:
    return xz[ConvexHull(xz).vertices]


def _separated(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex polygons (vertices in order)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, 0) - poly
        for e in edges:
            n = np.array([-e[1], e[0]])
            pa, pb = a @ n, b @ n
            if pa.max() < pb.min() or pb.max() < pa.min():
                return True
    return False


@pytest.fixture(scope="module")
def describer(tmp_path_factory, asset_dir):
    from dataclasses import replace

    from vhgen.pipeline.describe import FrameDescriber
    from vhgen.pipeline.job import prepare_job
    from vhgen.pipeline.plan import avatar_params, frame_seed

    p = tmp_path_factory.mktemp("place") / "scene.yaml"
    p.write_text(SCENE)
    cfg = JobConfig.load(p)
    job = prepare_job(cfg, asset_dir=asset_dir)
    n = 400  # frames over many seeds (each its own placement)
    plan = replace(job.plan, num_frames=n, avatar_id=np.arange(n) % 3,
                   pose_index=np.arange(n) % job.poses.num_poses,
                   seeds=np.array([frame_seed(99, 0, k) for k in range(n)], np.uint64),
                   avatars=[avatar_params(cfg.seed, a, cfg.avatars) for a in range(3)])
    return FrameDescriber(replace(job, plan=plan)), n


def test_placement_never_intersects_over_seeds(describer):
    d, n = describer
    placed_people = placed_props = occluders = 0
    for f in range(n):
        desc = d.describe(f)
        shapes = []
        for p in desc.people:
            b = d.body(p.avatar_id)
            v = skin_vertices(b.vertices, b.joints, b.weights, p.bones)
            assert v[:, 1].min() > -1e-6, f  # nobody sinks into the floor
            shapes.append(_hull(v[:, [0, 2]]))
        for m in desc.static:
            if m.name.startswith("prop:"):
                assert m.vertices[:, 1].min() == pytest.approx(0.0, abs=1e-9)
                shapes.append(_hull(m.vertices[:, [0, 2]]))
        for i in range(len(shapes)):
            for j in range(i):
                assert _separated(shapes[i], shapes[j]), (f, i, j)
        discs = [p.footprint for p in desc.people] + [p.footprint for p in desc.props]
        for k, disc in enumerate(discs):
            assert disc is not None
            if k > 0:  # person 1 is where the plan puts it; the room is sampled around it
                assert inside(desc.room, disc, gap=0.0), (f, k)
        placed_people += len(desc.people)
        placed_props += len(desc.props)
        occluders += sum(p.occluder for p in desc.props)
        assert len(desc.people) + desc.dropped["people"] >= 2
    # the config asks for 2-4 people and 3-5 props per frame: most of them fit
    assert placed_people > 2.0 * n and placed_props > 2.5 * n
    assert occluders > 0.5 * n  # occlusion [0.5, 1]: many props on a line of sight


def test_visible_fraction():
    eye = np.zeros(2)
    target = Disc(0.0, 4.0, 0.4)
    assert visible_fraction(eye, target, []) == 1.0
    assert visible_fraction(eye, target, [Disc(0.0, 2.0, 0.4)]) == 0.0  # right in front
    assert visible_fraction(eye, target, [Disc(0.0, 6.0, 2.0)]) == 1.0  # behind
    half = visible_fraction(eye, target, [Disc(-0.5, 2.0, 0.5)])
    assert 0.2 < half < 0.8


def test_compiled_visibility_decides_as_the_reference():
    """all_visible (one compiled call) answers what placement asked of visible_fraction,
    person by person, on thousands of random floor plans: 1-6 discs, some targets, the
    shipped thresholds; and the known answers above."""
    eye = np.zeros(2)
    target = Disc(0.0, 4.0, 0.4)
    assert all_visible(eye, [target], 1, 1.0)
    assert not all_visible(eye, [target, Disc(0.0, 2.0, 0.4)], 1, 0.01)
    assert all_visible(eye, [target, Disc(0.0, 2.0, 0.4)], 0, 1.0)  # no target
    assert all_visible(eye, [target, Disc(0.0, 6.0, 2.0)], 1, 1.0)  # behind
    rng = np.random.default_rng(5)
    answers = []
    for _ in range(4000):
        n = int(rng.integers(1, 7))
        eye = rng.uniform(-1, 1, 2)
        discs = [Disc(float(x), float(z), float(r)) for x, z, r in
                 zip(rng.uniform(-2, 2, n), rng.uniform(0.5, 6, n), rng.uniform(0.1, 0.6, n),
                     strict=True)]
        targets = int(rng.integers(1, n + 1))
        least = float(rng.choice([0.3, 0.5, 0.7]))
        ref = all(visible_fraction(eye, d, [o for o in discs if o is not d]) >= least
                  for d in discs[:targets])
        assert all_visible(eye, discs, targets, least) == ref
        answers.append(ref)
    assert 0.2 < np.mean(answers) < 0.9  # both answers, often
