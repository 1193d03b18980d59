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
    from vhgen.body.model import build_body

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
