"""IPOPT return statuses that count as a converged result.

A result whose status is not in :data:`SUCCESS_STATUSES` is never stored as a result (the
stages fall back, fail a quality gate, or raise); an interrupt status is turned into
``KeyboardInterrupt`` by :func:`pipeline.core.interrupts.raise_if_interrupted`.
"""

from __future__ import annotations

#: IPOPT statuses that are a converged result
SUCCESS_STATUSES = frozenset({"Solve_Succeeded", "Solved_To_Acceptable_Level"})


def is_success(status: str) -> bool:
    """``status`` (``solver.stats()["return_status"]``) is a converged result."""
    return str(status) in SUCCESS_STATUSES
