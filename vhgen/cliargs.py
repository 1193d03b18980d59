"""Argument types of the ``vhgen`` command line: each checks one value when argparse reads
it, so bad input fails in one line naming the flag before any work starts.

Every type is an :class:`ArgType`: a callable for argparse's ``type=`` that raises
``argparse.ArgumentTypeError`` with the allowed range, plus ``example`` (a valid value)
and ``invalid`` (values it must reject), which the CLI fuzz test feeds to every flag.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

_GARBAGE = ("", "abc", "nan", "1e999", "-1e999")


class ArgType:
    """A named argparse type with examples of valid and invalid input (for the fuzz test)."""

    def __init__(self, name: str, convert: Callable[[str], Any], example: str,
                 invalid: Sequence[str]):
        self.__name__ = name  # argparse names the type in its fallback messages
        self._convert = convert
        self.example = example
        self.invalid = tuple(invalid)

    def __call__(self, text: str) -> Any:
        return self._convert(text)

    def __repr__(self) -> str:
        return f"ArgType({self.__name__})"


def _fail(text: str, expected: str) -> argparse.ArgumentTypeError:
    # the parser turns "argument --x: V: must be ..." into "--x V: must be ..."
    return argparse.ArgumentTypeError(f"{text if text.strip() else repr(text)}: must be "
                                      f"{expected}")


def int_range(lo: int, hi: int | None = None) -> ArgType:
    """An integer in [lo, hi] (hi None: no upper bound)."""
    expected = f"an integer >= {lo}" if hi is None else f"an integer in [{lo}, {hi}]"

    def convert(text: str) -> int:
        try:
            v = int(text.strip())
        except ValueError:
            raise _fail(text, expected) from None
        if v < lo or (hi is not None and v > hi):
            raise _fail(text, expected)
        return v

    bad = [*_GARBAGE, "1.5", str(lo - 1), "1,2"]
    if hi is not None:
        bad.append(str(hi + 1))
    return ArgType(f"int[{lo},{hi}]", convert, str(lo), bad)


def float_range(lo: float, hi: float | None = None, *, lo_open: bool = False,
                hi_open: bool = False) -> ArgType:
    """A finite number in the interval lo..hi (open or closed ends)."""
    left, right = "(" if lo_open else "[", ")" if hi_open else "]"
    expected = f"a number in {left}{lo:g}, {'inf' if hi is None else f'{hi:g}'}{right}"

    def convert(text: str) -> float:
        try:
            v = float(text.strip())
        except ValueError:
            raise _fail(text, expected) from None
        if not math.isfinite(v) or v < lo or (lo_open and v == lo):
            raise _fail(text, expected)
        if hi is not None and (v > hi or (hi_open and v == hi)):
            raise _fail(text, expected)
        return v

    bad = [*_GARBAGE, str(lo - 1)]
    if lo_open:
        bad.append(f"{lo:g}")
    if hi is not None:
        bad.append(str(hi + 1))
    example = f"{lo + 1:g}" if hi is None else f"{(lo + hi) / 2:g}"
    return ArgType(f"float[{lo},{hi}]", convert, example, bad)


def _nonempty(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("must not be empty")
    return text


def _existing(kind: str, suffixes: tuple[str, ...] = ()) -> Callable[[str], str]:
    def convert(text: str) -> str:
        _nonempty(text)
        p = Path(text).expanduser()
        if not p.exists():
            raise argparse.ArgumentTypeError(f"{text}: no such {kind}")
        if kind == "file" and not p.is_file():
            raise argparse.ArgumentTypeError(f"{text}: not a file")
        if kind == "folder" and not p.is_dir():
            raise argparse.ArgumentTypeError(f"{text}: not a folder")
        if suffixes and p.is_file() and p.suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(f"{text}: expected a {' or '.join(suffixes)} file")
        return str(p)

    return convert


def _output(suffixes: tuple[str, ...]) -> Callable[[str], str]:
    def convert(text: str) -> str:
        _nonempty(text)
        p = Path(text).expanduser()
        if suffixes and p.suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(f"{text}: the name must end in "
                                             f"{' or '.join(suffixes)}")
        if p.is_dir() and suffixes:
            raise argparse.ArgumentTypeError(f"{text}: is a folder, expected a file name")
        parent = p.parent if str(p.parent) else Path(".")
        # the nearest existing ancestor must be a writable folder (we create the rest)
        anc = parent
        while not anc.exists() and anc != anc.parent:
            anc = anc.parent
        if not anc.is_dir():
            raise argparse.ArgumentTypeError(f"{text}: {anc} is not a folder")
        if not os.access(anc, os.W_OK | os.X_OK):
            ro = bool(os.statvfs(anc).f_flag & os.ST_RDONLY)
            raise argparse.ArgumentTypeError(f"{text}: folder {anc} is not writable"
                                             f"{' (read-only file system)' if ro else ''}")
        return str(p)

    return convert


def text(name: str = "text") -> ArgType:
    """Any non-empty string (a name or address checked later, cheaply)."""
    return ArgType(name, _nonempty, "x", [""])


def existing_path() -> ArgType:
    """A file or folder that exists."""
    return ArgType("path", _existing("file or folder"), ".", ["", "/nonexistent/vhgen/x"])


def existing_file(*suffixes: str) -> ArgType:
    """A file that exists (with one of ``suffixes``, if given)."""
    bad = ["", "/nonexistent/vhgen/x.bvh", "/"]
    return ArgType("file", _existing("file", suffixes),
                   "example" + (suffixes[0] if suffixes else ".txt"), bad)


def output_path(*suffixes: str) -> ArgType:
    """A path to write: a name ending in ``suffixes`` (if given) in a writable folder."""
    bad = ["", "/etc/hostname/x" + (suffixes[0] if suffixes else "")]
    if suffixes:
        bad.append("out.unknownsuffix")
    return ArgType("output", _output(suffixes), "out" + (suffixes[0] if suffixes else ""), bad)


def _frame_list(text: str) -> list[int]:
    parts = text.split(",")
    try:
        frames = [int(p) for p in parts]
    except ValueError:
        raise _fail(text, "comma-separated frame numbers >= 0, e.g. 0,5,9") from None
    if not frames or min(frames) < 0:
        raise _fail(text, "comma-separated frame numbers >= 0, e.g. 0,5,9")
    return frames


def frame_list() -> ArgType:
    """Comma-separated frame numbers >= 0."""
    return ArgType("frames", _frame_list, "0,1", ["", "1,x", "-1", "1,,2", "abc", "1.5"])


def _pose_spec(text: str) -> tuple[str, int]:
    path, sep, frame = text.rpartition(":")
    if not sep or not path:
        raise _fail(text, "BVH_FILE:FRAME, e.g. clip.bvh:120")
    try:
        index = int(frame)
    except ValueError:
        raise _fail(text, "BVH_FILE:FRAME with FRAME an integer >= 0") from None
    if index < 0:
        raise _fail(text, "BVH_FILE:FRAME with FRAME an integer >= 0")
    return _existing("file", (".bvh",))(path), index


def pose_spec() -> ArgType:
    """``BVH_FILE:FRAME`` with an existing file and a frame >= 0 (range checked on read)."""
    return ArgType("pose", _pose_spec, "clip.bvh:0",
                   ["", "x.bvh:abc", "x.bvh", "/nonexistent/vhgen/x.bvh:3", ":3", "x.bvh:-1"])


def key_value(ranges: dict[str, tuple[float, float]]) -> ArgType:
    """``KEY=VALUE`` with KEY a key of ``ranges`` and VALUE a number in its [lo, hi]."""
    allowed = ", ".join(ranges)

    def convert(text: str) -> tuple[str, float]:
        key, sep, val = text.partition("=")
        if not sep or key not in ranges:
            raise _fail(text, f"KEY=VALUE with KEY one of {allowed}")
        lo, hi = ranges[key]
        try:
            v = float(val)
        except ValueError:
            v = float("nan")
        if not (math.isfinite(v) and lo <= v <= hi):
            raise _fail(text, f"{key}=VALUE with VALUE a number in [{lo:g}, {hi:g}]")
        return key, v

    k0, (lo0, hi0) = next(iter(ranges.items()))
    return ArgType("key=value", convert, f"{k0}={lo0:g}",
                   ["", "abc", f"{k0}=x", f"{k0}=nan", f"nokey={lo0:g}", f"{k0}={hi0 + 1:g}"])


def _units(text: str) -> float | None:
    from vhgen.mocap.units import UNITS_M

    if text == "auto":
        return None
    if text in UNITS_M:
        return UNITS_M[text]
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not (math.isfinite(v) and v > 0):
        raise _fail(text, f"a unit ({', '.join(UNITS_M)}, auto) or a positive number "
                          "of metres per unit")
    return v


def units() -> ArgType:
    """A unit name, ``auto`` or a positive number of metres per unit (returns metres)."""
    return ArgType("units", _units, "cm", ["", "furlong", "0", "-1", "nan"])


def config_name(kind: str) -> ArgType:
    """A shipped config name (``configs/<kind>/``) or a path to a YAML file."""
    def convert(text: str) -> str:
        from vhgen.errors import ConfigError
        from vhgen.yamlio import find_config

        _nonempty(text)
        try:
            find_config(kind, text)
        except ConfigError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        return text

    return ArgType(f"{kind} config", convert, {"scenes": "default", "sensors": "ideal",
                                               "labels": "shotton31"}.get(kind, "x"),
                   ["", "no_such_config", "/nonexistent/vhgen/x.yaml"])


def _wear(text: str) -> tuple[str, str]:
    from vhgen.body.wardrobe import KINDS

    item, sep, kind = text.partition("=")
    if not sep or item not in KINDS or kind not in KINDS[item]:
        choices = "; ".join(f"{i}: {' '.join(k)}" for i, k in KINDS.items())
        raise _fail(text, f"ITEM=KIND ({choices})")
    return item, kind


def wear() -> ArgType:
    """``ITEM=KIND``: an item of the wardrobe and one of its kinds (``top=coat`` is not:
    ``outer=coat`` is; see :mod:`vhgen.body.wardrobe`)."""
    return ArgType("item=kind", _wear, "top=shirt", ["", "abc", "top=", "top=coat", "hat=crown"])


def _json_object(text: str) -> dict:
    import json

    src = text
    if text.endswith(".json"):
        try:
            src = Path(text).read_text()
        except OSError as e:
            raise _fail(text, f"a readable JSON file ({e.strerror})") from None
    try:
        value = json.loads(src)
    except ValueError:
        value = None
    if not isinstance(value, dict):
        raise _fail(text, "a JSON object, or a .json file holding one")
    return value


def json_object() -> ArgType:
    """A JSON object given inline or as a path to a ``.json`` file."""
    return ArgType("JSON object", _json_object, '{"scale": 1.0}',
                   ["", "abc", "[1, 2]", "/nonexistent/vhgen/x.json"])
