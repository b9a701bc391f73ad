"""A measurement CSV's header as instruments and spreadsheets write it: column names with units, any order,
and the delimiter of the first line.

A header cell is a quantity's name with an optional unit, in any of the spellings exports use::

    x      x_m      x_mm      x [mm]      x (mm)      X[mm]      q1_deg      shoulder_pan_joint [deg]

The unit converts the column to SI (``mm`` to m, ``deg`` to rad); a cell without one is in the SI unit.
:func:`parse_header` maps the cells onto the reader's quantities: fixed names (``x, y, z, rx, ry, rz``)
and one column per model joint, named ``q1..qn`` or by the model's joint names (matched like a bag's,
:func:`~pipeline.exchange.joint_names.match_joint_names`). A column the reader does not know, a quantity
given twice, or a unit that is not one of the quantity's (``x [deg]``) is an error naming the cell.

The delimiter is the first of ``,``, ``;`` and tab that splits the first line (:func:`sniff_delimiter`).
With ``;``, a decimal comma is read as a decimal point (``0,125`` is 0.125), as European spreadsheets
write numbers under that delimiter.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from pipeline.core.errors import DataFileError
from pipeline.exchange.joint_names import match_joint_names

#: SI factor of each unit a header may state, by the kind of quantity
LENGTH_UNITS = {"m": 1.0, "mm": 1e-3}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
UNITS = {"length": LENGTH_UNITS, "angle": ANGLE_UNITS}
DELIMITERS = (",", ";", "\t")

_UNIT_RE = re.compile(r"^(?P<name>.*?)\s*(?:\[\s*(?P<bracket>[a-z]+)\s*\]|\(\s*(?P<paren>[a-z]+)\s*\)"
                      r"|_(?P<suffix>m|mm|rad|deg))$")


@dataclass(frozen=True)
class HeaderColumn:
    """One header cell: the quantity's name (lower case) and the unit it states (None: the SI unit)."""

    name: str
    unit: str | None


@dataclass(frozen=True)
class CsvLayout:
    """Where each quantity is (0-based column) and its SI factor; ``joints`` in the model's order."""

    joints: tuple[int, ...]
    joint_factors: tuple[float, ...]
    fields: dict[str, int]
    field_factors: dict[str, float]
    n_columns: int


def sniff_delimiter(first_line: str) -> str:
    """The delimiter of a CSV whose first line is ``first_line`` (module doc): the first of
    :data:`DELIMITERS` that splits it, else ``,``."""
    return next((d for d in DELIMITERS if d in first_line), ",")


def number(cell: str, delimiter: str) -> float:
    """A cell as a float; with the ``;`` delimiter a decimal comma counts as a point (module doc)."""
    text = cell.strip()
    if delimiter == ";" and "," in text and "." not in text:
        text = text.replace(",", ".")
    return float(text)


def is_number(cell: str, delimiter: str = ",") -> bool:
    """``cell`` reads as a number (:func:`number`)."""
    try:
        number(cell, delimiter)
    except ValueError:
        return False
    return True


def header_column(cell: str, known: Sequence[str] = ()) -> HeaderColumn:
    """``cell`` as a name and unit (module doc); a cell equal to one of the ``known`` names (joint names
    that end like a unit) is that name without a unit."""
    text = cell.strip().lower()
    if text in known:
        return HeaderColumn(text, None)
    match = _UNIT_RE.match(text)
    if match is None:
        return HeaderColumn(text, None)
    unit = match.group("bracket") or match.group("paren") or match.group("suffix")
    return HeaderColumn(match.group("name").strip(), unit)


def parse_header(path: str | Path, line: int, cells: Sequence[str], joint_names: Sequence[str],
                 fields: dict[str, str], optional: Sequence[tuple[str, ...]] = (),
                 aliases: dict[str, str] | None = None) -> CsvLayout:
    """The layout of a header row (module doc). ``joint_names``: the model's joints (angle columns, ``q1..qn``
    or these names); ``fields``: the other columns' names and kinds (``{"x": "length", ...}``); ``optional``:
    groups of fields that may be absent together (``("rx", "ry", "rz")``); ``aliases``: other names of fields
    (``{"x1": "x"}``). Errors name ``path`` and the header's file ``line``."""
    where = f"line {line}"
    model = [str(n).lower() for n in joint_names]
    columns = [header_column(c, model) for c in cells]
    columns = [HeaderColumn((aliases or {}).get(c.name, c.name), c.unit) for c in columns]
    numbered = [f"q{i}" for i in range(1, len(model) + 1)]
    expected = ",".join(numbered + list(fields))
    seen: dict[str, int] = {}
    for k, col in enumerate(columns):
        if col.name in seen:
            raise DataFileError(path, f"{where}, column {k + 1}", f"{cells[k].strip()!r} repeats column "
                                f"{seen[col.name] + 1} ({cells[seen[col.name]].strip()!r})")
        seen[col.name] = k
    hint = (f"expected columns {expected} (joints as q1..q{len(model)} or by the model's joint names "
            f"{list(joint_names)}), units as x_mm or q1 [deg]")
    absent = [f for f in fields if f not in seen and not any(f in group for group in optional)]
    for group in optional:
        there = [f for f in group if f in seen]
        if there and len(there) != len(group):
            absent += [f for f in group if f not in seen]
    if absent:
        raise DataFileError(path, where, f"missing column(s) {absent}: expected columns {expected}")
    joint_cells = [c.name for c in columns if c.name not in fields]
    if sorted(n for n in joint_cells if n in numbered) == sorted(numbered):
        by_model = dict(zip(model, numbered, strict=True))
    else:
        try:   # by name, as a bag's joints (a common prefix, e.g. robot_joint_1 for joint_1)
            by_model = match_joint_names([n for n in joint_cells if n not in numbered], model, source=str(path),
                                         field=f"{where} (joint columns)")
        except DataFileError:
            unknown = [cells[k].strip() for k, c in enumerate(columns)
                       if c.name not in fields and c.name not in numbered and c.name not in model]
            problem = (f"unknown column(s) {unknown}: {hint}" if unknown else
                       f"the joints are neither q1..q{len(model)} nor the model's joint names: {hint}")
            raise DataFileError(path, where, problem) from None
    extra = [cells[k].strip() for k, c in enumerate(columns)
             if c.name not in fields and c.name not in by_model.values()]
    if extra:
        raise DataFileError(path, where, f"unknown column(s) {extra} (the joints are given by "
                            f"{'q<i>' if by_model[model[0]] in numbered else 'name'}): {hint}")
    joints = tuple(seen[by_model[name]] for name in model)
    for k in (*joints, *(seen[f] for f in fields if f in seen)):
        col = columns[k]
        kind = "angle" if k in joints else fields[col.name]
        if col.unit is not None and col.unit not in UNITS[kind]:
            raise DataFileError(path, f"{where}, column {k + 1}", f"{cells[k].strip()!r}: unit {col.unit!r} is not "
                                f"one of {'an' if kind == 'angle' else 'a'} {kind}'s ({', '.join(UNITS[kind])})")

    def factor(k: int, kind: str) -> float:
        unit = columns[k].unit
        return 1.0 if unit is None else UNITS[kind][unit]

    present = {f: seen[f] for f in fields if f in seen}
    return CsvLayout(joints, tuple(factor(k, "angle") for k in joints), present,
                     {f: factor(k, fields[f]) for f, k in present.items()}, len(cells))
