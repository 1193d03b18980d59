"""Small synthetic depth/label scenes for the forest tests (inline, seeded)."""

from __future__ import annotations

import numpy as np
import pytest


def two_boxes(n: int, seed: int, h: int = 60, w: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """n frames with two adjacent boxes: part 1 at 2.0 m, part 2 at 2.4 m, random placement;
    background (no measurement) elsewhere."""
    rng = np.random.default_rng(seed)
    d = np.zeros((n, h, w), np.uint16)
    lab = np.zeros((n, h, w), np.uint8)
    for i in range(n):
        x0, y0 = rng.integers(2, w - 32), rng.integers(2, h - 22)
        d[i, y0:y0 + 20, x0:x0 + 15], lab[i, y0:y0 + 20, x0:x0 + 15] = 2000, 1
        d[i, y0:y0 + 20, x0 + 15:x0 + 30], lab[i, y0:y0 + 20, x0 + 15:x0 + 30] = 2400, 2
    return d, lab


def write_store(path, depth: np.ndarray, labels: np.ndarray | None, *, scheme: str = "pcl25",
                names: list[str] | None = None, fx: float = 525.0) -> str:
    """A minimal store following the dataset contract (labels omitted if None)."""
    import zarr

    g = zarr.open_group(str(path), mode="w", zarr_format=3)
    g.create_array("depth", data=depth, chunks=(1,) + depth.shape[1:])
    if labels is not None:
        g.create_array("labels", data=labels, chunks=(1,) + labels.shape[1:])
    if names is None:
        from vhgen.body.labels import LabelScheme

        names = [p.name for p in LabelScheme.load(scheme).parts]
    g.attrs.update({"label_scheme": scheme, "label_names": names,
                    "sensor": {"name": "test", "intrinsics": {
                        "width": depth.shape[2], "height": depth.shape[1], "fx": fx,
                        "fy": fx, "cx": depth.shape[2] / 2 - 0.5,
                        "cy": depth.shape[1] / 2 - 0.5}}})
    return str(path)


@pytest.fixture()
def boxes_store(tmp_path):
    d, lab = two_boxes(12, seed=3)
    return write_store(tmp_path / "boxes.zarr", d, lab)
