"""Compiled kernels are cached on disk under $VHGEN_HOME (not beside the sources, which
may be read-only in an installed package): a second process loads instead of compiling."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

CODE = """
import numpy as np
import vhgen.sensor.sensor_kernels as k
d = np.full((4, 4), 2.0, np.float32)
k.sanitise(d)
s = k.sanitise.stats
print(sum(s.cache_hits.values()), sum(s.cache_misses.values()))
"""


def _run(home: Path) -> tuple[int, int]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["VHGEN_HOME"] = str(home)
    out = subprocess.run([sys.executable, "-c", CODE], env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    hits, misses = out.stdout.split()
    return int(hits), int(misses)


def test_kernels_cached_under_vhgen_home(tmp_path):
    assert _run(tmp_path) == (0, 1)  # compiled, and saved...
    assert list((tmp_path / "cache" / "numba").rglob("*.nbi"))  # ...under $VHGEN_HOME
    assert _run(tmp_path) == (1, 0)  # a new process loads it
