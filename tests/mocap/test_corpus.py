import json

import numpy as np
import pytest

from vhgen.cli import main
from vhgen.errors import RetargetError
from vhgen.mocap.bvh import read_bvh
from vhgen.mocap.posetable import PoseTable, read_pose_table, write_pose_table
from vhgen.mocap.retarget import build_retargeter, detect_dialect, load_all_maps
from vhgen.mocap.units import UNITS_M, detect_units


@pytest.mark.parametrize("name, dialect, units", [
    ("01_01.bvh", "cmu_mb", "cmu"), ("02_01.bvh", "cmu_mb", "cmu"),
    ("02_02.bvh", "daz_cmu", "cm"), ("03_03.bvh", "daz_cmu", "cm"),
    ("10_01.bvh", "bvh19", "inch")])
def test_dialects_and_units_detected(shared_mocap, body, name, dialect, units):
    m = read_bvh(shared_mocap / name)
    rmap = detect_dialect(m, load_all_maps())
    assert rmap.name == dialect and rmap.units_m == UNITS_M[units]
    from vhgen.mocap.units import skeleton_height

    rest = m.rest_positions()
    assert detect_units(skeleton_height(rest, rest + m.end_sites))[0] == units
    rot, root = build_retargeter(m, body.rig, rmap).apply(m)
    assert np.isfinite(rot).all() and np.isfinite(root).all()


def test_unknown_skeleton_error_names_joints(body):
    from vhgen.mocap.bvh import parse_bvh

    text = ("HIERARCHY\nROOT pelvis\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
            "JOINT femur_l\n{\nOFFSET 1 -1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
            "End Site\n{\nOFFSET 0 -1 0\n}\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n"
            "0 0 0 0 0 0\n")
    m = parse_bvh(text, "odd.bvh")
    with pytest.raises(RetargetError) as ei:
        detect_dialect(m, load_all_maps())
    assert "odd.bvh" in str(ei.value) and "pelvis" in str(ei.value)
    assert "femur_l" in str(ei.value)


def test_retarget_folds_null_joints_into_mapped_bones(shared_mocap, body):
    """daz_cmu maps the eyes and most finger joints to null: the mapped bones still carry
    the full world rotation (chains through unmapped joints keep their orientation)."""
    m = read_bvh(shared_mocap / "02_02.bvh")
    rmap = detect_dialect(m, load_all_maps())
    rt = build_retargeter(m, body.rig, rmap)
    rot, _ = rt.apply(m)
    g, _ = m.world_transforms()
    k = body.rig.index("Head")
    j = m.index("head")
    corr = rt.source_ref[k].T @ rt.target_ref[k]
    np.testing.assert_allclose(rot[:, k], g[:, j] @ corr, atol=1e-12)


def test_zero_length_source_bone_gives_no_nan(body):
    """A mapped limb of zero length cannot be straightened: it keeps its parent's
    reference orientation instead of producing NaN."""
    from vhgen.mocap.bvh import parse_bvh
    from vhgen.mocap.retarget import RetargetMap

    skel = ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\n"
            "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
            "JOINT LeftUpLeg\n{\nOFFSET 1 -1 0\nCHANNELS 3 Zrotation Yrotation Xrotation\n"
            "JOINT LeftLeg\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Yrotation Xrotation\n"
            "End Site\n{\nOFFSET 0 -8 0\n}\n}\n}\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n"
            "0 17 0 0 0 0 0 0 0 0 0 0\n0 17 0 10 20 30 40 50 60 70 80 90\n")
    m = parse_bvh(skel, "zero.bvh")
    rmap = RetargetMap.load("cmu_mb")
    rt = build_retargeter(m, body.rig, rmap)
    rot, root = rt.apply(m)
    assert np.isfinite(rot).all() and np.isfinite(root).all()
    k = body.rig.index("LeftUpLeg")
    np.testing.assert_allclose(rt.source_ref[k], rt.source_ref[body.rig.index("LHipJoint")])


def test_pose_table_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    from vhgen.rotations import euler_to_matrix

    rot = euler_to_matrix(rng.uniform(-3, 3, size=(5, 4, 3)), "XYZ")
    t = PoseTable(["a.bvh"] * 3 + ["b.bvh"] * 2, np.arange(5, dtype=np.int32), ["cmu_mb"] * 5,
                  np.full(5, 0.056444), rng.normal(size=(5, 3)), rot, "cmu_mb",
                  ["A", "B", "C", "D"], {"metric": "angle"})
    back = read_pose_table(write_pose_table(tmp_path / "p.parquet", t))
    np.testing.assert_array_equal(back.local_rotations, rot)
    np.testing.assert_array_equal(back.root_translation, t.root_translation)
    assert back.bones == t.bones and back.source_file == t.source_file
    assert back.settings == {"metric": "angle"}


def test_corpus_cli_skips_bad_files_and_reports(tmp_path, shared_mocap, capsys):
    import shutil

    src = tmp_path / "in"
    src.mkdir()
    for name in ("02_01.bvh", "10_01.bvh", "02_02.bvh"):
        shutil.copy(shared_mocap / name, src / name)  # a temporary corpus, not in the repo
    (src / "broken.bvh").write_text((shared_mocap / "02_01.bvh").read_text().replace(
        "Frames: 343", "Frames: 400"))
    (src / "garbage.BVH").write_bytes(b"\x00\x01\x02")
    out, rep = tmp_path / "poses.parquet", tmp_path / "report.json"
    rc = main(["corpus", "build", str(src), "-o", str(out), "--report", str(rep),
               "--min-angle-deg", "5", "--workers", "2"])
    assert rc == 0
    report = json.loads(rep.read_text())
    by = {f["file"].split("/")[-1]: f for f in report["files"]}
    assert by["broken.bvh"]["status"] == "skipped" and "343 data rows" in by["broken.bvh"]["error"]
    assert by["garbage.BVH"]["status"] == "skipped" and "binary" in by["garbage.BVH"]["error"]
    assert by["10_01.bvh"]["dialect"] == "bvh19" and by["10_01.bvh"]["poses_kept"] > 0
    table = read_pose_table(out)
    assert table.num_poses == sum(f["poses_kept"] for f in report["files"])
    assert set(table.dialect) == {"cmu_mb", "daz_cmu", "bvh19"}
    assert table.local_rotations.shape[1:] == (31, 3, 3)
    assert "broken.bvh" in capsys.readouterr().err
    assert main(["corpus", "build", str(src), "-o", str(out), "--strict"]) == 2
    assert main(["corpus", "build", str(src / "garbage.BVH"), "-o", str(out)]) == 2
