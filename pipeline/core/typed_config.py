"""YAML values checked against the type annotations of configuration dataclasses.

``build_dataclass(cls, values, where, source)`` instantiates a (nested) dataclass from a
mapping; every value is checked and converted by :func:`coerce` (bool, int, float, str, Path,
optional and union types, Literal, list/tuple/dict of those, nested dataclasses, numpy arrays),
and a problem raises :class:`pipeline.core.errors.ConfigError` naming ``source`` (the file or
``--set``) and the dotted field ``where``.
"""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.core.errors import ConfigError, PipelineError


def one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def unknown_key(key: str, known: Sequence[str]) -> str:
    """The problem text of an unknown key: the closest known key (``difflib``, similarity >= 0.6),
    else every known key."""
    close = difflib.get_close_matches(str(key), [str(k) for k in known], n=1)
    if close:
        return f"unknown key; did you mean {close[0]!r}?"
    return f"unknown key (known keys: {', '.join(sorted(map(str, known))) or 'none'})"


def _type_name(tp: object) -> str:
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


def describe(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def coerce(value: Any, tp: Any, where: str, source: str) -> Any:  # Any: a YAML value checked against any annotation
    """Check ``value`` (from YAML) against type annotation ``tp`` and convert it.

    Supported: bool, int, float (ints accepted), str, Path, None, X | None, Union, Literal,
    list[X], tuple[X, ...], tuple[X, Y], dict[K, V], nested dataclasses, Any, and
    ``np.ndarray`` (accepts nested lists). Unknown annotations accept the value as is.
    """
    def fail(expected: str) -> ConfigError:
        return ConfigError(source, where, f"expected {expected}, got {describe(value)}")

    if tp is Any or tp is object:
        return value
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin is typing.Union or origin is types.UnionType:
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return coerce(value, arg, where, source)
            except ConfigError as exc:
                errors.append(exc)
        raise fail(_type_name(tp))
    if origin is typing.Literal:
        if value in args:
            return value
        raise fail("one of " + ", ".join(repr(a) for a in args))
    if tp is type(None) or tp is None:
        if value is None:
            return None
        raise fail("null")
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        if dataclasses.is_dataclass(value) and isinstance(value, tp):
            return value
        if not isinstance(value, Mapping):
            raise fail(f"a mapping ({tp.__name__})")
        return build_dataclass(tp, value, where, source)
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise fail("true/false")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise fail("int")
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise fail("number")
    if tp is str:
        if isinstance(value, str):
            return value
        raise fail("string")
    if tp is Path:
        if isinstance(value, (str, Path)):
            return Path(value)
        raise fail("path string")
    if origin in (list, Sequence, typing.Sequence) or tp is list:
        if not isinstance(value, (list, tuple)):
            raise fail("a list")
        item_tp = args[0] if args else Any
        return [coerce(v, item_tp, f"{where}[{i}]", source) for i, v in enumerate(value)]
    if origin is tuple or tp is tuple:
        if not isinstance(value, (list, tuple)):
            raise fail("a list")
        if not args or (len(args) == 2 and args[1] is Ellipsis):
            item_tp = args[0] if args else Any
            return tuple(coerce(v, item_tp, f"{where}[{i}]", source) for i, v in enumerate(value))
        if len(value) != len(args):
            raise fail(f"a list of {len(args)} items")
        pairs = enumerate(zip(value, args, strict=True))
        return tuple(coerce(v, a, f"{where}[{i}]", source) for i, (v, a) in pairs)
    if origin in (dict, Mapping, typing.Mapping) or tp is dict:
        if not isinstance(value, Mapping):
            raise fail("a mapping")
        k_tp, v_tp = args if args else (Any, Any)
        return {coerce(k, k_tp, where, source): coerce(v, v_tp, f"{where}.{k}", source)
                for k, v in value.items()}
    if getattr(tp, "__name__", "") == "ndarray":
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise fail("a numeric array") from None
        return arr
    return value


def _hints(cls: type) -> dict[str, Any]:
    try:
        return typing.get_type_hints(cls)
    except Exception:  # unresolved forward references: fall back to no checking
        return dict.fromkeys((f.name for f in dataclasses.fields(cls)), Any)


def build_dataclass(cls: type, values: Mapping[str, Any], where: str, source: str) -> Any:
    """Instantiate dataclass ``cls`` from defaults overridden by ``values`` (validated)."""
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = _hints(cls)
    kwargs: dict[str, Any] = {}
    for key, value in values.items():
        dotted = f"{where}.{key}" if where else str(key)
        if key not in fields:
            raise ConfigError(source, dotted, unknown_key(key, list(fields)))
        kwargs[key] = coerce(value, hints.get(key, Any), dotted, source)
    try:
        instance = cls(**kwargs)
    except ConfigError as exc:  # a dataclass's own __post_init__ check: name where the value came from
        raise with_source(exc, source) from None
    except PipelineError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(source, where, one_line(exc)) from None
    return instance


def with_source(exc: ConfigError, source: str) -> ConfigError:
    """``exc`` naming ``source`` (the file or ``--set``) when it names no file itself."""
    if exc.file is not None and exc.file not in ("None", "config"):
        return exc
    return ConfigError(source, exc.field, exc.problem)


def dotted_get(data: object, dotted: str, default: object = None) -> Any:  # Any: whatever the mapping holds
    """The value at ``a.b.c`` in nested mappings, or ``default`` where a key is missing."""
    value = data
    for key in dotted.split("."):
        if not isinstance(value, dict) or key not in value:
            return default
        value = value[key]
    return value
