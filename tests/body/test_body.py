import numpy as np
import pytest

from vhgen.body.avatar import build_body
from vhgen.body.mesh import truncate_weights
from vhgen.body.skinning import bone_matrices, skin_vertices
from vhgen.errors import AssetError, ConfigError


def test_body_geometry_and_rig(body):
    assert body.vertices.shape == (13380, 3)
    assert body.faces.max() < len(body.vertices)
    height = body.vertices[:, 1].max() - body.vertices[:, 1].min()
    assert 1.55 < height < 1.80  # the MakeHuman base body, in metres
    assert body.vertices[:, 1].min() == pytest.approx(0.0)
    assert len(body.rig.names) == 31 and (body.rig.parents[1:] >= 0).all()
    # joints are inside the body: the head joint above the pelvis, left hip at +x
    rig = body.rig
    assert rig.heads[rig.index("Head"), 1] > rig.heads[rig.index("Hips"), 1]
    assert rig.heads[rig.index("LeftUpLeg"), 0] > 0 > rig.heads[rig.index("RightUpLeg"), 0]


def test_weights_fixed_length_normalised(body):
    assert body.joints.shape == (13380, 4) and body.weights.shape == (13380, 4)
    np.testing.assert_allclose(body.weights.sum(1), 1.0, atol=1e-12)
    assert (body.weights >= 0).all()


def test_truncation_keeps_largest_and_handles_zero_sum():
    dense = np.array([[0.1, 0.2, 0.3, 0.15, 0.25], [0, 0, 0, 0, 0], [0, 0.5, 0, 0, 0]])
    j, w = truncate_weights(dense, 4)
    assert sorted(j[0].tolist()) == [1, 2, 3, 4]
    np.testing.assert_allclose(w[0], np.array([0.3, 0.25, 0.2, 0.15]) / 0.9)
    assert j[1, 0] == 0 and w[1].tolist() == [1, 0, 0, 0]  # no influence: rigid to the root
    assert j[2, 0] == 1 and w[2, 0] == 1.0


def test_rest_pose_returns_template_exactly(body):
    b = len(body.rig.names)
    mats = bone_matrices(body.rig, np.broadcast_to(np.eye(3), (b, 3, 3)), body.rig.heads[0])
    np.testing.assert_allclose(skin_vertices(body.vertices, body.joints, body.weights, mats),
                               body.vertices, atol=1e-12)


def test_labels_cover_31_parts_and_respect_sides(body, shotton):
    assert len(shotton.names) == 31
    counts = np.bincount(body.face_labels, minlength=32)
    assert counts[0] == 0 and (counts[1:] > 0).all()
    centroid = body.vertices[body.faces].mean(axis=1)
    for k, name in enumerate(shotton.names, start=1):
        x = centroid[body.face_labels == k, 0]
        if name.startswith("L"):
            assert (x > -0.01).all(), name  # subject's left is +x
        elif name.startswith("R"):
            assert (x < 0.01).all(), name
    head = centroid[np.isin(body.face_labels, [1, 2])][:, 1].min()
    assert head > centroid[np.isin(body.face_labels, [3, 4])][:, 1].min()


def test_scaled_avatar_rig_fits(asset_dir, shotton, body):
    big = build_body(asset_dir, shotton, scale=1.1)
    np.testing.assert_allclose(big.vertices, body.vertices * 1.1, atol=1e-12)
    np.testing.assert_allclose(big.rig.heads, body.rig.heads * 1.1, atol=1e-12)


def test_missing_assets_name_the_fetch_command(tmp_path, shotton):
    with pytest.raises(AssetError, match="vhgen assets fetch"):
        from vhgen.assets import resolve_asset_dir

        resolve_asset_dir(tmp_path)


def test_label_scheme_errors(tmp_path, asset_dir):
    from vhgen.body.labels import LabelScheme

    p = tmp_path / "s.yaml"
    p.write_text("name: s\nparts:\n  - {name: a, color: [1, 2, 3], select: [{bones: [Hips]}]}\n")
    with pytest.raises(ConfigError, match="match no part"):
        build_body(asset_dir, LabelScheme.load(p))
    p.write_text("name: s\nparts:\n  - {name: a, color: [1, 2], select: [{bones: [Hips]}]}\n")
    with pytest.raises(ConfigError, match=r"parts\[0\].color"):
        LabelScheme.load(p)
    p.write_text("name: s\nparts:\n  - {name: a, color: [1, 2, 3], select: [{bonez: [X]}]}\n")
    with pytest.raises(ConfigError, match="bonez: unknown key"):
        LabelScheme.load(p)
