"""Field checks of run-configuration sections: each raises :class:`ConfigError` naming the
source (file or ``--set``) and the dotted field, saying what was expected and what was given.
Used by the sections' ``validate(source)`` methods (``pipeline.core.config`` calls them at load time);
a choice is a ``Literal`` field instead (:func:`pipeline.core.typed_config.check_choices`).
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence

from pipeline.core.errors import ConfigError, Source


def _bounds(gt: float | None, ge: float | None, lt: float | None, le: float | None) -> str:
    lo = f"> {gt:g}" if gt is not None else f">= {ge:g}" if ge is not None else None
    hi = f"< {lt:g}" if lt is not None else f"<= {le:g}" if le is not None else None
    if lo and hi:
        left = "(" if gt is not None else "["
        right = ")" if lt is not None else "]"
        low, high = (gt if gt is not None else ge), (lt if lt is not None else le)
        return f"in {left}{low:g}, {high:g}{right}"
    return lo or hi or "finite"


def check_number(source: Source, name: str, value: object, *, gt: float | None = None, ge: float | None = None,
                 lt: float | None = None, le: float | None = None, unit: str = "", why: str = "") -> None:
    """ConfigError unless ``value`` is a finite number within the bounds (``gt`` > , ``ge`` >=, ...)."""
    number = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else math.nan
    ok = math.isfinite(number)
    if ok:
        ok = ((gt is None or number > gt) and (ge is None or number >= ge)
              and (lt is None or number < lt) and (le is None or number <= le))
    if not ok:
        what = "a finite number" if (gt, ge, lt, le) == (None, None, None, None) else _bounds(gt, ge, lt, le)
        unit_text = f" {unit}" if unit else ""
        raise ConfigError(source, name, f"expected {what}{unit_text}, got {value!r}{why}")


def check_count(source: Source, name: str, value: object, minimum: int, why: str = "") -> None:
    """ConfigError unless ``value`` is an int >= ``minimum``."""
    if not isinstance(value, int) or isinstance(value, bool) or value < minimum:
        raise ConfigError(source, name, f"expected an integer >= {minimum}, got {value!r}{why}")


def check_vector(source: Source, name: str, values: object, n: int | None = None, unit: str = "", *,
                 gt: float | None = None, nonempty: bool = False) -> None:
    """A list of finite numbers: ``n`` of them (if given), non-empty (if asked), each > ``gt`` (if given)."""
    unit_text = f" ({unit})" if unit else ""
    if not isinstance(values, (list, tuple)):
        raise ConfigError(source, name, f"expected a list of numbers{unit_text}, got {values!r}")
    if n is not None and len(values) != n:
        raise ConfigError(source, name, f"expected {n} numbers{unit_text}, got {len(values)}: {list(values)!r}")
    if nonempty and not values:
        raise ConfigError(source, name, f"expected at least one number{unit_text}, got an empty list")
    for i, v in enumerate(values):
        check_number(source, f"{name}[{i}]", v, gt=gt, unit=unit)


def check_unique(source: Source, name: str, values: Sequence[Hashable]) -> None:
    seen = set()
    for v in values:
        if v in seen:
            raise ConfigError(source, name, f"{v!r} is listed twice in {list(values)!r}")
        seen.add(v)
