import numpy as np
import pytest

from vhgen.errors import BVHError
from vhgen.mocap.bvh import parse_bvh, read_bvh
from vhgen.rotations import euler_to_matrix

TWO_JOINTS = """HIERARCHY
ROOT hip
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT knee
\t{
\t\tOFFSET 0 -2 0
\t\tCHANNELS 3 Xrotation Yrotation Zrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -1.5 0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333333333333
1 2 3 0 0 0 0 0 0
1.0e0 2 3 90 0 0 0 0 90
"""


def test_two_joint_clip_kinematics():
    m = parse_bvh(TWO_JOINTS)
    assert m.names == ["hip", "knee"]
    assert m.parents.tolist() == [-1, 0]
    assert m.frame_time == pytest.approx(0.0333333333333333)
    p = m.world_positions()
    assert p.shape == (2, 2, 3) and p.dtype == np.float64
    np.testing.assert_allclose(p[0], [[1, 2, 3], [1, 0, 3]])
    # frame 1: root turns 90 deg about Z: the knee offset (0,-2,0) goes to (2,0,0)
    np.testing.assert_allclose(p[1], [[1, 2, 3], [3, 2, 3]], atol=1e-12)
    np.testing.assert_allclose(m.end_sites[1], [0, -1.5, 0])
    assert np.isnan(m.end_sites[0]).all()


@pytest.mark.parametrize("eol", ["\n", "\r\n", "\r"])
def test_line_endings_and_mixed(eol):
    text = TWO_JOINTS.replace("\n", eol)
    m = parse_bvh(text)
    assert m.num_frames == 2
    mixed = "".join(line + ("\r\n" if i % 3 else "\n")
                    for i, line in enumerate(TWO_JOINTS.splitlines()))
    assert parse_bvh(mixed).num_frames == 2


def _slow_world_positions(m):
    """Obvious reference: per frame, per joint, 4x4 products."""
    out = np.zeros((m.num_frames, m.num_joints, 3))
    for f in range(m.num_frames):
        mats = []
        for j in range(m.num_joints):
            t = np.eye(4)
            t[:3, :3] = m.rotations[f, j]
            t[:3, 3] = m.translations[f, j]
            mats.append(t if m.parents[j] < 0 else mats[m.parents[j]] @ t)
            out[f, j] = mats[j][:3, 3]
    return out


@pytest.mark.parametrize("name", ["01_01.bvh", "02_01.bvh", "cmu_12_01_walk.bvh", "rest.bvh",
                                  "10_01.bvh", "02_02.bvh"])
def test_real_files_parse_and_fk_matches_reference(shared_mocap, name):
    m = read_bvh(shared_mocap / name)
    assert m.rotations.shape == (m.num_frames, m.num_joints, 3, 3)
    sel = slice(0, min(m.num_frames, 40))
    fast = m.world_positions()[sel]
    slow = _slow_world_positions(m)[sel] if m.num_frames <= 40 else None
    if slow is None:
        sub = type(m)(m.names, m.parents, m.offsets, m.end_sites, m.channels, m.frame_time,
                      m.rotations[sel], m.translations[sel])
        slow = _slow_world_positions(sub)
    np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=1e-12)


def test_whole_shared_corpus_parses_with_declared_frame_counts(shared_mocap):
    expected = {"01_01.bvh": 2752, "01_03.bvh": 4511, "02_01.bvh": 343, "05_06.bvh": 885,
                "rest.bvh": 1, "10_01.bvh": 201, "02_02.bvh": 299, "49_06.bvh": 482}
    files = sorted(shared_mocap.glob("*.bvh"))
    assert len(files) >= 24
    for f in files:
        m = read_bvh(f)
        assert np.isfinite(m.world_positions()).all(), f
        if f.name in expected:
            assert m.num_frames == expected[f.name]


def test_finger_spellings(shared_mocap):
    assert "LFingers" in read_bvh(shared_mocap / "01_01.bvh").names
    assert "LeftHandIndex1" in read_bvh(shared_mocap / "02_01.bvh").names


def test_cmu_rotation_order_matches_euler(shared_mocap):
    m = read_bvh(shared_mocap / "02_01.bvh")
    row = np.array(open(shared_mocap / "02_01.bvh").read().split("Frame Time:")[1]
                   .splitlines()[1].split(), float)
    np.testing.assert_allclose(m.rotations[0, 0], euler_to_matrix(np.deg2rad(row[3:6]), "ZYX"))
    np.testing.assert_allclose(m.translations[0, 0], row[:3])


def _err(text, **kw):
    with pytest.raises(BVHError) as ei:
        parse_bvh(text, "clip.bvh", **kw)
    return ei.value


def test_frame_count_mismatch_says_rows_found():
    e = _err(TWO_JOINTS.replace("Frames: 2", "Frames: 5"))
    assert "5" in str(e) and "2 data rows" in str(e) and e.path == "clip.bvh"
    m = parse_bvh(TWO_JOINTS.replace("Frames: 2", "Frames: 5"), allow_truncated=True)
    assert m.num_frames == 2


def test_truncated_last_line():
    text = TWO_JOINTS.rstrip("\n")[:-6] + "\n"
    e = _err(text)
    assert e.line == 20 and "values, expected 9" in str(e)
    assert parse_bvh(text.replace("Frames: 2", "Frames: 2"), allow_truncated=True).num_frames == 1


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_non_finite_values_are_errors(bad):
    e = _err(TWO_JOINTS.replace("1 2 3 0 0 0 0 0 0", f"1 2 3 0 {bad} 0 0 0 0"))
    assert e.line == 19 and "non-finite" in str(e)


def test_other_errors_name_the_line():
    assert "duplicate joint name 'hip'" in str(_err(TWO_JOINTS.replace("JOINT knee", "JOINT hip")))
    e = _err(TWO_JOINTS.replace("Xrotation Yrotation Zrotation", "Xrotation Yrotation Wrotation"))
    assert e.line == 9 and "unknown channel 'Wrotation'" in str(e)
    assert "not a number" in str(_err(TWO_JOINTS.replace("OFFSET 0 -2 0", "OFFSET 0 abc 0")))
    e = _err(TWO_JOINTS.replace("CHANNELS 3", "CHANNELS 4"))
    assert "CHANNELS says 4 but lists 3" in str(e)
    assert "'x' is not a number" in str(_err(TWO_JOINTS.replace("1 2 3 0 0 0", "1 x 3 0 0 0")))


def test_empty_and_binary_files(tmp_path):
    (tmp_path / "empty.bvh").write_bytes(b"")
    (tmp_path / "blank.bvh").write_bytes(b"\n\n  \n")
    (tmp_path / "garbage.bvh").write_bytes(bytes(range(256)) * 8)
    for name in ("empty.bvh", "blank.bvh", "garbage.bvh"):
        with pytest.raises(BVHError) as ei:
            read_bvh(tmp_path / name)
        assert name in str(ei.value)
    with pytest.raises(BVHError, match="cannot read"):
        read_bvh(tmp_path / "missing.bvh")


def test_one_frame_and_position_channels_on_a_child():
    text = TWO_JOINTS.replace("CHANNELS 3 Xrotation Yrotation Zrotation",
                              "CHANNELS 4 Yposition Xrotation Yrotation Zrotation")
    text = text.split("MOTION")[0] + "MOTION\nFrames: 1\nFrame Time: 1e-2\n1 2 3 0 0 0 -5 0 0 0\n"
    m = parse_bvh(text)
    assert m.num_frames == 1 and m.frame_time == pytest.approx(0.01)
    # the Yposition channel replaces the offset's y (Blender's reading), x/z keep the offset
    np.testing.assert_allclose(m.world_positions()[0, 1], [1, -3, 3])


@pytest.mark.parametrize("name", ["01_03.bvh", "02_02.bvh", "10_01.bvh", "49_06.bvh"])
def test_fk_agrees_with_independent_scipy_implementation(shared_mocap, name):
    """scipy's Rotation (intrinsic, upper-case axes) and a per-joint recursion written
    differently: joint positions agree to 1e-9 relative on real files of three dialects."""
    from scipy.spatial.transform import Rotation

    m = read_bvh(shared_mocap / name)
    text = (shared_mocap / name).read_text().replace("\r", "")
    rows = np.array([ln.split() for ln in text.split("Frame Time:")[1].split("\n")[1:]
                     if ln.strip()], dtype=float)
    rows = rows[:: max(1, len(rows) // 50)]
    frames = np.arange(0, m.num_frames, max(1, m.num_frames // 50))[: len(rows)]
    ref = np.zeros((len(rows), m.num_joints, 3))
    col = 0
    glob_r = [None] * m.num_joints
    for j, chans in enumerate(m.channels):
        vals = rows[:, col:col + len(chans)]
        col += len(chans)
        rot_axes = "".join(c[0] for c in chans if c.endswith("rotation"))
        rot_vals = vals[:, [i for i, c in enumerate(chans) if c.endswith("rotation")]]
        local_t = np.tile(m.offsets[j], (len(rows), 1))
        for i, c in enumerate(chans):
            if c.endswith("position"):
                local_t[:, "XYZ".index(c[0])] = vals[:, i]
        local_r = Rotation.from_euler(rot_axes.upper(), rot_vals, degrees=True)
        p = m.parents[j]
        if p < 0:
            glob_r[j], ref[:, j] = local_r, local_t
        else:
            glob_r[j] = glob_r[p] * local_r
            ref[:, j] = ref[:, p] + glob_r[p].apply(local_t)
    got = m.world_positions()[frames]
    scale = np.abs(ref).max()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9 * scale)


def test_100k_frames_scientific_notation_long_frame_time():
    head = TWO_JOINTS.split("MOTION")[0]
    n = 120_000
    rng = np.random.default_rng(0)
    vals = rng.uniform(-180, 180, size=(n, 9))
    body = "\n".join(" ".join(f"{v:.6e}" for v in r) for r in vals)
    text = f"{head}MOTION\nFrames: {n}\nFrame Time: 0.008333333333333333333\n{body}\n"
    m = parse_bvh(text)
    assert m.num_frames == n and m.frame_time == pytest.approx(1 / 120)
    np.testing.assert_allclose(m.translations[:, 0], vals[:, :3], rtol=1e-6)
    p = m.world_positions()
    assert p.shape == (n, 2, 3) and np.isfinite(p).all()
    # bone length is preserved in every frame: rotations are orthonormal
    np.testing.assert_allclose(np.linalg.norm(p[:, 1] - p[:, 0], axis=1), 2.0, rtol=1e-12)
