"""`vhgen forest ...` end to end on small stores; user errors are one line, exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from tests.forest.conftest import two_boxes, write_store
from vhgen.cli import main
from vhgen.forest.trees import Forest

SMALL = ["--trees", "2", "--depth", "6", "--pixels-per-image", "200", "--features", "40",
         "--thresholds", "8", "--max-offset", "40", "--min-samples", "4", "--quiet"]


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_train_eval_label_export(tmp_path, capsys, boxes_store):
    forest = tmp_path / "f.npz"
    code, out, _ = run(capsys, "forest", "train", boxes_store, "--out", str(forest), *SMALL)
    assert code == 0 and "wrote" in out
    f = Forest.load(forest)
    assert f.meta["fx"] == 525.0 and f.meta["label_scheme"] == "pcl25"
    assert f.meta["params"]["trees"] == 2 and len(f.meta["trees"][0]["levels"]) >= 2

    d, lab = two_boxes(5, seed=77)
    test = write_store(tmp_path / "test.zarr", d, lab)
    code, out, err = run(capsys, "forest", "eval", str(forest), test, "--json",
                         str(tmp_path / "e.json"), "--out", str(tmp_path / "ev"))
    assert code == 0 and err == ""
    res = json.loads((tmp_path / "e.json").read_text())
    assert res["pixel_accuracy"] == 1.0 and res["mean_per_class"] == 1.0
    assert [p["name"] for p in res["per_part"]] == ["Lfoot", "Lleg"]
    assert (tmp_path / "ev" / "confusion.png").stat().st_size > 1000
    assert (tmp_path / "ev" / "contact_sheet.png").is_file()

    # a store from another focal length: a note that the probes follow it, not an error
    other = write_store(tmp_path / "fx.zarr", d, lab, fx=571.26)
    code, _, err = run(capsys, "forest", "eval", str(forest), other)
    assert code == 0 and "focal length fx=571.26" in err and "scaled by 1.088" in err

    png = tmp_path / "depth.png"
    Image.fromarray(d[0]).save(png)
    code, out, _ = run(capsys, "forest", "label", str(forest), str(png), "-o",
                       str(tmp_path / "lab.png"))
    assert code == 0
    np.testing.assert_array_equal(np.array(Image.open(tmp_path / "lab.png")), lab[0])
    # the same frame as an organized PCD cloud (OpenNI's NaN for no measurement): the same
    # labels, and its recovered focal length is checked against the forest's
    from vhgen.camera import Intrinsics
    from vhgen.depthfile import write_pcd

    h, w = d[0].shape
    pcd = write_pcd(tmp_path / "depth.pcd", d[0], Intrinsics(w, h, 525.0, 525.0, 39.5, 29.5))
    code, out, err = run(capsys, "forest", "label", str(forest), str(pcd), "-o",
                         str(tmp_path / "lab2.png"))
    assert code == 0 and err == ""
    np.testing.assert_array_equal(np.array(Image.open(tmp_path / "lab2.png")), lab[0])
    far = write_pcd(tmp_path / "f571.pcd", d[0], Intrinsics(w, h, 571.0, 571.0, 39.5, 29.5))
    code, _, err = run(capsys, "forest", "label", str(forest), str(far), "-o",
                       str(tmp_path / "lab3.png"))
    assert code == 0 and "fx=571 px" in err and "scaled by 1.088" in err

    # --instances: the people of the segmentation stage as an 8-bit image
    code, _, err = run(capsys, "forest", "label", str(forest), str(pcd), "-o",
                       str(tmp_path / "lab4.png"), "--instances", str(tmp_path / "inst.png"))
    assert code == 2 and "--instances" in err and "--segment" in err
    code, out, err = run(capsys, "forest", "label", str(forest), str(pcd), "-o",
                         str(tmp_path / "lab4.png"), "--segment", "--instances",
                         str(tmp_path / "inst.png"))
    assert code == 0 and "people (pixel value = person" in out
    from vhgen.forest.segment import Segmenter

    inst = np.array(Image.open(tmp_path / "inst.png"))
    seg_labels = np.array(Image.open(tmp_path / "lab4.png"))
    assert inst.dtype == np.uint8 and inst.shape == d[0].shape
    np.testing.assert_array_equal(inst, Segmenter().instances(
        d[0], Intrinsics(w, h, 525.0, 525.0, 39.5, 29.5), seg_labels))
    assert ((inst > 0) == (seg_labels > 0)).all()

    code, out, _ = run(capsys, "forest", "export", str(forest), "--format", "pcl", "-o",
                       str(tmp_path / "pcl"))
    assert code == 0 and (tmp_path / "pcl" / "tree_1.txt").is_file()
    # the exported trees evaluate like the forest they came from (one vote each here)
    code, out, _ = run(capsys, "forest", "eval", str(tmp_path / "pcl"), test)
    assert code == 0 and "pixel_accuracy 1.0000" in out


def one_line_error(capsys, *argv: str, match: str) -> str:
    code, out, err = run(capsys, *argv)
    assert code == 2, (out, err)
    assert err.startswith("vhgen: error: ") and err.count("\n") == 1, err
    assert match in err, err
    return err


def test_cli_errors(tmp_path, capsys, boxes_store):
    out = str(tmp_path / "f.npz")
    one_line_error(capsys, "forest", "train", str(tmp_path / "missing.zarr"), "--out", out,
                   match="missing.zarr: no such store")
    d, lab = two_boxes(2, seed=1)
    nolab = write_store(tmp_path / "nolab.zarr", d, None)
    one_line_error(capsys, "forest", "train", nolab, "--out", out, match="no `labels` array")
    other = write_store(tmp_path / "s31.zarr", d, lab, scheme="shotton31")
    one_line_error(capsys, "forest", "train", boxes_store, other, "--out", out,
                   match="label scheme 'shotton31'")
    one_line_error(capsys, "forest", "train", boxes_store, "--out", out, "--depth", "0",
                   match="--depth 0")
    one_line_error(capsys, "forest", "train", boxes_store, "--out", out, "--max-frames", "0",
                   match="--max-frames 0")
    empty = write_store(tmp_path / "empty.zarr", np.zeros_like(d), lab)
    one_line_error(capsys, "forest", "train", empty, "--out", out, match="no training pixels")
    assert main(["forest", "train", boxes_store, "--out", out, *SMALL]) == 0
    capsys.readouterr()
    one_line_error(capsys, "forest", "eval", out, other, match="label scheme mismatch")
    one_line_error(capsys, "forest", "eval", str(tmp_path / "nope.npz"), boxes_store,
                   match="nope.npz: no such forest file")
    rgb = tmp_path / "rgb.png"
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(rgb)
    one_line_error(capsys, "forest", "label", out, str(rgb), "-o", str(tmp_path / "x.png"),
                   match="16-bit depth PNG")
    (tmp_path / "bad.pcd").write_bytes(b"VERSION 0.7\nFIELDS x y\n")
    one_line_error(capsys, "forest", "label", out, str(tmp_path / "bad.pcd"), "-o",
                   str(tmp_path / "x.png"), match="bad.pcd: not a PCD file")
    wide = tmp_path / "wide.png"
    Image.fromarray(np.full((2, 40000), 1500, np.uint16)).save(wide)
    one_line_error(capsys, "forest", "label", out, str(wide), "-o", str(tmp_path / "x.png"),
                   match="wide.png: 40000x2 px")
    s31 = tmp_path / "s31.npz"
    f = Forest.load(out)
    f.meta.update({"label_scheme": "shotton31", "label_names": ["x"] * 31})
    f.save(s31)
    one_line_error(capsys, "forest", "export", str(s31), "-o", str(tmp_path / "p"),
                   match="label scheme mismatch")


@pytest.mark.parametrize("executor", ["local", pytest.param("ray", marks=pytest.mark.slow)])
def test_same_forest_whatever_workers(boxes_store, executor):
    """In this process, in worker processes or on Ray actors: the same forest."""
    from vhgen.forest.from_stores import train_forest
    from vhgen.forest.train import TrainParams

    p = TrainParams(trees=2, depth=6, pixels_per_image=200, features=40, thresholds=8,
                    seed=3, max_offset=40, min_samples=4)
    ref = train_forest([boxes_store], p)
    for w in (1, 2):
        f = train_forest([boxes_store], p, workers=w, executor=executor)
        for k in ("offsets", "thresh", "left", "depth", "counts", "roots"):
            np.testing.assert_array_equal(getattr(f, k), getattr(ref, k))
        assert f.meta["workers"] == w
