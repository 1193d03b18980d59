"""The one clip loader and its one report format (corpus build, generate, attrs)."""

import dataclasses

import numpy as np

from vhgen.mocap.clips import (
    BUILTIN_MOTION,
    Clip,
    ClipFailure,
    ClipReport,
    expand_motion_paths,
    load_clip,
    select_frames,
)
from vhgen.mocap.retarget import load_all_maps

FIELDS = ["file", "status", "frames", "poses_read", "poses_kept", "dialect", "units_m",
          "error", "mapping", "confidence", "up", "reference_frame", "ref_error_deg",
          "ref_error_bone", "notes"]


def test_real_clip_loads_grounded_with_report(shared_mocap, body):
    clip = load_clip("02_01.bvh", shared_mocap / "02_01.bvh", body.rig, load_all_maps(),
                     frame_step=10)
    assert isinstance(clip, Clip)
    r = clip.report
    assert list(r.to_dict()) == FIELDS
    assert (r.status, r.dialect, r.frames) == ("ok", "cmu_mb", 343)
    assert r.poses_read == r.poses_kept == len(clip.source_frames) == 35
    assert clip.rotations.shape == (35, len(body.rig.names), 3, 3)
    assert np.isfinite(clip.roots).all() and r.units_m is not None and r.units_m > 0


def test_broken_files_are_typed_failures_never_raise(tmp_path, shared_mocap, body):
    bad = tmp_path / "broken.bvh"
    bad.write_text((shared_mocap / "02_01.bvh").read_text().replace("Frames: 343",
                                                                    "Frames: 400"))
    junk = tmp_path / "junk.bvh"
    junk.write_bytes(b"\x00\x01")
    for p, text in ((bad, "data rows"), (junk, "binary")):
        out = load_clip(p.name, p, body.rig, load_all_maps())
        assert isinstance(out, ClipFailure)
        assert out.report.status == "skipped" and text in out.report.error
    # the same file, allowed truncated, loads
    assert isinstance(load_clip("b", bad, body.rig, load_all_maps(), allow_truncated=True), Clip)


def test_units_override_is_recorded(shared_mocap, body):
    maps = load_all_maps()
    a = load_clip("a", shared_mocap / "02_01.bvh", body.rig, maps, frame_step=50)
    b = load_clip("b", shared_mocap / "02_01.bvh", body.rig, maps, frame_step=50,
                  units_m=0.01)
    assert isinstance(a, Clip) and isinstance(b, Clip)
    assert b.report.units_m == 0.01 != a.report.units_m
    # the root path is scaled from the skeletons' proportions, not from the units
    np.testing.assert_array_equal(a.roots, b.roots)


def test_frame_selection_and_builtin_name():
    np.testing.assert_array_equal(select_frames(10, 3, 1), [1, 4, 7])
    assert len(select_frames(100, 1, 0, 7)) == 7
    (name, path), = expand_motion_paths([BUILTIN_MOTION])
    assert name == BUILTIN_MOTION and path.is_file()
    assert [f.name for f in dataclasses.fields(ClipReport)] == FIELDS
