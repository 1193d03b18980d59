"""The checks every config section shares (vhgen.yamlio): each value parsed or refused with
one message naming the file and the field, the same words wherever a section uses it."""

from __future__ import annotations

import pytest

from vhgen.errors import ConfigError
from vhgen.yamlio import int_range, number, number_range, probability, range_value

SRC = "job.yaml"


def _refused(call, *args, **kwargs) -> str:
    with pytest.raises(ConfigError) as e:
        call(*args, **kwargs)
    assert "\n" not in str(e.value) and SRC in str(e.value)
    return f"{e.value.field}: {e.value.message}"


def test_number():
    d = {"n": 3, "x": 2.5, "flag": True, "s": "4"}
    assert number(d, "n", SRC, "a.", lo=1, hi=5, integer=True) == 3
    assert isinstance(number(d, "n", SRC, "a."), float)
    assert number(d, "missing", SRC, "a.", default=7.0) == 7.0
    assert _refused(number, d, "missing", SRC, "a.") == "a.missing: required key is missing"
    assert _refused(number, d, "x", SRC, "a.", integer=True) == \
        "a.x: must be an integer, got 2.5"
    assert _refused(number, d, "flag", SRC, "a.") == "a.flag: must be a number, got True"
    assert _refused(number, d, "s", SRC, "a.") == "a.s: must be a number, got '4'"
    assert _refused(number, d, "n", SRC, "a.", lo=4, hi=9) == "a.n: 3 is outside [4, 9]"


def test_ranges():
    assert range_value(2, SRC, "r") == (2.0, 2.0)
    assert range_value([1, 2.5], SRC, "r", lo=0, hi=3) == (1.0, 2.5)
    assert _refused(range_value, [3, 1], SRC, "r") == "r: min 3.0 > max 1.0"
    assert _refused(range_value, [1, 2, 3], SRC, "r") == \
        "r: must be a number or [min, max], got [1, 2, 3]"
    assert _refused(range_value, [0.5, 1.5], SRC, "r", lo=0, hi=1) == \
        "r: [0.5, 1.5] is outside [0, 1]"
    d = {"w": [1, 4], "c": [2, 3.5]}
    assert number_range(d, "w", SRC, "room.", (0.0, 1.0)) == (1.0, 4.0)
    assert number_range(d, "absent", SRC, "room.", (0.0, 1.0)) == (0.0, 1.0)
    assert int_range(d, "w", SRC, "room.", (1, 1), 0, 10) == (1, 4)
    assert _refused(int_range, d, "c", SRC, "room.", (1, 1), 0, 10) == \
        "room.c: must be integers, got [2, 3.5]"


def test_probability():
    assert probability(0, SRC, "p") == 0.0 and probability(1, SRC, "p") == 1.0
    for bad in (1.5, -0.1, True, "0.5"):
        assert _refused(probability, bad, SRC, "p") == \
            f"p: must be a probability in [0, 1], got {bad!r}"
