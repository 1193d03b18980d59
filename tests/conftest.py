"""Shared fixtures. Real data comes from ../shared/mocap (never copied into the repo) and
the MakeHuman assets fetched by ``vhgen assets fetch``; a missing one is an error, not a skip."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED_MOCAP = REPO.parent / "shared" / "mocap" / "cmu"


@pytest.fixture(scope="session")
def shared_mocap() -> Path:
    if not SHARED_MOCAP.is_dir():
        pytest.fail(f"{SHARED_MOCAP} not found: the tests read the shared BVH corpus from "
                    "../shared/mocap/cmu beside the repository")
    return SHARED_MOCAP


@pytest.fixture(scope="session")
def asset_dir() -> Path:
    from vhgen.assets import resolve_asset_dir

    return resolve_asset_dir()


@pytest.fixture(scope="session")
def shotton():
    from vhgen.body.labels import LabelScheme

    return LabelScheme.load("shotton31")


@pytest.fixture(scope="session")
def body(asset_dir, shotton):
    from vhgen.body.avatar import build_body

    return build_body(asset_dir, shotton)


@pytest.fixture(scope="session")
def cmu_map():
    from vhgen.mocap.retarget import RetargetMap

    return RetargetMap.load("cmu_mb")


@pytest.fixture(params=["egl", "osmesa"])
def gl_ctx(request):
    """A fresh context per test on each backend; GL must be error-free before and after."""
    from vhgen.render.context import create_context

    ctx = create_context(request.param)
    assert ctx.error == "GL_NO_ERROR"
    yield ctx
    assert ctx.error == "GL_NO_ERROR"
    ctx.release()


SMALL_STORE_CONFIG = """
name: small
seed: 5
motions: [{m}/01_01.bvh, {m}/02_01.bvh]
sensor: kinect_v1_full
poses: {{frame_step: 400, skip_first: 1, max_per_motion: 3}}
avatars: {{count: 2}}
output: {{frames_per_shard: 3}}
render: {{backend: osmesa}}
num_workers: 2
"""


@pytest.fixture(scope="session")
def small_store(tmp_path_factory, shared_mocap, asset_dir) -> Path:
    """A real store made by the Ray driver from two CMU clips: 8 frames in shards of 3
    (the last one short), arrays depth/labels/raw. Read-only: copy it before damaging it."""
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    tmp = tmp_path_factory.mktemp("small_store")
    (tmp / "small.yaml").write_text(SMALL_STORE_CONFIG.format(m=shared_mocap))
    run_job(JobConfig.load(tmp / "small.yaml"), tmp / "small.zarr")
    return tmp / "small.zarr"
