"""Automatic skeleton mapping on every real file in ../shared/mocap, a renaming fuzzer,
refusals, and the --explain / --map / --report command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.mocap import skeleton_fuzz as fz
from vhgen.body.skinning import posed_heads
from vhgen.cli import main
from vhgen.errors import RetargetError
from vhgen.mocap.automap import auto_map
from vhgen.mocap.bvh import parse_bvh, read_bvh
from vhgen.mocap.clips import ground_offset
from vhgen.mocap.retarget import (
    RetargetMap,
    build_retargeter,
    detect_dialect,
    load_all_maps,
)

MOCAP = Path(__file__).resolve().parents[2].parent / "shared" / "mocap"
FILES = sorted(str(p.relative_to(MOCAP)) for p in MOCAP.rglob("*.bvh")) if MOCAP.is_dir() else []
DIALECTS = MOCAP / "dialects"


def test_shared_corpus_present():
    assert len(FILES) >= 29, f"expected the shared BVH files under {MOCAP}, found {FILES}"
    assert {"cmu", "dialects"} <= {f.split("/")[0] for f in FILES}


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _source_left(m, rt, rmap, frames):
    """(F, 3) the source subject's geometric left, +Y up: up x forward, forward from the
    feet (heel to toe) where they point somewhere, else from the knees (bent forward)."""
    g, p = m.world_transforms()
    g, p = rt.world_fix @ g[frames], p[frames] @ rt.world_fix.T
    inv = {rmap.joints[n]: j for j, n in enumerate(m.names) if rmap.joints.get(n)}
    fwd = np.zeros((len(frames), 3))
    length = np.zeros(len(frames))
    for s in ("Left", "Right"):
        foot = inv[f"{s}Foot"]
        toe = inv.get(f"{s}ToeBase")
        if toe is not None:
            v = p[:, toe] - p[:, foot]
        elif np.isfinite(m.end_sites[foot]).all():
            v = g[:, foot] @ m.end_sites[foot]
        else:
            v = np.zeros((len(frames), 3))
        fwd += v
        length += np.linalg.norm(v, axis=1)
    fwd[:, 1] = 0
    if np.linalg.norm(fwd, axis=1).mean() <= 0.3 * length.mean():  # feet point down
        fwd[:] = 0
        for s in ("Left", "Right"):
            hip, knee, ank = (p[:, inv[f"{s}{b}"]] for b in ("UpLeg", "Leg", "Foot"))
            fwd += knee - 0.5 * (hip + ank)
        fwd[:, 1] = 0
    return np.cross([0.0, 1.0, 0.0], fwd)


@pytest.mark.parametrize("rel", FILES)
def test_every_shared_file_maps_grounds_and_faces(body, rel):
    """Every real file is accepted; its feet reach the floor, the head stays above them,
    and the target's left is the subject's geometric left (not just the names' left), so
    a subject facing the camera shows its left on the image right."""
    rig = body.rig
    m = read_bvh(MOCAP / rel)
    rmap = detect_dialect(m, load_all_maps())
    assert (rmap.confidence is None) == rel.startswith("cmu/"), rmap.name  # shipped maps win
    rt = build_retargeter(m, rig, rmap)
    rot, root = rt.apply(m)
    assert np.isfinite(rot).all() and np.isfinite(root).all()
    root = root.copy()
    root[:, 1] += ground_offset(rig, rot, root)
    frames = np.arange(0, m.num_frames, max(1, m.num_frames // 60))
    heads = posed_heads(rig, rot[frames], root[frames])
    tails = heads + np.einsum("fbij,bj->fbi", rot[frames], rig.tails - rig.heads)
    ends = np.concatenate([heads, tails], axis=1)[..., 1]  # (F, 2B) heights
    feet = [rig.index(n) for n in ("LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase")]
    feet = feet + [k + len(rig.names) for k in feet]
    rest_low = min(rig.heads[:, 1].min(), rig.tails[:, 1].min())
    assert abs(np.percentile(ends.min(axis=1), 5) - rest_low) < 0.02  # grounded (sampled)
    # feet on the floor when the source's feet are: the target's lowest foot point follows
    # the source's (feet, toes and their End Sites, scaled), both from their 5th percentile
    g, p = m.world_transforms()
    g, p = rt.world_fix @ g[frames], p[frames] @ rt.world_fix.T
    src_pts = []
    for j, n in enumerate(m.names):
        if rmap.joints.get(n) in ("LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase"):
            src_pts.append(p[:, j, 1])
            if np.isfinite(m.end_sites[j]).all():
                src_pts.append(p[:, j, 1] + (g[:, j] @ m.end_sites[j])[:, 1])
    src_low = np.min(src_pts, axis=0) * rt.scale
    foot_low = ends[:, feet].min(axis=1)
    gap = (foot_low - np.percentile(foot_low, 5)) - (src_low - np.percentile(src_low, 5))
    assert np.median(np.abs(gap)) < 0.06, np.median(np.abs(gap))
    lowest_is_foot = np.isin(ends.argmin(axis=1), feet)
    upright = heads[:, rig.index("Head"), 1] - ends.min(axis=1) > 1.0
    assert lowest_is_foot.mean() > 0.6 and upright.mean() > 0.6, (lowest_is_foot.mean(),
                                                                 upright.mean())
    # left: target left thigh/arm on the subject's geometric left
    left_src = _source_left(m, rt, rmap, frames)
    # frames with a clear forward cue, upright (up x forward means left only then)
    strong = (np.linalg.norm(left_src, axis=1) > 0.2 * np.linalg.norm(left_src, axis=1).mean()
              ) & (heads[:, rig.index("Head"), 1] > heads[:, rig.index("Hips"), 1] + 0.3)
    for a, b in (("LeftUpLeg", "RightUpLeg"), ("LeftArm", "RightArm")):
        d = heads[:, rig.index(a)] - heads[:, rig.index(b)]
        assert np.mean(np.sum(d * left_src, axis=1)[strong] > 0) > 0.9, (a, rel)
    # facing the camera (+Z toward a camera looking down -Z, image right = +X): turn each
    # frame so the target's feet point +Z; its left hand must then have the larger x
    fwd = (heads[:, rig.index("LeftToeBase")] - heads[:, rig.index("LeftFoot")] +
           heads[:, rig.index("RightToeBase")] - heads[:, rig.index("RightFoot")])
    ang = np.arctan2(fwd[:, 0], fwd[:, 2])
    lh = heads[:, rig.index("LeftHand")] - heads[:, rig.index("RightHand")]
    lh_x = np.cos(ang) * lh[:, 0] - np.sin(ang) * lh[:, 2]  # x after turning by -ang about Y
    lt = heads[:, rig.index("LeftUpLeg")] - heads[:, rig.index("RightUpLeg")]
    lt_x = np.cos(ang) * lt[:, 0] - np.sin(ang) * lt[:, 2]
    up_ok = heads[:, rig.index("Head"), 1] > heads[:, rig.index("Hips"), 1] + 0.3
    assert np.mean(lt_x[up_ok] > 0) > 0.9 and np.mean(lh_x[up_ok] > 0) > 0.6, rel


def test_dialect_files_conventions(body):
    """Z-up, mirrored Kinect names, Rokoko bone-local OFFSETs, units: off the geometry."""
    units = {p.name: build_retargeter(m, body.rig, auto_map(m)).units_m
             for p in DIALECTS.glob("*.bvh") for m in [read_bvh(p)]}
    assert units["jesse_dance.bvh"] == units["test.bvh"] == 0.01  # cm
    assert units["2017-10-19-11-14-48.bvh"] == 0.01
    assert units["AV_8Walk_Meredith_HVHA_Rep1.bvh"] == 0.0254  # inches
    assert 0.03 < units["jumping.bvh"] < 0.05  # no named unit fits: from the size alone
    up = {p.name: auto_map(read_bvh(p)).up for p in DIALECTS.glob("*.bvh")}
    assert up == {"jumping.bvh": "+z", "jesse_dance.bvh": "+y", "test.bvh": "+y",
                  "2017-10-19-11-14-48.bvh": "+y", "AV_8Walk_Meredith_HVHA_Rep1.bvh": "+y"}
    k = auto_map(read_bvh(DIALECTS / "2017-10-19-11-14-48.bvh"))
    assert any("mirrored" in n for n in k.notes)
    assert k.joints["WristLeft"] == "RightHand" and k.joints["HipRight"] == "LeftUpLeg"
    assert k.confidence < 0.9  # a conflict lowers the confidence
    sfu = auto_map(read_bvh(DIALECTS / "AV_8Walk_Meredith_HVHA_Rep1.bvh"))
    assert sfu.joints["Spine"] == "Spine1" and sfu.joints["LeftHand_End"] is None
    assert sfu.confidence > 0.9 and not sfu.notes


TOY = ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition "
       "Zrotation Xrotation Yrotation\nJOINT Spine\n{\nOFFSET 0 10 0\nCHANNELS 3 Zrotation "
       "Xrotation Yrotation\nJOINT Head\n{\nOFFSET 0 10 0\nCHANNELS 3 Zrotation Xrotation "
       "Yrotation\nEnd Site\n{\nOFFSET 0 5 0\n}\n}\n}\nJOINT LeftLeg\n{\nOFFSET 5 -10 0\n"
       "CHANNELS 3 Zrotation Xrotation Yrotation\nEnd Site\n{\nOFFSET 0 -10 0\n}\n}\n}\n"
       "MOTION\nFrames: 1\nFrame Time: 0.1\n" + "0 " * 15 + "\n")


def test_toy_and_partial_skeletons_refused(shared_mocap):
    with pytest.raises(RetargetError, match=r"toy.bvh: not a complete humanoid.*no left "
                                            r"foot, right foot, left hand, right hand"):
        detect_dialect(parse_bvh(TOY, "toy.bvh"), load_all_maps())
    m = read_bvh(shared_mocap / "02_01.bvh")
    one_arm = fz.drop_subtree(m, m.index("RightShoulder"))
    with pytest.raises(RetargetError, match="right hand"):
        detect_dialect(one_arm, load_all_maps())
    no_shin = fz.remove(fz.remove(m, m.index("LeftLeg")), m.index("LeftFoot") - 1)
    with pytest.raises(RetargetError, match="left (shin|thigh)"):
        detect_dialect(no_shin, load_all_maps())
    no_head = fz.drop_subtree(m, m.index("Neck"))
    with pytest.raises(RetargetError, match="head"):
        detect_dialect(no_head, load_all_maps())


def _target(m, rig, rmap=None, frames=None):
    rmap = rmap or auto_map(m)
    rt = build_retargeter(m, rig, rmap)
    rot, root = rt.apply(m, frames)
    dirs = _unit(np.einsum("fbij,bj->fbi", rot, rig.tails - rig.heads))
    return rmap, rot, root, dirs


BASES = {"02_01": ("cmu/02_01.bvh", 120), "sfu": ("dialects/AV_8Walk_Meredith_HVHA_Rep1.bvh", 150),
         "rokoko": ("dialects/jesse_dance.bvh", 150), "fair1": ("dialects/jumping.bvh", 150)}


@pytest.mark.parametrize("seed", range(22))
def test_fuzzed_skeletons_give_the_same_world_bones(body, seed):
    """Rename into another convention, reorder children, insert unnamed joints, rotate
    the rest pose (bone-local frames), switch the up axis, add a static root, mirror the
    names: the target's world bone directions (and rotations, root path) do not change."""
    rng = np.random.default_rng(seed)
    key = list(BASES)[seed % len(BASES)]
    rel, n = BASES[key]
    m = fz.crop(read_bvh(MOCAP / rel), n)
    rmap0, rot0, root0, dirs0 = _target(m, body.rig)
    f = m
    conv = list(fz.CONVENTIONS)[seed % len(fz.CONVENTIONS)]
    f = fz.rename(f, rmap0.joints, conv)
    # joints inserted above mapped joints (between a mapped joint and its mapped parent
    # chain); above an unmapped finger they would change what the hand points at
    mapped_names = {f.names[j] for j, n in enumerate(m.names) if rmap0.joints[n]}
    done = [conv]
    if seed % 3 == 0:
        f, _ = fz.mirror_names(f), done.append("mirror")
        mapped_names = set(fz.mirror_names(fz.make(m, sorted(mapped_names), [-1] * len(
            mapped_names), m.offsets[:len(mapped_names)], m.end_sites[:len(mapped_names)],
            m.rotations[:, :len(mapped_names)], m.translations[:, :len(mapped_names)])).names)
    for k in range(int(rng.integers(1, 4))):
        mapped = [j for j, nm in enumerate(f.names) if f.parents[j] >= 0 and nm in mapped_names]
        c = int(rng.choice(mapped))
        f = fz.insert(f, c, f"Xtra{k}", float(rng.uniform(0.2, 0.8)))
        done.append(f"insert above {f.names[c + 1]}")
    f = fz.reorder(f, rng)
    if seed % 2 == 0:
        f, _ = fz.rotate_rest(f, rng), done.append("rest rotated")
    up = ["+z", "-z", "+x", "-x", "-y", "+y"][seed % 6]
    f, _ = fz.switch_up(f, up, rmap0.up), done.append(f"up {up}")
    if seed % 4 == 1:
        f, _ = fz.static_root(f, rng), done.append("static root")
    rmap1, rot1, root1, dirs1 = _target(f, body.rig)
    assert rmap1.up == up, done
    np.testing.assert_allclose(dirs1, dirs0, atol=1e-6, err_msg=str(done))
    np.testing.assert_allclose(rot1, rot0, atol=1e-6, err_msg=str(done))
    np.testing.assert_allclose(root1, root0, atol=1e-6, err_msg=str(done))


def test_removed_intermediate_joints_keep_limb_directions(body, shared_mocap):
    m = fz.crop(read_bvh(shared_mocap / "02_01.bvh"), 120)
    _, _, _, dirs0 = _target(m, body.rig)
    f = m
    for name in ("LHipJoint", "Spine", "Neck1", "RightShoulder"):
        f = fz.remove(f, f.names.index(name))
    assert fz.same_world(m, f, [(m.index(n), f.names.index(n)) for n in f.names]) < 1e-9
    rmap, _, _, dirs1 = _target(f, body.rig)
    limbs = [body.rig.index(f"{s}{b}") for s in ("Left", "Right")
             for b in ("UpLeg", "Leg", "Arm", "ForeArm", "Hand", "Foot")]
    np.testing.assert_allclose(dirs1[:, limbs], dirs0[:, limbs], atol=1e-6)
    assert rmap.joints["RightArm"] == "RightArm" and "RightShoulder" not in rmap.joints


def test_explain_writes_a_map_that_round_trips(tmp_path, body, capsys):
    src = DIALECTS / "jumping.bvh"
    out = tmp_path / "jump.yaml"
    assert main(["corpus", "build", "--explain", str(src), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "automatic, confidence" in text and "up +z" in text
    assert "RightHandThumb1" in text and "folds into RightHand" in text
    m = read_bvh(src)
    user = RetargetMap.load(out)
    _, rot0, root0, _ = _target(m, body.rig, detect_dialect(m, load_all_maps()))
    _, rot1, root1, _ = _target(m, body.rig, user)
    np.testing.assert_array_equal(rot1, rot0)
    np.testing.assert_array_equal(root1, root0)
    # an edit takes effect: the neck folded into the chest
    out.write_text(out.read_text().replace("  Neck:", "  Neck: null #").replace(
        "Neck                           #", "#"))
    edited = RetargetMap.load(out)
    assert edited.joints["Neck"] is None
    _, rot2, _, _ = _target(m, body.rig, edited)
    assert not np.allclose(rot2[:, body.rig.index("Neck")], rot0[:, body.rig.index("Neck")])


def test_corpus_report_and_map_flag(tmp_path, capsys):
    rep = tmp_path / "r.json"
    files = [str(DIALECTS / "AV_8Walk_Meredith_HVHA_Rep1.bvh"),
             str(DIALECTS / "2017-10-19-11-14-48.bvh")]
    assert main(["corpus", "build", *files, "-o", str(tmp_path / "p.parquet"), "--report",
                 str(rep), "--workers", "1", "--frame-step", "10"]) == 0
    out = capsys.readouterr().out
    entries = json.loads(rep.read_text())["files"]
    assert [e["dialect"] for e in entries] == ["auto", "auto"]
    assert all(0 < e["confidence"] <= 1 and e["poses_kept"] > 0 and
               "ref_error_deg" in e for e in entries)
    assert "mirrored" in entries[1]["notes"][0]
    assert "conf" in out and "AV_8Walk_Meredith_HVHA_Rep1.bvh" in out and "ref err" in out
    # --map: a written map used for the file it was made for
    ymap = tmp_path / "sfu.yaml"
    assert main(["corpus", "build", "--explain", files[0], "-o", str(ymap)]) == 0
    assert main(["corpus", "build", files[0], "-o", str(tmp_path / "q.parquet"), "--map",
                 str(ymap), "--workers", "1", "--frame-step", "10"]) == 0


@pytest.mark.parametrize("argv, field", [
    (["--explain", "/nonexistent.bvh"], "--explain"),
    (["x.bvh", "-o", "p.parquet", "--map", "/nonexistent.yaml"], "--map"),
    (["--explain", str(DIALECTS / "jumping.bvh"), "-o", "m.parquet"], "--output"),
    ([], "inputs"),
    (["a.bvh", "--explain", str(DIALECTS / "jumping.bvh")], "--explain"),
])
def test_bad_flags_one_line(capsys, argv, field):
    assert main(["corpus", "build", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("vhgen: error:") and field in err[0], err


def test_positions_on_every_joint_and_mixed_euler_orders_as_text(body, shared_mocap):
    """Through the parser: 6 channels on every joint, random Euler orders, angles beyond
    +-180, CRLF, a blank line after MOTION, leading spaces: same mapping, same poses."""
    m = fz.crop(read_bvh(shared_mocap / "02_01.bvh"), 60)
    f = parse_bvh(fz.to_bvh_text(fz.reorder(m, np.random.default_rng(3)),
                                 np.random.default_rng(3)), "text.bvh")
    assert all(len(c) == 6 for c in f.channels)
    rmap0, rot0, root0, _ = _target(m, body.rig)
    rmap1, rot1, root1, _ = _target(f, body.rig)
    assert {n: rmap1.joints[n] for n in m.names} == rmap0.joints
    np.testing.assert_allclose(rot1, rot0, atol=1e-6)
    np.testing.assert_allclose(root1, root0, atol=1e-6)


def test_scene_config_takes_a_written_map_relative_to_itself(tmp_path, body):
    """`retarget: my.map.yaml` in a scene config, as --explain wrote it, drives load_poses
    (the `vhgen generate` path) exactly like the automatic mapping."""
    from vhgen.errors import ConfigError
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.poses import load_poses

    src = DIALECTS / "AV_8Walk_Meredith_HVHA_Rep1.bvh"
    (tmp_path / "maps").mkdir()
    assert main(["corpus", "build", "--explain", str(src), "-o",
                 str(tmp_path / "maps" / "sfu.yaml")]) == 0
    scene = (Path(__file__).resolve().parents[2] / "configs" / "scenes" / "default.yaml")
    text = scene.read_text().replace("motions: [builtin:demo]", f"motions: [{src}]")
    cfg_path = tmp_path / "scene.yaml"
    cfg_path.write_text(text.replace("retarget: auto", "retarget: maps/sfu.yaml"))
    cfg = JobConfig.load(cfg_path)
    assert cfg.retarget == str((tmp_path / "maps" / "sfu.yaml").resolve())
    by_map = load_poses(cfg.motions, body.rig, RetargetMap.load(cfg.retarget), cfg.poses)
    auto = load_poses(cfg.motions, body.rig, load_all_maps(), cfg.poses)
    assert auto.report[0]["dialect"] == "auto" and by_map.num_poses == auto.num_poses > 0
    np.testing.assert_array_equal(by_map.rotations, auto.rotations)
    cfg_path.write_text(text.replace("retarget: auto", "retarget: maps/missing.yaml"))
    with pytest.raises(ConfigError, match="retarget: map file .*missing.yaml does not exist"):
        JobConfig.load(cfg_path)


def test_explain_refuses_a_toy_in_one_line(tmp_path, capsys):
    toy = tmp_path / "toy.bvh"
    toy.write_text(TOY)
    assert main(["corpus", "build", "--explain", str(toy), "-o", str(tmp_path / "t.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "toy.bvh: not a complete humanoid" in err[0]
    assert "no left foot" in err[0] and not (tmp_path / "t.yaml").exists()
