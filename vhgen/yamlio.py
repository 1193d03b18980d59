"""YAML at the edge: load a mapping from a file, check its keys, and the checks every config
section shares (a number, a number or [min, max] range, a probability), each naming file
and field."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from vhgen.errors import ConfigError


def load_yaml(path: str | Path) -> dict[str, Any]:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(path, "<file>", f"cannot read: {e.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "<file>"
        raise ConfigError(path, where, f"invalid YAML: {getattr(e, 'problem', e)}") from None
    if not isinstance(data, dict):
        raise ConfigError(path, "<file>", "expected a mapping at the top level")
    return data


def check_keys(data: dict, allowed: set[str], required: set[str], source, prefix: str) -> None:
    """Raise ConfigError on unknown or missing keys (typos must not pass silently)."""
    if not isinstance(data, dict):
        raise ConfigError(source, prefix or "<top>",
                          f"expected a mapping, got {type(data).__name__}")
    for k in data:
        if k not in allowed:
            raise ConfigError(source, f"{prefix}{k}",
                              f"unknown key (allowed: {', '.join(sorted(allowed))})")
    for k in required:
        if k not in data:
            raise ConfigError(source, f"{prefix}{k}", "required key is missing")


def number(d: dict, key: str, src, prefix: str, *, lo: float | None = None,
           hi: float | None = None, integer: bool = False, default: Any = None) -> Any:
    """``d[key]`` as a float (an int when ``integer``) within [lo, hi]; ``default`` when the
    key is absent (None: the key is required). ConfigError naming ``prefix + key``."""
    if key not in d:
        if default is None:
            raise ConfigError(src, prefix + key, "required key is missing")
        return default
    v = d[key]
    ok = isinstance(v, int) if integer else isinstance(v, (int, float))
    if isinstance(v, bool) or not ok:
        kind = "an integer" if integer else "a number"
        raise ConfigError(src, prefix + key, f"must be {kind}, got {v!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ConfigError(src, prefix + key, f"{v!r} is outside [{lo}, {hi}]")
    return int(v) if integer else float(v)


def range_value(v: Any, src, where: str, *, lo: float | None = None,
                hi: float | None = None) -> tuple[float, float]:
    """A number (min = max) or [min, max] within [lo, hi], as (min, max) floats;
    ConfigError naming ``where``."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v, v]
    if (not isinstance(v, list) or len(v) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise ConfigError(src, where, f"must be a number or [min, max], got {v!r}")
    a, b = float(v[0]), float(v[1])
    if a > b:
        raise ConfigError(src, where, f"min {a} > max {b}")
    if (lo is not None and a < lo) or (hi is not None and b > hi):
        raise ConfigError(src, where, f"[{a}, {b}] is outside [{lo}, {hi}]")
    return (a, b)


def number_range(d: dict, key: str, src, prefix: str, default: tuple[float, float], *,
                 lo: float | None = None, hi: float | None = None) -> tuple[float, float]:
    """``d[key]`` by :func:`range_value`, ``default`` when the key is absent."""
    if key not in d:
        return default
    return range_value(d[key], src, prefix + key, lo=lo, hi=hi)


def int_range(d: dict, key: str, src, prefix: str, default: tuple[int, int], lo: int,
              hi: int) -> tuple[int, int]:
    """``d[key]`` as an integer (min, max) within [lo, hi] (see :func:`number_range`)."""
    a, b = number_range(d, key, src, prefix, (float(default[0]), float(default[1])), lo=lo,
                        hi=hi)
    if a != int(a) or b != int(b):
        raise ConfigError(src, prefix + key, f"must be integers, got {d[key]!r}")
    return int(a), int(b)


def probability(v: Any, src, where: str) -> float:
    """A number in [0, 1]; ConfigError naming ``where``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
        raise ConfigError(src, where, f"must be a probability in [0, 1], got {v!r}")
    return float(v)


def configs_dir() -> Path:
    """The shipped configs: the package ``vhgen.configs``.

    The repository keeps them in ``configs/`` at its top; the build maps that folder into
    the package (setup.py), so an editable install and an installed wheel both find them
    here, wherever the user's working directory is. A source tree on ``sys.path`` without
    a build (``PYTHONPATH=.``; pytest puts the repository first when vhgen is installed
    elsewhere, as on a GPU node with the bundle) has no ``vhgen.configs``: then the
    ``configs/`` beside the package.
    """
    try:
        return Path(str(resources.files("vhgen.configs")))
    except ModuleNotFoundError:
        beside = Path(__file__).resolve().parent.parent / "configs"
        if beside.is_dir():
            return beside
        raise


def find_config(kind: str, name_or_path: str | Path) -> Path:
    """A config by path (relative to the working directory), or by bare name from the
    shipped ``configs/<kind>/<name>.yaml``."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.exists():
        if not p.is_file():
            raise ConfigError(p, "<file>", "no such file" if not p.exists() else "not a file")
        return p
    cand = configs_dir() / kind / f"{name_or_path}.yaml"
    if not cand.is_file():
        avail = sorted(q.stem for q in (configs_dir() / kind).glob("*.yaml"))
        raise ConfigError(None, kind, f"no config named {name_or_path!r} "
                                      f"(available: {', '.join(avail) or 'none'})")
    return cand
