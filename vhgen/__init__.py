"""vhgen: labelled synthetic Kinect-style depth images of people.

The public API below is pure NumPy; GL (``vhgen.render``) and Ray (``vhgen.pipeline.driver``)
are imported only when used, so ``import vhgen`` imports neither moderngl nor ray.
"""

from vhgen.assets import fetch_assets, resolve_asset_dir
from vhgen.body import Body, LabelScheme, bone_matrices, build_body, skin_vertices
from vhgen.camera import Intrinsics, backproject, look_at, project
from vhgen.errors import (
    AssetError,
    BVHError,
    ConfigError,
    RenderError,
    RetargetError,
    StoreError,
    VhgenError,
)
from vhgen.job_config import JobConfig, SensorConfig
from vhgen.mocap import Motion, parse_bvh, read_bvh
from vhgen.mocap.retarget import RetargetMap, build_retargeter
from vhgen.version import __version__

__all__ = [
    "AssetError", "BVHError", "Body", "ConfigError", "Intrinsics", "JobConfig", "LabelScheme",
    "Motion", "RenderError", "RetargetError", "RetargetMap", "SensorConfig", "StoreError",
    "VhgenError", "__version__", "backproject", "bone_matrices", "build_body",
    "build_retargeter", "fetch_assets", "look_at", "parse_bvh", "project", "read_bvh",
    "resolve_asset_dir", "skin_vertices",
]
