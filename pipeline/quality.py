"""Quality gates: a stage vouches for its result or stops.

A stage checks the figures that say whether its result can be trusted (solver status,
condition numbers, validation residual against the noise, chi²/dof, limit violations) against
thresholds stated in its ``Config``. A failed gate ends the stage with
:class:`~pipeline.core.errors.QualityGateError` naming the figure and the threshold, unless the run
was started with ``--accept-poor`` (``RunConfig.accept_poor``); then the result is handed on and
its ``summary["quality_gates"]`` and ``summary["accepted_poor"]`` say so (the report shows it).

Usage inside a stage's ``run``::

    gates = QualityGates("identification", accept_poor=ctx.run.accept_poor)
    gates.check("validation_rms_over_sigma", ratio, "<=", cfg.max_validation_rms_over_sigma)
    gates.require("excitation_status", status == "Solve_Succeeded", f"IPOPT returned {status}")
    return gates.finish(result)      # raises QualityGateError unless every gate passed or accept_poor
"""

from __future__ import annotations

import math
import operator
from dataclasses import asdict, dataclass
from typing import Protocol

from pipeline.core.errors import QualityGateError

_COMPARE = {"<=": operator.le, "<": operator.lt, ">=": operator.ge, ">": operator.gt}


class _HasSummary(Protocol):
    summary: dict


@dataclass(frozen=True)
class GateCheck:
    """One gate: ``value <op> threshold`` (or a plain pass/fail with a message)."""

    name: str
    passed: bool
    value: float | str | None
    op: str
    threshold: float | None
    message: str


class QualityGates:
    """Collects a stage's gate checks and decides at :meth:`finish`."""

    def __init__(self, stage: str, accept_poor: bool = False) -> None:
        self.stage = stage
        self.accept_poor = bool(accept_poor)
        self.checks: list[GateCheck] = []

    def check(self, name: str, value: float, op: str, threshold: float, what: str = "") -> bool:
        """Gate ``value op threshold`` (a NaN value fails). Returns whether it passed."""
        if op not in _COMPARE:
            raise ValueError(f"op must be one of {sorted(_COMPARE)}, got {op!r}")
        value = float(value)
        passed = bool(not math.isnan(value) and _COMPARE[op](value, threshold))
        message = f"{name} = {value:.4g}, must be {op} {threshold:.4g}" + (f" ({what})" if what else "")
        self.checks.append(GateCheck(name, passed, value, op, float(threshold), message))
        return passed

    def require(self, name: str, passed: bool, message: str) -> bool:
        """A pass/fail gate with its own message (e.g. a solver status)."""
        self.checks.append(GateCheck(name, bool(passed), None, "", None, f"{name}: {message}"))
        return bool(passed)

    @property
    def failed(self) -> list[GateCheck]:
        return [c for c in self.checks if not c.passed]

    def as_summary(self) -> dict:
        """JSON-able record for ``summary.json``."""
        return {"passed": not self.failed, "checks": [asdict(c) for c in self.checks]}

    def finish(self, result: _HasSummary) -> _HasSummary:
        """Record the gates in ``result.summary``; raise unless all passed or ``accept_poor``."""
        result.summary["quality_gates"] = self.as_summary()
        result.summary["accepted_poor"] = bool(self.failed) and self.accept_poor
        if self.failed and not self.accept_poor:
            first = self.failed[0]
            more = f" (+{len(self.failed) - 1} more gate(s) failed)" if len(self.failed) > 1 else ""
            raise QualityGateError(self.stage, first.name, first.message + more
                                   + "; nothing handed on (--accept-poor to continue knowingly)", result=result)
        return result
