"""On real generated frames (CMU mocap from ../shared, MakeHuman bodies, OSMesa): a forest
learns something on held-out motions, and its PCL export labels them exactly as it does."""

from __future__ import annotations

import numpy as np
import pytest

from tests.forest.test_predict_kernel import reference_predict
from vhgen.forest.data import read_frames, select_frames, store_info
from vhgen.forest.evaluate import evaluate
from vhgen.forest.from_stores import train_forest
from vhgen.forest.pcl import export_pcl, pcl_tree_labels, read_pcl_tree, to_pcl_label
from vhgen.forest.train import TrainParams
from vhgen.forest.trees import Predictor
from vhgen.job_config import JobConfig
from vhgen.pipeline.driver import run_job

pytestmark = pytest.mark.slow

CONFIG = """
name: {name}
seed: {seed}
motions: [{motions}]
labels: pcl25
sensor: kinect_v1_full
poses: {{frame_step: 40, skip_first: 1, max_per_motion: {per}}}
avatars: {{count: 2}}
output: {{frames_per_shard: 8}}
render: {{backend: osmesa}}
num_workers: 2
"""


@pytest.fixture(scope="module")
def stores(tmp_path_factory, shared_mocap, asset_dir):
    tmp = tmp_path_factory.mktemp("forest_real")
    out = {}
    for name, seed, files, per in (("train", 1, ["01_01", "05_06", "10_06"], 6),
                                   ("test", 2, ["16_27"], 3)):
        p = tmp / f"{name}.yaml"
        p.write_text(CONFIG.format(name=name, seed=seed, per=per, motions=", ".join(
            str(shared_mocap / f"{f}.bvh") for f in files)))
        run_job(JobConfig.load(p), tmp / f"{name}.zarr")
        out[name] = str(tmp / f"{name}.zarr")
    return out


def test_forest_on_real_frames(stores, tmp_path):
    p = TrainParams(trees=2, depth=12, pixels_per_image=400, features=80, thresholds=12,
                    seed=0, min_samples=8)
    forest = train_forest([stores["train"]], p)
    assert forest.meta["frames"] == 36 and forest.meta["fx"] == pytest.approx(571.26)
    res = evaluate(forest, [store_info(stores["test"])])
    # 25 parts: chance is 0.04; even this tiny forest must do several times better
    assert res["mean_per_class"] > 0.15 and res["pixel_accuracy"] > 0.15, res
    paths = export_pcl(forest, tmp_path / "pcl")
    depth, _ = read_frames(select_frames([store_info(stores["test"])], 2, 0))
    ours = Predictor(forest)
    for t, path in enumerate(paths):
        tree = read_pcl_tree(path)
        for d in depth:
            np.testing.assert_array_equal(
                pcl_tree_labels(d, tree),
                np.where(d > 0, to_pcl_label(ours.tree_labels(d, t)), 29))


def test_fast_kernel_equals_reference_on_real_frames(stores):
    """Predictor (the compiled kernel of eval/label) against the NumPy reference on held-out
    generated frames with a 3 x depth-20 forest trained on real frames; the bodies are also
    shifted across every image border and given extra no-measurement holes."""
    p = TrainParams(trees=3, depth=20, pixels_per_image=600, features=60, thresholds=10,
                    seed=3, min_samples=2)
    forest = train_forest([stores["train"]], p)
    assert forest.depth.max() >= 15  # a deep forest, paths of many lengths
    depth, _ = read_frames(select_frames([store_info(stores["test"])], 3, 0))
    rng = np.random.default_rng(0)
    frames = []
    for d in depth:
        ys, xs = np.nonzero(d)
        frames.append(d)
        for dy, dx in ((-ys.min() - 20, 0), (d.shape[0] - ys.max() + 20, 0),
                       (0, -xs.min() - 30), (0, d.shape[1] - xs.max() + 30)):
            s = np.roll(d, (dy, dx), axis=(0, 1))
            s[rng.random(s.shape) < 0.03] = 0
            frames.append(s)
    frames_arr = np.stack(frames)
    border = np.concatenate([frames_arr[:, 0], frames_arr[:, -1], frames_arr[:, :, 0],
                             frames_arr[:, :, -1]], axis=1)
    assert (border > 0).sum() > 100  # body pixels on the borders: probes leave the image
    assert (depth == 0).any()  # the sensor model's own holes as well
    pred = Predictor(forest)
    got = pred.predict(frames_arr)
    for d, g in zip(frames_arr, got, strict=True):
        ref = reference_predict(forest, d)
        np.testing.assert_array_equal(g, ref)
        np.testing.assert_array_equal(pred.predict(d), ref)
    assert len(np.unique(got[frames_arr > 0])) > 5
