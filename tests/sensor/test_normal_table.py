"""The N(0, 1) quantile table is computed once per machine and cached on disk: the cached
table must be the computed one bit for bit, and a damaged cache file is recomputed."""

from __future__ import annotations

import numpy as np

from vhgen.sensor.state import (
    NORMAL_TABLE,
    NORMAL_TABLE_FILE,
    compute_normal_table,
    load_normal_table,
)


def test_cache_round_trip_is_exact(tmp_path):
    fresh = compute_normal_table()
    first = load_normal_table(tmp_path)  # computes and writes
    assert (tmp_path / NORMAL_TABLE_FILE).is_file()
    second = load_normal_table(tmp_path)  # reads
    assert np.array_equal(first, fresh) and np.array_equal(second, fresh)
    assert np.array_equal(NORMAL_TABLE, fresh)  # what the sensor stages use
    assert abs(fresh.std() - 1.0) < 1e-12 and fresh[0] < -4.0 < 4.0 < fresh[-1]


def test_damaged_cache_is_recomputed(tmp_path):
    fresh = compute_normal_table()
    path = tmp_path / NORMAL_TABLE_FILE
    for damage in (b"not a numpy file", None):
        if damage is None:  # a readable array that is not the table
            np.save(path, np.zeros(65536))
        else:
            path.write_bytes(damage)
        assert np.array_equal(load_normal_table(tmp_path), fresh)
        assert np.array_equal(np.load(path), fresh)  # and rewritten


def test_unwritable_cache_still_gives_the_table(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")  # a file where the cache folder would be: cannot create it
    assert np.array_equal(load_normal_table(blocker / "cache"), compute_normal_table())
