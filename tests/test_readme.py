"""The README's Python examples run as written, on a store made as the README's first
command makes it (``out/cluttered_room.zarr``, here limited to 8 frames): the ```python
blocks in the environment the README's first command creates (vhgen and its dependencies,
no extras), the ```py blocks with the readers the dev extra adds (pandas, DuckDB)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow


def python_blocks(text: str) -> list[str]:
    """The fenced ```python (and ```py) blocks of a Markdown text, in order."""
    return re.findall(r"^```py(?:thon)?\n(.*?)^```", text, flags=re.S | re.M)


def test_blocks_found():
    blocks = python_blocks("x\n```python\na = 1\n```\n```bash\nls\n```\n```py\nb\n```\n")
    assert blocks == ["a = 1\n", "b\n"]


def test_readme_python_examples_run(tmp_path, asset_dir):
    from vhgen.job_config import JobConfig
    from vhgen.pipeline.driver import run_job

    blocks = python_blocks((REPO / "README.md").read_text())
    assert blocks, "the README has no Python example"
    cfg = JobConfig.load("cluttered_room", backend="osmesa", num_workers=1)
    run_job(cfg, tmp_path / "out" / "cluttered_room.zarr", max_frames=8)
    for i, code in enumerate(blocks):
        r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 0, f"README Python example {i + 1} fails:\n{code}\n{r.stderr}"
