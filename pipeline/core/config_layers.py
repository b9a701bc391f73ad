"""Layers of a run configuration: reading a YAML file, parsing ``--set key=value``, merging the
layers (later wins) and finding which layer set a field (for error blame).

Used by :mod:`pipeline.core.config`, which validates the merged result against the stages' dataclasses.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pipeline.core.errors import ConfigError
from pipeline.core.typed_config import one_line
from pipeline.core.yaml12 import YAMLError, load_yaml, yaml_problem


def field_path(dotted: str) -> tuple[str, ...]:
    """``"control.iso.centre_m[1]"`` -> ``("control", "iso", "centre_m")``."""
    parts = []
    for part in str(dotted).split("."):
        part = part.split("[", 1)[0].strip()
        if part:
            parts.append(part)
    return tuple(parts)


def leaf_paths(value: Mapping[str, Any], prefix: tuple[str, ...]) -> list[tuple[str, ...]]:
    """Dotted paths of the values a layer sets (mappings are walked into; ``{}`` sets nothing)."""
    out: list[tuple[str, ...]] = []
    for key, item in value.items():
        path = (*prefix, str(key))
        if isinstance(item, Mapping) and item:
            out.extend(leaf_paths(item, path))
        else:
            out.append(path)
    return out


def related(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    """One path is the other or a part of it."""
    n = min(len(a), len(b))
    return n > 0 and a[:n] == b[:n]


def lookup_origin(origins: Mapping[str, str], dotted: str) -> str | None:
    """The latest layer in ``origins`` (ordered by when the field was last set) that set
    ``dotted``, a part of it, or a field inside it."""
    target = field_path(dotted)
    if len(target) < 2:          # a whole section or a top-level key: not a field
        return None
    found = None
    for key, src in origins.items():
        if related(field_path(key), target):
            found = src
    return found


def to_plain(value: object) -> Any:  # Any: plain dict/list/str/float/... of whatever shape came in
    """Dataclasses, tuples, Paths and numpy values -> plain Python (dict/list/str/float/...)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist"):      # numpy arrays and scalars
        return to_plain(value.tolist())
    return value


def parse_set(item: str) -> tuple[list[str], Any]:
    """``"a.b=3"`` -> (["a", "b"], 3); the value is parsed as a YAML scalar/flow value."""
    if "=" not in item:
        raise ConfigError("--set", item, "expected key=value")
    key, _, text = item.partition("=")
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise ConfigError("--set", item, "empty key")
    try:
        value = load_yaml(text) if text.strip() else ""
    except YAMLError as exc:
        raise ConfigError("--set", key, f"cannot parse value {text!r}: {one_line(exc)}") from None
    return key.split("."), value


def read_yaml(path: Path) -> dict[str, Any]:
    """Read a YAML config file whose top level must be a mapping.

    A file that is not UTF-8 text (binary, another encoding) and an empty file (or one holding
    only comments) are errors: an empty ``--config`` would otherwise silently start the full
    default profile; leave ``--config`` out to run the defaults.
    """
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(path, None, "config file not found") from None
    except IsADirectoryError:
        raise ConfigError(path, None, "is a directory, expected a YAML file") from None
    except OSError as exc:
        raise ConfigError(path, None, f"cannot read: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(path, None, f"not a UTF-8 text file (byte {exc.start}: {raw[exc.start]:#04x}); "
                          "expected a YAML run configuration") from None
    if "\0" in text:
        raise ConfigError(path, None, "contains NUL bytes (a binary file?); expected a YAML run configuration")
    try:
        data = load_yaml(text)
    except YAMLError as exc:
        raise ConfigError(path, *yaml_problem(exc)) from None
    if data is None:
        raise ConfigError(path, None, "the config file is empty; leave out --config to run the "
                          "built-in defaults (full profile), or write e.g. 'profile: full'")
    if not isinstance(data, dict):
        raise ConfigError(path, None, f"top level must be a mapping, got {type(data).__name__}")
    return data


def merge_layers(base: dict[str, Any], update: Mapping[str, Any]) -> dict[str, Any]:
    """Deep merge of plain dicts (update wins)."""
    out = dict(base)
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge_layers(dict(out[key]), value)
        else:
            out[key] = value
    return out
