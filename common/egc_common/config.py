"""Configuration: a TOML file per role plus ``--set key=value`` overrides (DESIGN 3).

Every parameter has a default in the dataclass that consumes it; this module only merges the
layers. Keys are dotted (``pipeline.horizon_s``); values given on the command line are parsed as
TOML values when they parse (``0.5``, ``true``, ``"text"``) and kept as strings otherwise.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any


class ConfigError(ValueError):
    pass


def load_toml(path: str | Path) -> dict[str, Any]:
    p = Path(path)
    try:
        with p.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {p}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file {p} is not valid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"cannot read config file {p}: {exc.strerror}") from None


def parse_override(text: str) -> tuple[list[str], Any]:
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"override {text!r} must look like key=value")
    try:
        value = tomllib.loads(f"x = {raw}")["x"]
    except tomllib.TOMLDecodeError:
        value = raw
    return [k.strip() for k in key.split(".")], value


def merge(base: Mapping[str, Any], overrides: Iterable[str]) -> dict[str, Any]:
    """A deep copy of ``base`` with each ``key.sub=value`` override applied in order."""
    out: dict[str, Any] = _deep_copy(base)
    for text in overrides:
        path, value = parse_override(text)
        node = out
        for key in path[:-1]:
            child = node.setdefault(key, {})
            if not isinstance(child, dict):
                raise ConfigError(f"override {text!r}: {key!r} is not a table")
            node = child
        node[path[-1]] = value
    return out


def load(
    path: str | Path | None, overrides: Iterable[str] = (), tables: Iterable[str] | None = None
) -> dict[str, Any]:
    """The file merged with the overrides; with ``tables``, any other top-level name (a
    misspelled ``[saftey]``, a key given without its table) is an error, not a silent no-op."""
    config = merge(load_toml(path) if path else {}, overrides)
    if tables is not None:
        known = set(tables)
        unknown = sorted(set(config) - known)
        if unknown:
            raise ConfigError(
                f"unknown config table(s): {', '.join(unknown)} (known: "
                f"{', '.join(sorted(known))}; a key is given as table.key, e.g. "
                f"{sorted(known)[0]}.<key>)"
            )
    return config


def section(config: Mapping[str, Any], name: str, allowed: Iterable[str]) -> dict[str, Any]:
    """One table of the config, checked for unknown keys (typos fail loudly)."""
    table = config.get(name, {})
    if not isinstance(table, dict):
        raise ConfigError(f"[{name}] must be a table")
    known = set(allowed)
    unknown = sorted(set(table) - known)
    if unknown:
        raise ConfigError(
            f"[{name}] has unknown keys: {', '.join(unknown)} (known: {', '.join(sorted(known))})"
        )
    return dict(table)


def _deep_copy(m: Mapping[str, Any]) -> dict[str, Any]:
    return {k: _deep_copy(v) if isinstance(v, Mapping) else v for k, v in m.items()}
