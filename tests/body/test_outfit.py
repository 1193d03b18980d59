"""Outfits on the CPU: the wardrobe config, drawing and recording outfits, rebuilding them,
labels of garments, closed parts, the contact math. No GL."""

from __future__ import annotations

import json
import pickle
from dataclasses import replace

import numpy as np
import pytest

from vhgen.body.avatar import AvatarParams, _chart, build_avatar, build_body
from vhgen.body.chart import LEG_L, LEG_R, TORSO
from vhgen.body.contact import body_contacts, dressed_positions, hand_distance, push_out
from vhgen.body.drape import hull_radius
from vhgen.body.skin_kernels import skin_points
from vhgen.body.skinning import bone_matrices
from vhgen.body.wardrobe import (
    ITEMS,
    KINDS,
    Chance,
    Outfit,
    OutfitConfig,
    default_outfit_config,
    parse_outfit,
)
from vhgen.errors import ConfigError
from vhgen.geom.primitives import box, lathe, signed_volume, solid_sheet
from vhgen.job_config import AvatarConfig, JobConfig
from vhgen.pipeline.plan import avatar_params
from vhgen.scene.topology import OUTWARD, closed_sides


def _only(**kinds: str) -> OutfitConfig:
    """A wardrobe that always wears exactly these kinds (other items never)."""
    d = {item: False for item in ITEMS}
    d.update({item: {"probability": 1.0, "kinds": [kind]} for item, kind in kinds.items()})
    return parse_outfit(d, None).with_class(5)


# every kind of every item at least once, in outfits people wear
OUTFITS = [
    dict(top="tshirt", bottom="trousers", shoes="shoes", hair="short", carried="shoulder_bag"),
    dict(top="shirt", outer="jacket", bottom="shorts", shoes="boots", hair="medium",
         hat="cap", carried="backpack"),
    dict(top="jumper", outer="coat", bottom="skirt", hair="long", hat="beanie",
         carried="hand_bag"),
    dict(top="dress", hair="ponytail", hat="brimmed", carried="cup"),
    dict(top="tank", bottom="trousers", hair="bun", carried="phone"),
    dict(top="shirt", bottom="trousers", carried="box"),
]


def test_the_outfits_cover_every_kind():
    worn = {(item, kind) for o in OUTFITS for item, kind in o.items()}
    worn.add(("bottom", "skirt"))  # a dress is a top and a skirt
    assert worn == {(item, kind) for item in ITEMS for kind in KINDS[item]}


def test_no_outfit_key_draws_nothing_more():
    """Configs without avatars.outfit keep their avatars: no extra draw, no new key; with
    one, the outfit is drawn after everything else (the rest stays the same)."""
    bare = AvatarConfig(count=4, tights_probability=0.5, skirt_probability=0.5)
    dressed = AvatarConfig(count=4, tights_probability=0.5, skirt_probability=0.5,
                           outfit=parse_outfit({}, None))
    for a in range(4):
        p, q = avatar_params(11, a, bare).to_dict(), avatar_params(11, a, dressed).to_dict()
        assert set(p) == {"shape", "scale", "clothing"}
        assert {k: q[k] for k in p} == p and set(q["outfit"]) == set(ITEMS)
    assert parse_outfit(None, None) == OutfitConfig() and not OutfitConfig().enabled


@pytest.mark.parametrize("k", range(len(OUTFITS)))
def test_rebuild_from_recorded_params_is_byte_identical(asset_dir, shotton, k):
    """The manifest records avatar_params as JSON; building from it gives the same arrays
    byte for byte as the body the job rendered."""
    cfg = AvatarConfig(count=3, outfit=_only(**OUTFITS[k]))
    params = avatar_params(7, k, cfg)
    body = build_avatar(asset_dir, shotton, params)
    recorded = json.loads(json.dumps({**body.params, "skinning": "lbs"}, sort_keys=True))
    again = build_avatar(asset_dir, shotton, AvatarParams.from_dict(recorded))
    assert again.fingerprint() == body.fingerprint()
    for name in ("vertices", "faces", "joints", "weights", "face_labels", "offsets", "press",
                 "face_classes"):
        assert np.array_equal(getattr(again, name), getattr(body, name)), name
    assert params.outfit is not None and recorded["outfit"] == params.outfit.to_dict()
    assert AvatarParams.from_dict(recorded) == params


def test_typed_outfits_round_trip_to_the_same_manifest_data():
    """Outfits travel typed; their plain data (the manifest's avatar_params.outfit) holds
    every item, each worn one as its kind and exactly that kind's parameters (a side as
    ``side``, a carried thing's labelling last), and rebuilds the same records, through
    JSON and through pickling (how the plan reaches workers)."""
    cfg = AvatarConfig(count=40, outfit=default_outfit_config().with_class(5))
    seen = set()
    for a in range(cfg.count):
        params = avatar_params(5, a, cfg)
        outfit = params.outfit
        assert outfit is not None
        d = outfit.to_dict()
        assert list(d) == list(ITEMS)
        for item, rec in d.items():
            if rec is None:
                assert getattr(outfit, item) is None
                continue
            seen.add((item, rec["kind"]))
            names = ["side" if n == "left" else n for n in KINDS[item][rec["kind"]]]
            extra = ["as_person", "class"] if item == "carried" else []
            assert list(rec) == ["kind", *names, *extra]
            for n, p in KINDS[item][rec["kind"]].items():
                v = rec["side" if n == "left" else n]
                if isinstance(p, Chance):
                    assert v in (("left", "right") if n == "left" else (True, False))
                else:
                    assert isinstance(v, float) and p.lo <= v <= p.hi
        recorded = json.loads(json.dumps(params.to_dict(), sort_keys=True))
        assert Outfit.from_dict(recorded["outfit"]) == outfit
        assert AvatarParams.from_dict(recorded) == params
        assert pickle.loads(pickle.dumps(params)) == params
    assert len(seen) > 15  # many kinds drawn


@pytest.fixture(scope="module")
def dressed(asset_dir, shotton):
    """One body per outfit of OUTFITS (avatar shapes drawn too), and the bare ones."""
    out = []
    for k, o in enumerate(OUTFITS):
        params = avatar_params(3, k, AvatarConfig(count=6, outfit=_only(**o)))
        body = build_avatar(asset_dir, shotton, params)
        bare = build_avatar(asset_dir, shotton, replace(params, outfit=None))
        out.append((body, bare))
    return out


def test_tight_garments_keep_every_body_triangle_and_its_label(dressed):
    """Tight garments move the body's own vertices: the body's triangles, their labels and
    weights are unchanged, vertices only move outwards along the skin's normal."""
    for body, bare in dressed:
        t, v = len(bare.faces), len(bare.vertices)
        assert np.array_equal(body.faces[:t], bare.faces)
        assert np.array_equal(body.face_labels[:t], bare.face_labels)
        assert np.array_equal(body.joints[:v], bare.joints)
        np.testing.assert_allclose(body.vertices[:v] - body.offsets[:v], bare.vertices,
                                   atol=1e-12)
        assert np.linalg.norm(body.offsets[:v], axis=1).max() < 0.12
        assert (np.linalg.norm(body.offsets[:v], axis=1) > 0.002).mean() > 0.1


def test_every_added_part_is_a_closed_outward_surface(dressed):
    """So the renderer culls the far side of everything (the cost of a clothed person)."""
    for body, _ in dressed:
        side = closed_sides(body.vertices, body.faces)
        assert (side == OUTWARD).all(), np.unique(side, return_counts=True)


def _closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Squared distance (N, T) from points (N, 3) to triangles (T, 3, 3) (exact, brute
    force: the projection inside the triangle or the nearest point of its edges)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-15)
    q = p[:, None] - a[None]
    h = np.einsum("ntk,tk->nt", q, n)
    proj = p[:, None] - h[..., None] * n[None]
    inside = np.ones(h.shape, bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ntk,tk->nt", np.cross((v - u)[None], proj - u[None]), n) >= 0
    best = np.where(inside, h * h, np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        e = v - u
        s = np.clip(np.einsum("ntk,tk->nt", p[:, None] - u[None], e) /
                    np.einsum("tk,tk->t", e, e), 0, 1)
        d = p[:, None] - (u[None] + s[..., None] * e[None])
        best = np.minimum(best, np.einsum("ntk,ntk->nt", d, d))
    return best


def test_loose_cloth_takes_the_label_of_the_body_under_it(dressed, asset_dir):
    """A skirt's, a coat's, a hood's, long hair's triangles carry the label of the body
    triangle under them: checked against the exactly closest body triangle (of the torso
    and legs for cloth round the legs): the same label for 95% of them, and where not,
    the other label's triangles are within 2 cm (a part boundary)."""
    chart = _chart(asset_dir, "cmu_mb")
    body, bare = dressed[2]  # jumper, coat, skirt, long hair, beanie, hand bag
    t = len(bare.faces)
    skin = bare.vertices
    cand = np.flatnonzero(np.isin(chart.face_region, (TORSO, LEG_L, LEG_R)))
    rng = np.random.default_rng(0)
    cloth = t + np.flatnonzero(body.face_classes[t:] == 0)
    low = body.vertices[body.faces[cloth]].mean(axis=1)[:, 1] < 0.95  # skirt and coat hem
    pick = rng.choice(cloth[low], 150, replace=False)
    centroid = body.vertices[body.faces[pick]].mean(axis=1)
    d2 = _closest_on_triangles(centroid, skin[bare.faces[cand]])
    nearest = bare.face_labels[cand[np.argmin(d2, axis=1)]]
    same = nearest == body.face_labels[pick]
    assert same.mean() >= 0.95, same.mean()
    for i in np.flatnonzero(~same):
        mine = bare.face_labels[cand] == body.face_labels[pick[i]]
        assert np.sqrt(d2[i][mine].min()) - np.sqrt(d2[i].min()) < 0.02


def test_carried_things_have_their_own_class_or_the_hands_label(asset_dir, shotton):
    """Not part of the person: label 0, the configured class; part of it: the label of
    the hand that holds it, the person's class."""
    own = build_body(asset_dir, shotton, outfit=Outfit.from_dict({"carried": {
        "kind": "phone", "side": "left", "width_m": 0.07, "height_m": 0.15, "depth_m": 0.008,
        "as_person": False, "class": 6}}))
    t = len(own.faces) - 12
    assert (own.face_classes[t:] == 6).all() and (own.face_labels[t:] == 0).all()
    assert (own.face_classes[:t] == 0).all() and (own.face_labels[:t] > 0).all()
    person = build_body(asset_dir, shotton, outfit=Outfit.from_dict({"carried": {
        "kind": "phone", "side": "left", "width_m": 0.07, "height_m": 0.15, "depth_m": 0.008,
        "as_person": True, "class": 0}}))
    hand = shotton.names.index("L_hand") + 1
    assert (person.face_classes == 0).all() and (person.face_labels[t:] == hand).all()


def test_sleeves_and_trouser_legs_end_where_asked(asset_dir, shotton):
    """A known answer on the chart: a sleeve to 0.5 covers the upper arm and stops at the
    elbow; full-length trousers reach the ankle, shorts stop above the knee."""
    chart = _chart(asset_dir, "cmu_mb")
    arm = np.isin(chart.face_region, (3, 4))

    def moved(outfit: dict) -> np.ndarray:
        b = build_body(asset_dir, shotton, outfit=Outfit.from_dict(outfit))
        off = np.linalg.norm(b.offsets, axis=1)
        return (off[b.faces[:len(chart.face_region)]] > 0).all(axis=1)

    top = {"kind": "shirt", "sleeve": 0.5, "hem": 0.0, "collar": 0.0, "thickness_m": 0.01}
    m = moved({"top": top})
    assert m[arm & (chart.face_arm_t < 0.45)].all()
    assert not m[arm & (chart.face_arm_t > 0.56)].any()
    legs = np.isin(chart.face_region, (LEG_L, LEG_R))
    for length in (0.4, 1.0):
        m = moved({"bottom": {"kind": "trousers", "length": length, "rise": 0.2, "width": 0.0,
                              "thickness_m": 0.01}})
        assert m[legs & (chart.face_leg_t < length - 0.05)].all()
        assert not m[legs & (chart.face_leg_t > length + 0.06)].any()


def test_config_errors_name_the_field(tmp_path):
    bad = [({"tops": {}}, "avatars.outfit.tops"),
           ({"top": {"kinds": ["toga"]}}, "avatars.outfit.top.kinds.toga"),
           ({"top": {"probability": 1.5}}, "avatars.outfit.top.probability"),
           ({"top": {"shirt": {"sleeve": [0.5, 2.0]}}}, "avatars.outfit.top.shirt.sleeve"),
           ({"top": {"shirt": {"sleeves": 0.5}}}, "avatars.outfit.top.shirt.sleeves"),
           ({"outer": {"coat": {"open": 2}}}, "avatars.outfit.outer.coat.open"),
           ({"hair": {"kinds": {"long": -1}}}, "avatars.outfit.hair.kinds.long"),
           ({"carried_as_person": "yes"}, "avatars.outfit.carried_as_person")]
    for d, field in bad:
        with pytest.raises(ConfigError) as e:
            parse_outfit(d, "x.yaml")
        assert e.value.field == field, (d, e.value)
    p = tmp_path / "c.yaml"
    p.write_text("name: c\nmotions: [builtin:demo]\navatars:\n  outfit:\n    hat: {kinds: "
                 "[crown]}\n")
    with pytest.raises(ConfigError, match=r"c.yaml: avatars.outfit.hat.kinds.crown"):
        JobConfig.load(p)


def test_carried_class_follows_the_scene_classes(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("name: c\nmotions: [builtin:demo]\nscene:\n  floor: true\n  props: {kinds: "
                 "[box, {kind: sofa, class: sofa}]}\navatars:\n  outfit: {carried: "
                 "{probability: 1}}\n")
    cfg = JobConfig.load(p)
    assert cfg.class_names[-2:] == ("sofa", "carried")
    assert cfg.avatars.outfit.carried_class == len(cfg.class_names) - 1
    p.write_text("name: c\nmotions: [builtin:demo]\navatars:\n  outfit: {carried_as_person: "
                 "true}\n")
    assert JobConfig.load(p).class_names == JobConfig.load(p).scene.class_names


# -- the primitives and the contact math on known answers ------------------------------

def test_primitives_are_closed_and_outward():
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 3), indexing="ij"), -1)
    outer = np.concatenate([grid, np.zeros(grid.shape[:2] + (1,))], -1)
    inner = outer + [0, 0, -0.1]
    for mesh in (solid_sheet(outer, inner, wrap=False), box(np.array([1, 2, 3.0]), np.eye(4)),
                 lathe(np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]]), np.eye(4))):
        assert (closed_sides(*mesh) == OUTWARD).all()
    v, f = box(np.array([1, 2, 3.0]), np.eye(4))
    assert signed_volume(v, f) == pytest.approx(6.0)


def test_hull_radius_of_a_square():
    pts = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1.0], [0.2, 0.3]])
    r = hull_radius(pts, np.zeros(2), np.array([0.0, np.pi / 4, np.pi / 2]))
    np.testing.assert_allclose(r, [1.0, np.sqrt(2), 1.0], rtol=2e-3)


def test_contact_math_known_answers():
    a, b = np.zeros(3), np.array([0, 0, 1.0])
    p = np.array([[0.1, 0, 0.5], [0, 0.3, 2.0], [0.0, 0.04, 0.5]])
    np.testing.assert_allclose(hand_distance(p, a, b, np.array([1.0, 0, 0]), 2.0),
                               [0.05, np.hypot(0.3, 1.0), 0.04])
    out = push_out(p, a, b, 0.2, 0.2)
    np.testing.assert_allclose(np.linalg.norm(out[[0, 2], :2], axis=1), 0.208)
    np.testing.assert_array_equal(out[1], p[1])


def test_garment_positions_are_the_skinning_of_the_garment_away_from_the_hands(
        dressed):
    """Where no hand presses and no leg pushes, the garment program's vertices are the
    dressed vertices skinned with the body's weights (float64, to rounding)."""
    body = dressed[1][0]
    rng = np.random.default_rng(1)
    rot = np.stack([np.linalg.qr(np.eye(3) + 0.2 * rng.normal(size=(3, 3)))[0]
                    for _ in range(body.num_bones)])
    rot *= np.sign(np.linalg.det(rot))[:, None, None]
    m = bone_matrices(body.rig, rot, np.array([0.0, 0.9, 0.0]))
    c = body_contacts(body.rig, body.vertices - body.offsets, body.joints)
    got = dressed_positions(body.vertices, body.offsets, np.zeros_like(body.press),
                            body.joints, body.weights, m, c)
    np.testing.assert_allclose(got, skin_points(body.vertices, body.joints, body.weights, m),
                               atol=1e-12)
