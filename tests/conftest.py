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
output: {{frames_per_shard: 3, arrays: [depth, labels, instances, classes, raw]}}
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


def unmerge_manifest(store: Path, drop: tuple[int, ...] = ()) -> None:
    """Put a finished store back in the state of a run stopped before its merge: one
    manifest part per shard (but the ``drop`` shards', as if never finished) from its
    ``manifest.parquet``, which is removed."""
    import numpy as np
    import pyarrow.compute as pc

    from vhgen.store.manifest import read_manifest, write_parquet

    table = read_manifest(store)
    (store / "manifest").mkdir(exist_ok=True)
    for s in np.unique(table.column("shard").to_numpy()):
        if int(s) not in drop:
            write_parquet(table.filter(pc.equal(table.column("shard"), s)),
                          store / "manifest" / f"part-{int(s):06d}.parquet")
    (store / "manifest.parquet").unlink()


def write_synthetic_store(path: Path, *, frames: int = 40, frames_per_shard: int = 4,
                          height: int = 96, width: int = 128, seed: int = 0,
                          codec: str = "zstd", compression_level: int | None = 3) -> Path:
    """A store in vhgen's layout without rendering: depth, labels, instances, classes of
    seeded noise, and a manifest.parquet of a few columns of each kind (numbers, strings
    with nulls, fixed-size lists, list of structs; rows shuffled) with its parts. For
    reader tests that need many frames or a store to damage. ``compression_level`` 3 is
    the codec of every array of the stores vhgen wrote before the per-array levels (None:
    today's levels)."""
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    from vhgen.store.zarr_store import create_store, write_shard

    rng = np.random.default_rng(seed)
    create_store(path, num_frames=frames, height=height, width=width,
                 frames_per_shard=frames_per_shard, compression_level=compression_level,
                 attrs={"label_names": ["a", "b", "c"]}, codec=codec)
    for s in range(-(-frames // frames_per_shard)):
        n = min(frames_per_shard, frames - s * frames_per_shard)
        depth = (rng.integers(500, 4000, (n, 1, 1)) + rng.integers(0, 8, (n, height, width))
                 ).astype(np.uint16)
        labels = rng.integers(0, 4, (n, height, width), dtype=np.uint8)
        write_shard(path, s, frames_per_shard, depth, labels,
                    extra={"instances": (labels > 0).astype(np.uint8), "classes": labels // 2})
    f = np.arange(frames)
    people = [[{"instance": 1, "avatar_id": int(i % 3), "joints": [0.5, float(i)]}]
              * int(i % 3) for i in f]
    table = pa.table({
        "frame": pa.array(f, pa.int64()),
        "shard": pa.array(f // frames_per_shard, pa.int32()),
        "avatar_id": pa.array(f % 3, pa.int32()),
        "seed": pa.array(f * 2**40 + 7, pa.uint64()),
        "body_pixels": pa.array(f * 10, pa.int32()),
        "camera_pitch_deg": pa.array(f * 0.25, pa.float64()),
        "visible": pa.array(f % 2 == 0),
        "motion_file": pa.array([f"m{i % 5}.bvh" for i in f]),
        "scene": pa.array([None if i % 4 == 0 else f'{{"props": {i}}}' for i in f]),
        "world_to_camera": pa.array([list(np.arange(16.0) + i) for i in f],
                                    pa.list_(pa.float64(), 16)),
        "joints_cam": pa.array([list(np.arange(6, dtype=np.float32) / (i + 1)) for i in f],
                               pa.list_(pa.float32(), 6)),
        "people": pa.array(people),
    })
    for s in range(-(-frames // frames_per_shard)):
        part = table.slice(s * frames_per_shard, frames_per_shard)
        pq.write_table(part, path / "manifest" / f"part-{s:06d}.parquet")
    pq.write_table(table.take(rng.permutation(frames)), path / "manifest.parquet")
    return path
