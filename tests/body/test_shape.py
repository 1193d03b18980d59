import numpy as np
import pytest

from vhgen.body.avatar import build_body
from vhgen.body.shape import (
    Shape,
    ShapeSampler,
    age_from_years,
    target_weights,
    variable_weights,
    years_from_age,
)
from vhgen.body.skinning import bone_matrices, skin_vertices
from vhgen.errors import ConfigError


@pytest.mark.parametrize("age, expect", [(0.0, "baby"), (0.1875, "child"), (0.5, "young"),
                                         (1.0, "old")])
def test_age_sample_points_follow_makehuman_a8(age, expect):
    w = variable_weights(Shape(age=age))["age"]
    assert w[expect] == pytest.approx(1.0, abs=1e-3)
    assert sum(w.values()) == pytest.approx(1.0)


def test_target_weights_are_products_of_partitions_of_unity():
    rng = np.random.default_rng(0)
    for _ in range(50):
        s = ShapeSampler(age_years=(1, 90), gender=(0, 1), muscle=(0, 1), weight=(0, 1),
                         height=(0, 1), proportions=(0, 1)).sample(rng)
        tw = target_weights(s)
        assert sum(v for k, v in tw.items() if k.startswith("universal-")) == pytest.approx(1.0)
        race = sum(v for k, v in tw.items() if k.split("-")[0] in ("african", "asian",
                                                                    "caucasian"))
        assert race == pytest.approx(1.0)
        h = sum(v for k, v in tw.items() if k.startswith("height/"))
        assert h == pytest.approx(abs(2 * s.height - 1))
        assert all(v > 0 for v in tw.values())


def test_years_round_trip_and_validation():
    for y in (1, 11, 25, 40, 90):
        assert years_from_age(age_from_years(y)) == pytest.approx(y)
    with pytest.raises(ConfigError, match="shape.weight"):
        Shape(weight=1.5)
    with pytest.raises(ConfigError):
        Shape(gender=float("nan"))


def test_sampler_is_seeded():
    a = ShapeSampler().sample(np.random.default_rng(42))
    b = ShapeSampler().sample(np.random.default_rng(42))
    assert a == b and a != ShapeSampler().sample(np.random.default_rng(43))


def _height(body):
    return body.vertices[:, 1].max()


EXTREMES = {
    "baby": Shape(age=0.0, weight=0.0, muscle=0.0, height=0.0),
    "child": Shape(age=age_from_years(8), height=0.0),
    "small_woman": Shape(gender=0.0, height=0.0, weight=0.0, muscle=0.0, proportions=0.0),
    "large_man": Shape(gender=1.0, height=1.0, weight=1.0, muscle=1.0, proportions=1.0),
    "old_heavy": Shape(gender=0.3, age=1.0, weight=1.0, muscle=0.0, african=1.0, asian=0.0,
                       caucasian=0.0),
}


@pytest.fixture(scope="module")
def extremes(asset_dir, shotton):
    return {k: build_body(asset_dir, shotton, shape=s) for k, s in EXTREMES.items()}


def test_extreme_bodies_are_sane(extremes, body):
    h = {k: _height(b) for k, b in extremes.items()}
    assert h["baby"] < h["child"] < h["small_woman"] < h["large_man"]
    # MakeHuman's extremes: a 1-year-old at minimum height ~0.44 m, a young man at maximum
    # height ~2.45 m
    assert 0.35 < h["baby"] < 0.95 and 2.2 < h["large_man"] < 2.6
    for name, b in extremes.items():
        assert np.isfinite(b.vertices).all(), name
        assert b.vertices[:, 1].min() == pytest.approx(0.0)
        lo, hi = b.vertices.min(0), b.vertices.max(0)
        # the rig is refitted from the shaped joint cubes: every joint inside the body box
        assert np.all((b.rig.heads >= lo - 1e-9) & (b.rig.heads <= hi + 1e-9)), name
        # same topology, same per-triangle labels whatever the shape
        np.testing.assert_array_equal(b.face_labels, body.face_labels)
        assert b.hip_drop > 0.1


def test_rest_pose_returns_shaped_template_exactly(extremes):
    for b in extremes.values():
        n = b.num_bones
        mats = bone_matrices(b.rig, np.broadcast_to(np.eye(3), (n, 3, 3)), b.rig.heads[0])
        np.testing.assert_allclose(skin_vertices(b.vertices, b.joints, b.weights, mats),
                                   b.vertices, atol=1e-12)


def test_clothing_helpers_are_included_and_labelled(asset_dir, shotton, body):
    dressed = build_body(asset_dir, shotton, clothing=("tights", "skirt"))
    assert len(dressed.faces) > len(body.faces) and len(dressed.vertices) > len(body.vertices)
    assert (dressed.face_labels > 0).all()
    with pytest.raises(ConfigError, match="unknown helper"):
        build_body(asset_dir, shotton, clothing=("hat",))


@pytest.mark.parametrize("scheme", ["pcl25", "coarse10"])
def test_other_label_schemes_cover_every_part(asset_dir, scheme):
    from vhgen.body.labels import LabelScheme

    s = LabelScheme.load(scheme)
    b = build_body(asset_dir, s)
    counts = np.bincount(b.face_labels, minlength=len(s.names) + 1)
    assert counts[0] == 0 and (counts[1:] > 0).all()
    centroid = b.vertices[b.faces].mean(axis=1)
    for k, name in enumerate(s.names, start=1):
        x = centroid[b.face_labels == k, 0]
        if name.startswith("L") and name != "Lchest" or name.startswith("L_"):
            assert np.median(x) > 0, name
        if name.startswith("R") or name.startswith("R_"):
            assert np.median(x) < 0, name


def test_avatar_rebuilt_from_manifest_params(asset_dir, shotton):
    import json

    from vhgen.job_config import AvatarConfig
    from vhgen.pipeline.plan import avatar_params

    p = avatar_params(7, 3, AvatarConfig(count=5, tights_probability=1.0))
    a = build_body(asset_dir, shotton, shape=p.shape, scale=p.scale, clothing=p.clothing)
    recorded = json.loads(json.dumps(a.params))  # what the manifest row stores
    b = build_body(asset_dir, shotton, shape=Shape.from_dict(recorded["shape"]),
                   scale=recorded["scale"], clothing=tuple(recorded["clothing"]))
    assert a.fingerprint() == b.fingerprint() and "tights" in recorded["clothing"]


def test_explicit_vertex_selectors(tmp_path, asset_dir, body):
    from vhgen.body.labels import LabelScheme

    some = list(range(0, 1400, 7))  # base.obj vertex numbering
    bones = ", ".join(body.rig.names)
    (tmp_path / "s.yaml").write_text(
        "name: s\nparts:\n"
        f"  - {{name: picked, color: [1, 2, 3], select: [{{vertices: {some}}}]}}\n"
        "  - {name: tights, color: [4, 5, 6], select: [{vertex_group: helper-tights}]}\n"
        f"  - {{name: rest, color: [7, 8, 9], select: [{{bones: [{bones}]}}]}}\n")
    scheme = LabelScheme.load(tmp_path / "s.yaml")
    b = build_body(asset_dir, scheme, clothing=("tights",))
    counts = np.bincount(b.face_labels, minlength=4)
    assert counts[1] > 0 and counts[2] > 1000 and counts[3] > 10000
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: s\nparts:\n  - {name: a, color: [1, 2, 3], select: [{t: [0, 1]}]}\n")
    with pytest.raises(ConfigError, match="needs bones, vertices or vertex_group"):
        LabelScheme.load(bad)
