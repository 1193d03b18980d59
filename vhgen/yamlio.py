"""YAML at the edge: load a mapping from a file and check its keys, naming file and field."""

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


def configs_dir() -> Path:
    """The shipped configs: the package ``vhgen.configs``.

    The repository keeps them in ``configs/`` at its top; the build maps that folder into
    the package (setup.py), so an editable install and an installed wheel both find them
    here, wherever the user's working directory is.
    """
    return Path(str(resources.files("vhgen.configs")))


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
