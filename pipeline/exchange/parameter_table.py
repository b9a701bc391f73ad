"""A table of identified parameters for a controller or a spreadsheet: ``parameter,value,std,unit``.

One row per parameter, one header line; ``value`` and ``std`` (its standard deviation) with 17
significant digits, so a float64 reads back bit for bit; ``unit`` as text (``m``, ``rad``,
``rad/(N m)``). Written atomically.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.core.artefacts import write_text
from pipeline.core.errors import DataFileError

PARAMETER_COLUMNS = ("parameter", "value", "std", "unit")


@dataclass(frozen=True)
class ParameterTable:
    """Named parameters with their standard deviations and units, in the order of the fit."""

    names: tuple[str, ...]
    values: np.ndarray
    stds: np.ndarray
    units: tuple[str, ...]

    def __post_init__(self) -> None:
        n = len(self.names)
        if not (np.shape(self.values) == np.shape(self.stds) == (n,) and len(self.units) == n):
            raise ValueError(f"{n} names, {np.shape(self.values)} values, {np.shape(self.stds)} stds, "
                             f"{len(self.units)} units")


def write_parameter_table_csv(path: str | Path, table: ParameterTable) -> Path:
    """``table`` as CSV (module docstring)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(PARAMETER_COLUMNS)
    for name, value, std, unit in zip(table.names, table.values, table.stds, table.units, strict=True):
        writer.writerow([name, f"{float(value):.17g}", f"{float(std):.17g}", unit])
    return write_text(path, buffer.getvalue())


def read_parameter_table_csv(path: str | Path) -> ParameterTable:
    """A parameter table written by :func:`write_parameter_table_csv` (or by hand in its layout)."""
    source = Path(path)
    try:
        with source.open(newline="", encoding="utf-8-sig") as handle:
            rows = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataFileError(source, None, f"cannot read: {exc}") from exc
    if not rows or tuple(c.strip() for c in rows[0]) != PARAMETER_COLUMNS:
        raise DataFileError(source, "header", f"expected {','.join(PARAMETER_COLUMNS)}, got "
                            f"{','.join(rows[0]) if rows else 'an empty file'}")
    names, values, stds, units = [], [], [], []
    for line, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(PARAMETER_COLUMNS):
            raise DataFileError(source, f"line {line}", f"{len(row)} values, expected {len(PARAMETER_COLUMNS)}")
        try:
            value, std = float(row[1]), float(row[2])
        except ValueError:
            raise DataFileError(source, f"line {line}", f"value {row[1]!r} or std {row[2]!r} is not a number") from None
        names.append(row[0].strip())
        values.append(value)
        stds.append(std)
        units.append(row[3].strip())
    return ParameterTable(tuple(names), np.array(values, float), np.array(stds, float), tuple(units))
