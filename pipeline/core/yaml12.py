"""The one YAML reader and writer of the package (ruamel.yaml): safe, the YAML 1.2 core schema both
ways, duplicate keys refused, nesting depth and alias expansion bounded.

YAML 1.2.2, section 10.3.2 (the core schema) resolves a plain scalar to

* null: ``null``/``Null``/``NULL``, ``~`` or nothing;
* bool: ``true``/``false`` (any of three capitalisations); ``yes``/``no``/``on``/``off`` are strings;
* int: ``[-+]?[0-9]+`` (decimal, ``010`` is ten), ``0o[0-7]+``, ``0x[0-9a-fA-F]+``;
* float: ``[-+]?(\\.[0-9]+|[0-9]+(\\.[0-9]*)?)([eE][-+]?[0-9]+)?``, ``[-+]?.inf``, ``.nan``
  (``1e-3``, ``1.0e6``, ``.5``, ``-2E+3`` are floats; ``1_000`` and ``2024-01-01`` are strings);

plus the merge key ``<<``. The reader and the writer share that one resolver
(:class:`CoreSchemaResolver`): the writer quotes every string the reader would resolve to another
type (``"30425e4453996520"``, ``"1234"``, ``"true"``), so :func:`dump_yaml` then :func:`load_yaml`
gives back what was written.

Fields that are digests (:data:`TEXT_KEYS`: ``sha256``) are read as text whatever they look like:
earlier writers (YAML 1.1, where ``30425e4453996520`` is a string) left them unquoted.

Hostile input is refused as a ``YAMLError`` with a line: a mapping holding a key twice
(:class:`DuplicateKeyError`, naming the key and both lines), collections nested deeper than
:data:`MAX_DEPTH` (:class:`NestingTooDeepError`, before any recursion), aliases that refer to
their own node or whose expansion would exceed :data:`MAX_NODES` values (:class:`AliasExpansionError`;
an "alias bomb" of 2 kB otherwise expands to 10^9 values). Each check is linear in the text.

Parsing is pure-Python and a run reads the same files several times (config, robot.yaml for the
spec and for the model): :func:`load_yaml` keeps the last ``PARSED_TEXTS`` parsed texts and hands
out deep copies (the same data, no shared state).
"""

from __future__ import annotations

import copy
import functools
import io
import json
import re
from pathlib import Path
from typing import Any

from ruamel.yaml import YAML
from ruamel.yaml.composer import Composer
from ruamel.yaml.constructor import SafeConstructor
from ruamel.yaml.emitter import Emitter
from ruamel.yaml.error import MarkedYAMLError, YAMLError
from ruamel.yaml.events import AliasEvent
from ruamel.yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode
from ruamel.yaml.representer import SafeRepresenter
from ruamel.yaml.resolver import BaseResolver
from ruamel.yaml.scanner import Scanner

from pipeline.core.errors import ConfigError, PipelineError

__all__ = ["MAX_DEPTH", "MAX_NODES", "PARSED_TEXTS", "TEXT_KEYS", "AliasExpansionError", "DuplicateKeyError",
           "NestingTooDeepError", "YAMLError", "dump_yaml", "load_yaml", "read_yaml_file", "yaml_key",
           "yaml_problem"]

#: deepest nesting of collections a file may hold (a robot.yaml holds 4 levels)
MAX_DEPTH = 64
#: most values (scalars and collections, aliases expanded) a file may hold (a robot.yaml: ~600)
MAX_NODES = 200_000
#: keys whose plain scalar value is read as text whatever it looks like (digests)
TEXT_KEYS = frozenset({"sha256"})

_STR_TAG = "tag:yaml.org,2002:str"
_MERGE_TAG = "tag:yaml.org,2002:merge"


class CoreSchemaResolver(BaseResolver):
    """The YAML 1.2 core schema's implicit types (and the merge key), for reading and writing."""

    def __init__(self, version: Any = None, loader: Any = None, loadumper: Any = None) -> None:
        super().__init__(loadumper if loadumper is not None else loader)

    @property
    def processing_version(self) -> tuple[int, int]:
        return (1, 2)


for _tag, _pattern, _first in (
        ("bool", r"^(?:true|True|TRUE|false|False|FALSE)$", "tTfF"),
        ("int", r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$", "-+0123456789"),
        ("float", r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
                  r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$", "-+0123456789."),
        ("null", r"^(?:~|null|Null|NULL|)$", ["~", "n", "N", ""]),
        ("merge", r"^(?:<<)$", "<")):
    CoreSchemaResolver.add_implicit_resolver_base(f"tag:yaml.org,2002:{_tag}", re.compile(_pattern), list(_first))


class DuplicateKeyError(MarkedYAMLError):
    """A mapping holds ``key`` twice: on ``first_line`` and on ``second_line`` (1-based)."""

    def __init__(self, key: object, first_line: int, node: Node) -> None:
        self.key = key
        self.first_line = first_line
        self.second_line = node.start_mark.line + 1
        super().__init__(problem=f"duplicate key {key!r} (lines {first_line} and {self.second_line})",
                         problem_mark=node.start_mark)


class UnhashableKeyError(MarkedYAMLError):
    """A mapping key that is itself a mapping or holds one (``? {a: 1}``, ``? [- {a: 1}]``): no
    dictionary can hold it."""

    def __init__(self, node: Node) -> None:
        super().__init__(problem=f"a mapping key that is a collection (line {node.start_mark.line + 1}): "
                                 "keys must be plain values", problem_mark=node.start_mark)


class NestingTooDeepError(MarkedYAMLError):
    """Collections nested deeper than :data:`MAX_DEPTH`."""


class AliasExpansionError(MarkedYAMLError):
    """An alias that refers to its own node, or aliases expanding to more than :data:`MAX_NODES` values."""


class _BoundedScanner(Scanner):
    """ruamel's scanner refusing flow collections (``[``, ``{``) nested deeper than :data:`MAX_DEPTH`
    as it meets them: a scanner looks ahead through an unclosed flow collection for a possible
    key, quadratic in its depth (5 s for 20 000 ``[``)."""

    def fetch_flow_collection_start(self, TokenClass: Any, to_push: str) -> None:  # noqa: N803 - ruamel's name
        if len(self.flow_context) >= MAX_DEPTH:
            raise NestingTooDeepError(problem=f"nested deeper than {MAX_DEPTH} levels",
                                      problem_mark=self.reader.get_mark())
        super().fetch_flow_collection_start(TokenClass, to_push)


class _BoundedComposer(Composer):
    """ruamel's composer refusing nesting deeper than :data:`MAX_DEPTH` (before it recurses) and,
    once a document is composed, a node graph whose expansion exceeds :data:`MAX_NODES` values."""

    def __init__(self, loader: Any = None) -> None:
        super().__init__(loader)
        self.warn_double_anchors = False     # YAML 1.2 lets an anchor be defined again (the later one holds)

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.depth > MAX_DEPTH and not self.parser.check_event(AliasEvent):   # depth counts scalars too
            raise NestingTooDeepError(problem=f"nested deeper than {MAX_DEPTH} levels",
                                      problem_mark=self.parser.peek_event().start_mark)
        return super().compose_node(parent, index)

    def compose_document(self) -> Any:
        node = super().compose_document()
        _expanded_size(node, {})
        return node


def _expanded_size(node: Node, sizes: dict[int, int]) -> int:
    """How many values ``node`` stands for with every alias expanded (memoised per node, so linear
    in the composed nodes; recursion no deeper than the text's nesting: an alias refers to a node
    composed, and sized, before it)."""
    key = id(node)
    if key in sizes:
        if sizes[key] < 0:
            raise AliasExpansionError(problem="an alias refers to the node that holds it (a recursive structure)",
                                      problem_mark=node.start_mark)
        size = sizes[key]
    else:
        sizes[key] = -1
        if isinstance(node, SequenceNode):
            size = 1 + sum(_expanded_size(child, sizes) for child in node.value)
        elif isinstance(node, MappingNode):
            size = 1 + sum(_expanded_size(k, sizes) + _expanded_size(v, sizes) for k, v in node.value)
        else:
            size = 1
        sizes[key] = size
    if size > MAX_NODES:
        raise AliasExpansionError(problem=f"aliases expand to more than {MAX_NODES} values",
                                  problem_mark=node.start_mark)
    return size


class _Constructor(SafeConstructor):
    """ruamel's safe constructor with duplicate keys refused (a merge key may be overridden), the
    core schema's ints, and the values of :data:`TEXT_KEYS` read as text."""

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, MappingNode):
            lines: dict[Any, int] = {}
            for key_node, value_node in node.value:
                if key_node.tag == _MERGE_TAG:    # "<<: *base" may override keys on purpose
                    continue
                key = self.construct_object(key_node, deep=True)
                if (isinstance(key, str) and key in TEXT_KEYS and isinstance(value_node, ScalarNode)
                        and value_node.style is None and value_node.value != ""):
                    value_node.tag = _STR_TAG
                try:
                    first = lines.get(key)
                except TypeError:                 # a mapping, or a sequence holding one (made a tuple)
                    raise UnhashableKeyError(key_node) from None
                if first is not None:
                    raise DuplicateKeyError(key, first, key_node)
                lines[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: Any) -> int:
        text = str(self.construct_scalar(node))
        if text.startswith("0o"):
            return int(text[2:], 8)
        if text.startswith("0x"):
            return int(text[2:], 16)
        return int(text, 10)


_Constructor.add_constructor("tag:yaml.org,2002:int", _Constructor.construct_yaml_int)


#: characters a YAML 1.1 emitter takes for line breaks (NEL, LS, PS) but a reader keeps: such a
#: string is written double-quoted, where they are escaped (\N, \L, \P)
_ESCAPED_BREAKS = frozenset("\x85\u2028\u2029")


class _PlainRepresenter(SafeRepresenter):
    """Safe representer writing shared objects out in full (no anchors/aliases), tuples as lists,
    and double-quoted: strings holding NEL, LS or PS (in any other style they would be folded) and
    strings starting with ``?`` or ``:`` (written plain in a flow collection, ``[?0]`` or ``{:0: x}``,
    ruamel's parser reads a mapping key or fails)."""

    def ignore_aliases(self, data: Any) -> bool:
        return True

    def represent_str(self, data: str) -> ScalarNode:
        if _ESCAPED_BREAKS.intersection(data) or data.startswith(("?", ":")):
            return self.represent_scalar(_STR_TAG, data, style='"')
        return super().represent_str(data)


_PlainRepresenter.add_representer(tuple, SafeRepresenter.represent_list)
_PlainRepresenter.add_representer(str, _PlainRepresenter.represent_str)


class _Emitter(Emitter):
    """ruamel's emitter with every double-quoted scalar on one line. Folding a long double-quoted
    scalar, ruamel may break the line right after an escape (``\\x7F``, ``\\x1F``) where the text has no
    space, and a reader folds that break into a space: the text would not read back as written."""

    def write_double_quoted(self, text: str, split: bool = True) -> None:
        super().write_double_quoted(text, split=False)


def _yaml() -> YAML:
    """A fresh ruamel instance (an instance keeps parser state: one per call, thread-safe)."""
    yaml = YAML(typ="safe", pure=True)
    yaml.Resolver = CoreSchemaResolver
    yaml.Scanner = _BoundedScanner
    yaml.Composer = _BoundedComposer
    yaml.Constructor = _Constructor
    yaml.Representer = _PlainRepresenter
    yaml.Emitter = _Emitter
    yaml.allow_duplicate_keys = True      # refused by _Constructor, with both lines
    return yaml


#: how many parsed texts :func:`load_yaml` keeps (the files of a few runs)
PARSED_TEXTS = 32


@functools.lru_cache(maxsize=PARSED_TEXTS)
def _parsed(text: str) -> Any:   # Any: whatever the YAML holds
    return _yaml().load(text)


def load_yaml(text: str) -> Any:
    """Parse YAML text (raises ``YAMLError``); a text parsed before is answered with a deep copy of
    its earlier result (the reader is a pure function of the text)."""
    return copy.deepcopy(_parsed(text))


def dump_yaml(value: Any, *, flow: bool | None = False, width: int = 80, sort_keys: bool = False) -> str:
    """``value`` (dicts, lists, tuples, str, int, float, bool, None) as YAML text that
    :func:`load_yaml` reads back equal; ``flow``: False block style, True flow style, None flow
    for the innermost collections only. A bare scalar ends without the document-end marker."""
    yaml = _yaml()
    yaml.default_flow_style = flow
    yaml.width = width
    yaml.sort_base_mapping_type_on_output = sort_keys  # type: ignore[assignment]  # ruamel annotates it None
    stream = io.StringIO()
    yaml.dump(value, stream)
    text = stream.getvalue()
    return text[:-4] if text.endswith("\n...\n") else text


#: a plain key every YAML reader takes as this text: an identifier that is no YAML 1.1 or 1.2 literal
_PLAIN_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_YAML11_LITERALS = frozenset(("y", "n", "yes", "no", "on", "off", "true", "false", "null"))


def yaml_key(text: str) -> str:
    """``text`` as a mapping key for a file written line by line that every reader takes back as this
    string (ruamel and yaml-cpp at YAML 1.2, PyYAML at 1.1, where ``yes``/``on``/``1:30`` are no strings):
    plain when it is an identifier and no literal of either version, else JSON's double-quoted string
    (valid YAML 1.1 and 1.2)."""
    if _PLAIN_KEY.fullmatch(text) and text.lower() not in _YAML11_LITERALS:
        return text
    return json.dumps(text)


def yaml_problem(exc: YAMLError) -> tuple[str | None, str]:
    """(field, problem) of a YAML error for a one-line message: the key of a duplicate, else
    the line of the problem."""
    if isinstance(exc, DuplicateKeyError):
        return str(exc.key), f"duplicate key (lines {exc.first_line} and {exc.second_line}); keep one"
    mark = getattr(exc, "problem_mark", None)
    where = f"line {mark.line + 1}" if mark is not None else None
    problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
    if isinstance(exc, NestingTooDeepError | AliasExpansionError):
        return where, f"refused: {problem}"
    return where, f"invalid YAML: {problem}"


def read_yaml_file(path: str | Path, error: type[PipelineError] = ConfigError) -> Any:
    """Read and parse a UTF-8 YAML file; a YAML problem raises ``error(path, field, problem)``
    (:func:`yaml_problem`). OS and decoding errors propagate."""
    text = Path(path).read_text(encoding="utf-8")
    try:
        return load_yaml(text)
    except YAMLError as exc:
        field, problem = yaml_problem(exc)
        raise error(path, field, problem) from None
