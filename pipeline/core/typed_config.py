"""YAML values checked against the type annotations of configuration dataclasses.

``build_dataclass(cls, values, where, source)`` instantiates a (nested) dataclass from a
mapping; every value is checked and converted by :func:`coerce` (bool, int, float, str, Path,
optional and union types, Literal, list/tuple/dict of those, nested dataclasses, numpy arrays),
and a problem raises :class:`pipeline.core.errors.ConfigError` naming ``source`` (the file or
``--set``) and the dotted field ``where``. A choice is a ``Literal`` (``engine: Literal["pipeline",
"mujoco"]``): a value outside it is refused with one line naming the field and the choices.

A field naming a file or folder whose content is an input of the stage is declared
``Annotated[str | None, FileInput]`` (:func:`file_input_fields`): the stage's inputs hash covers
that content, never the path.
"""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np

from pipeline.core.errors import ConfigError, PipelineError, Source


class DataclassInstance(Protocol):
    """Any dataclass instance (a validated section of a run configuration)."""

    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]


class FileInput:
    """Marker of a configuration field that names a file or folder read by the stage:
    ``measurements_csv: Annotated[str | None, FileInput] = None``. The inputs hash of the stage
    covers the file's content (:func:`file_input_fields`), so a renamed field stays covered."""


def file_input_fields(cls: type) -> tuple[str, ...]:
    """The fields of dataclass ``cls`` annotated with :class:`FileInput`, in declaration order."""
    hints = typing.get_type_hints(cls, include_extras=True)
    out = []
    for f in dataclasses.fields(cls):
        tp = hints.get(f.name)
        if typing.get_origin(tp) is typing.Annotated and any(
                m is FileInput or isinstance(m, FileInput) for m in getattr(tp, "__metadata__", ())):
            out.append(f.name)
    return tuple(out)


def choices(tp: object) -> tuple[object, ...]:
    """The values of a ``Literal`` annotation (``()`` for any other annotation)."""
    return typing.get_args(tp) if typing.get_origin(tp) is typing.Literal else ()


def _choice_text(values: Sequence[object]) -> str:
    return ", ".join(str(v) if isinstance(v, str) else repr(v) for v in values)


def _check_literal(value: object, tp: object, where: str, source: Source) -> None:
    """ConfigError unless ``value`` holds one of the choices wherever annotation ``tp`` has a Literal
    (``Literal[...]``, ``Literal[...] | None``, ``list[Literal[...]]``, ``tuple[Literal[...], ...]``)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is typing.Literal:
        if not any(value == a and type(value) is type(a) for a in args):
            raise ConfigError(source, where, f"expected one of {_choice_text(args)}, got {value!r}")
    elif origin is typing.Union or origin is types.UnionType:
        arms = [a for a in args if a is not type(None)]
        if value is not None and len(arms) == 1:
            _check_literal(value, arms[0], where, source)
    elif origin in (list, tuple, Sequence) and args and isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            _check_literal(item, args[0], f"{where}[{i}]", source)


def check_choices(instance: object, where: str, source: Source = None) -> None:
    """Every ``Literal`` field of dataclass ``instance`` holds one of its choices (a config built in
    Python, which :func:`build_dataclass` did not check): ConfigError naming ``<where>.<field>``."""
    hints = _hints(type(instance))
    for f in dataclasses.fields(instance):  # type: ignore[arg-type]  # a dataclass instance
        _check_literal(getattr(instance, f.name), hints.get(f.name, Any), f"{where}.{f.name}", source)


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
        arms = [a for a in args if a is not type(None)]
        if len(arms) == 1 and choices(arms[0]):       # Literal[...] | None: name the choices
            raise errors[0]
        raise fail(_type_name(tp))
    if origin is typing.Literal:
        if any(value == a and type(value) is type(a) for a in args):
            return value
        raise ConfigError(source, where, f"expected one of {_choice_text(args)}, got {value!r}")
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
