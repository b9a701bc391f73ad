"""The one YAML loader of the package: safe, YAML 1.2 core-schema numbers and booleans, and
duplicate keys refused.

PyYAML implements YAML 1.1, where ``1e-3`` and ``1.0e6`` are strings (a 1.1 float needs a dot
and a signed exponent), ``.5`` needs the dot, ``yes``/``no``/``on``/``off`` are booleans and
``010`` is octal. The YAML 1.2 core schema (YAML 1.2.2, section 10.3.2) reads

* int: ``[-+]?[0-9]+`` (decimal, ``010`` is ten), ``0o[0-7]+``, ``0x[0-9a-fA-F]+``;
* float: ``[-+]?(\\.[0-9]+|[0-9]+(\\.[0-9]*)?)([eE][-+]?[0-9]+)?``, ``[-+]?.inf``, ``.nan``
  (``1e-3``, ``1.0e6``, ``.5``, ``-2E+3`` are floats);
* bool: ``true``/``false`` (any of three capitalisations); ``yes``/``no``/``on``/``off`` are strings.

A mapping that holds the same key twice is an error (:class:`DuplicateKeyError`, naming the key
and both lines) instead of PyYAML's silent "the last one wins".

Parsing is pure-Python PyYAML (tens of milliseconds for a robot.yaml) and a run reads the same
files several times (config, robot.yaml for the spec and for the model): :func:`load_yaml` keeps
the last ``PARSED_TEXTS`` parsed texts and hands out deep copies (the same data, no shared state).
"""

from __future__ import annotations

import copy
import functools
import re
from pathlib import Path
from typing import Any

import yaml

from pipeline.core.errors import ConfigError, PipelineError

_BOOL_TAG = "tag:yaml.org,2002:bool"
_INT_TAG = "tag:yaml.org,2002:int"
_FLOAT_TAG = "tag:yaml.org,2002:float"
_MERGE_TAG = "tag:yaml.org,2002:merge"

_BOOL_12 = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_INT_12 = re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$")
_FLOAT_12 = re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
                       r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$")


class DuplicateKeyError(yaml.MarkedYAMLError):
    """A mapping holds ``key`` twice: on ``first_line`` and on ``second_line`` (1-based)."""

    def __init__(self, key: object, first_line: int, node: yaml.Node) -> None:
        self.key = key
        self.first_line = first_line
        self.second_line = node.start_mark.line + 1
        super().__init__(problem=f"duplicate key {key!r} (lines {first_line} and {self.second_line})",
                         problem_mark=node.start_mark)


class Yaml12Loader(yaml.SafeLoader):
    """``yaml.SafeLoader`` with the YAML 1.2 core schema's ints, floats and booleans, refusing
    duplicate mapping keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        if isinstance(node, yaml.MappingNode):
            lines: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == _MERGE_TAG:    # "<<: *base" may override keys on purpose
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = lines.get(key)
                except TypeError:                 # an unhashable key: SafeConstructor names it
                    continue
                if first is not None:
                    raise DuplicateKeyError(key, first, key_node)
                lines[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        text = str(self.construct_scalar(node))
        if text.startswith("0o"):
            return int(text[2:], 8)
        if text.startswith("0x"):
            return int(text[2:], 16)
        return int(text, 10)


Yaml12Loader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag not in (_BOOL_TAG, _INT_TAG, _FLOAT_TAG)]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
Yaml12Loader.add_implicit_resolver(_BOOL_TAG, _BOOL_12, list("tTfF"))
Yaml12Loader.add_implicit_resolver(_INT_TAG, _INT_12, list("-+0123456789"))
Yaml12Loader.add_implicit_resolver(_FLOAT_TAG, _FLOAT_12, list("-+0123456789."))
Yaml12Loader.add_constructor(_INT_TAG, Yaml12Loader.construct_yaml_int)


#: how many parsed texts :func:`load_yaml` keeps (the files of a few runs)
PARSED_TEXTS = 32


@functools.lru_cache(maxsize=PARSED_TEXTS)
def _parsed(text: str) -> Any:   # Any: whatever the YAML holds
    return yaml.load(text, Loader=Yaml12Loader)  # noqa: S506 - a SafeLoader subclass


def load_yaml(text: str) -> Any:
    """Parse YAML text with :class:`Yaml12Loader` (raises ``yaml.YAMLError``); a text parsed before
    is answered with a deep copy of its earlier result (the loader is a pure function of the text)."""
    return copy.deepcopy(_parsed(text))


def yaml_problem(exc: yaml.YAMLError) -> tuple[str | None, str]:
    """(field, problem) of a YAML error for a one-line message: the key of a duplicate, else
    the line of the problem."""
    if isinstance(exc, DuplicateKeyError):
        return str(exc.key), f"duplicate key (lines {exc.first_line} and {exc.second_line}); keep one"
    mark = getattr(exc, "problem_mark", None)
    where = f"line {mark.line + 1}" if mark is not None else None
    problem = getattr(exc, "problem", None) or " ".join(str(exc).split())
    return where, f"invalid YAML: {problem}"


def read_yaml_file(path: str | Path, error: type[PipelineError] = ConfigError) -> Any:
    """Read and parse a UTF-8 YAML file; a YAML problem raises ``error(path, field, problem)``
    (:func:`yaml_problem`). OS and decoding errors propagate."""
    text = Path(path).read_text(encoding="utf-8")
    try:
        return load_yaml(text)
    except yaml.YAMLError as exc:
        field, problem = yaml_problem(exc)
        raise error(path, field, problem) from None
