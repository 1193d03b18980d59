"""Clothed people on the GPU: silhouettes grow where garments are, labels stay the body's
and crisp, carried things get their own class, a hand resting on a coat stays a hand,
and the garment program draws what vhgen.body.contact computes."""

from __future__ import annotations

import numpy as np
import pytest

from vhgen.body.avatar import build_body
from vhgen.body.contact import body_contacts, dressed_positions
from vhgen.body.skinning import bone_matrices
from vhgen.body.wardrobe import KINDS, Chance, Outfit
from vhgen.camera import Intrinsics, look_at
from vhgen.render.renderer import DepthLabelRenderer, Draw
from vhgen.render.scene_renderer import upload_body
from vhgen.scene.geometry import PERSON

INTR = Intrinsics(240, 320, 300.0, 300.0, 119.5, 159.5)


def _mid(item: str, kind: str, **kw) -> dict:
    """A kind with every parameter in the middle of its range, yes/no ones no."""
    d: dict = {"kind": kind}
    for name, p in KINDS[item][kind].items():
        if isinstance(p, Chance):
            if name == "left":
                d["side"] = "left"
            else:
                d[name] = False
        else:
            d[name] = (p.lo + p.hi) / 2
    d.update(kw)
    return d


def _draw(ctx, body, w2c, bones=None, instance=1):
    ren = DepthLabelRenderer(ctx, INTR)
    mesh = upload_body(ren, body)
    if bones is None:
        bones = bone_matrices(body.rig, np.broadcast_to(np.eye(3), (body.num_bones, 3, 3)),
                              body.rig.heads[0])
    view = ren.draw([Draw(mesh, w2c @ bones, instance, PERSON)])
    mesh.release()
    ren.release()
    return view


FRONT = look_at(np.array([0.0, 1.0, 3.0]), np.array([0.0, 0.95, 0.0]))


def test_silhouette_grows_where_garments_are_and_labels_stay_crisp(gl_ctx, asset_dir,
                                                                    shotton):
    outfit = {"top": _mid("top", "jumper"), "bottom": _mid("bottom", "trousers", width=0.05),
              "shoes": _mid("shoes", "boots"), "hair": _mid("hair", "medium")}
    bare = _draw(gl_ctx, build_body(asset_dir, shotton), FRONT)
    dressed = _draw(gl_ctx, build_body(asset_dir, shotton, outfit=Outfit.from_dict(outfit)),
                    FRONT)
    b, d = bare.labels > 0, dressed.labels > 0
    # garments only add: the bare body's silhouette lies inside the clothed one
    assert (d[b]).mean() > 0.998
    assert d.sum() > 1.15 * b.sum()
    # wide trouser legs: the lower legs (labels LW_leg) are much wider than bare ones
    lw = [shotton.names.index(n) + 1 for n in ("LW_leg", "RW_leg")]
    width = [np.isin(v.labels, lw).sum(axis=1).max() for v in (bare, dressed)]
    assert width[1] > width[0] + 2 * 0.03 * INTR.fx / 3.0
    # labels are the body's: inside each bare part (away from its edges) the clothed
    # image has the same part
    from scipy.ndimage import binary_erosion

    same = []
    for k in np.unique(bare.labels[b]):
        core = binary_erosion(bare.labels == k, iterations=4)
        same.append((dressed.labels[core] == k).mean() if core.any() else 1.0)
    assert min(same) > 0.9 and np.mean(same) > 0.97
    # crisp: hardly a pixel differs from all of its 4 neighbours (no speckle, no
    # blending; a few at fingertips, as on the bare body)
    def lone(labels: np.ndarray) -> int:
        lab = labels.astype(int)
        inner = lab[1:-1, 1:-1]
        return int(((inner > 0) & (inner != lab[:-2, 1:-1]) & (inner != lab[2:, 1:-1])
                    & (inner != lab[1:-1, :-2]) & (inner != lab[1:-1, 2:])).sum())

    assert lone(dressed.labels) <= max(2 * lone(bare.labels), 0.002 * d.sum())
    assert set(np.unique(dressed.labels)) <= set(range(len(shotton.names) + 1))


@pytest.mark.parametrize("as_person", [False, True])
def test_carried_things_have_their_own_class(gl_ctx, asset_dir, shotton, as_person):
    bag = {**_mid("carried", "backpack"), "as_person": as_person, "class": 0 if as_person
           else 7}
    body = build_body(asset_dir, shotton, outfit=Outfit.from_dict({"carried": bag}))
    back = look_at(np.array([0.0, 1.2, -2.5]), np.array([0.0, 1.2, 0.0]))
    view = _draw(gl_ctx, body, back, instance=3)
    hit = view.depth > 0
    if as_person:  # the person's class and instance, the label of the back under it
        assert (view.classes[hit] == PERSON).all() and (view.instances[hit] == 3).all()
        assert (view.labels[hit] > 0).all()
    else:
        bag_px = view.classes == 7
        assert bag_px.sum() > 1500  # a backpack seen from behind
        assert (view.labels[bag_px] == 0).all() and (view.instances[bag_px] == 0).all()
        person = view.classes == PERSON
        assert (view.instances[person] == 3).all() and (view.labels[person] > 0).all()


def _walk_pose(shared_mocap, base, frame):
    from vhgen.mocap.clips import load_clip
    from vhgen.mocap.retarget import load_all_maps

    clip = load_clip("walk", shared_mocap / "cmu_12_01_walk.bvh", base.rig, load_all_maps(),
                     frame_step=1, skip_first=0, max_poses=0)
    i = int(np.flatnonzero(clip.source_frames == frame)[0])
    return bone_matrices(base.rig, clip.rotations[i], clip.roots[i])


def test_a_hand_resting_on_a_coat_stays_a_hand(gl_ctx, shared_mocap, asset_dir, shotton):
    """Real motion capture (CMU 12_01, frame 319: the right palm 9 mm from the thigh).
    Garments built in the rest pose stand off the skin by their thickness, so a hand
    resting on the body sinks into a coat: most of its pixels become torso and leg
    labels. The garment program presses the coat in under the hand (shown by drawing the
    same body without that: the hand is lost)."""
    from dataclasses import replace

    base = build_body(asset_dir, shotton)
    m = _walk_pose(shared_mocap, base, 319)
    outfit = {"top": _mid("top", "jumper"), "bottom": _mid("bottom", "trousers"),
              "outer": _mid("outer", "coat", thickness_m=0.04, length=0.7)}
    coat = build_body(asset_dir, shotton, outfit=Outfit.from_dict(outfit))
    k = base.rig.index("RightHand")
    hand = m[k, :3, :3] @ base.rig.heads[k] + m[k, :3, 3]
    r_hand = shotton.names.index("R_hand") + 1
    for yaw in (-90.0, -60.0, -120.0):  # from the subject's right, the hand on the thigh
        t = np.deg2rad(yaw)
        w2c = look_at(hand + [1.2 * np.sin(t), 0.2, 1.2 * np.cos(t)], hand)
        seen = [(_draw(gl_ctx, b, w2c, m).labels == r_hand).sum()
                for b in (base, coat, replace(coat, press=np.zeros_like(coat.press)))]
        assert seen[0] > 300
        assert seen[1] >= 0.85 * seen[0], seen
        assert seen[2] < 0.3 * seen[0], seen  # the case the press fixes


def test_the_garment_program_draws_the_numpy_positions(gl_ctx, shared_mocap, asset_dir,
                                                        shotton):
    """Depth of the dressed body drawn by the garment program (hands pressing, legs
    pushing a skirt) equals the depth of the float64 positions of
    vhgen.body.contact.dressed_positions drawn as a plain mesh."""
    base = build_body(asset_dir, shotton)
    m = _walk_pose(shared_mocap, base, 319)
    outfit = {"top": _mid("top", "shirt"), "bottom": _mid("bottom", "skirt", flare=0.0),
              "outer": _mid("outer", "coat")}
    body = build_body(asset_dir, shotton, outfit=Outfit.from_dict(outfit))
    contacts = body_contacts(body.rig, body.vertices - body.offsets, body.joints)
    p = dressed_positions(body.vertices, body.offsets, body.press, body.joints, body.weights,
                          m, contacts)
    k = base.rig.index("RightHand")
    target = m[k, :3, :3] @ base.rig.heads[k] + m[k, :3, 3]
    w2c = look_at(target + [-1.5, 0.1, 0.3], target - [0, 0.2, 0])
    gpu = _draw(gl_ctx, body, w2c, m)
    ren = DepthLabelRenderer(gl_ctx, INTR)
    flat = ren.upload(p, body.faces, np.zeros((len(p), 4), int),
                      np.tile([1.0, 0, 0, 0], (len(p), 1)), body.face_labels, body.num_bones)
    ref = ren.draw([Draw(flat, np.broadcast_to(w2c, (body.num_bones, 4, 4)), 1, PERSON)])
    flat.release()
    ren.release()
    both = (gpu.depth > 0) & (ref.depth > 0)
    assert both.sum() > 5000
    assert ((gpu.depth > 0) != (ref.depth > 0)).sum() < 0.01 * both.sum()
    err = np.abs(gpu.depth[both] - ref.depth[both])
    assert np.percentile(err, 99) < 2e-4 and (gpu.labels[both] == ref.labels[both]).mean() > 0.99


def test_a_job_records_outfits_its_bodies_are_rebuilt_from(tmp_path, asset_dir, shotton):
    """Through the pipeline: each frame's manifest avatar_params (JSON) rebuilds the
    very body the frame was drawn with, byte for byte; carried things are in the store's
    `carried` class."""
    import json

    from vhgen.body.avatar import AvatarParams, build_avatar
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.frames import FrameGenerator
    from vhgen.pipeline.job import prepare_job

    p = tmp_path / "c.yaml"
    p.write_text("name: c\nseed: 3\nmotions: [builtin:demo]\nposes: {frame_step: 40}\n"
                 "avatars:\n  count: 2\n  outfit: {carried: {probability: 1, kinds: "
                 "[backpack]}}\nrender: {backend: osmesa}\n")
    cfg = JobConfig.load(p)
    job = prepare_job(cfg, asset_dir=asset_dir)
    gen, plan = FrameGenerator(job), job.plan
    try:
        carried = cfg.class_names.index("carried")
        for frame in (0, len(plan.avatar_id) - 1):
            out = gen.render_frame(frame)
            params = json.loads(out.record.avatar_params)
            planned = plan.avatars[out.record.avatar_id].outfit
            assert planned is not None and params["outfit"] == planned.to_dict()
            rebuilt = build_avatar(asset_dir, shotton, AvatarParams.from_dict(params))
            drawn = gen.describer.body(out.record.avatar_id)
            assert rebuilt.fingerprint() == drawn.fingerprint()
            assert (drawn.face_classes == carried).any()
    finally:
        gen.close()
