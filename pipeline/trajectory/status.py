"""IPOPT return statuses of the trajectory solvers: success, interrupt, or a stage error.

A status other than success is never stored as a result: the planners raise instead, and the
stage stores the success status string (``solver_status`` entries of results.json). IPOPT turns a
Ctrl-C inside a callback into ``NonIpopt_Exception_Thrown`` (or ``User_Requested_Stop`` when
CasADi's iteration callback stops it): those are re-raised as :class:`KeyboardInterrupt` so that an
interrupt ends the run as an interrupt, never as "IPOPT failed" (private helper until a shared
one exists in the pipeline).
"""

from __future__ import annotations

INTERRUPT_STATUSES = ("NonIpopt_Exception_Thrown", "User_Requested_Stop")
SUCCESS_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def raise_if_interrupted(status: str, what: str) -> None:
    """KeyboardInterrupt when ``status`` is IPOPT's answer to an interrupt."""
    if status in INTERRUPT_STATUSES:
        raise KeyboardInterrupt(f"{what}: interrupted (IPOPT {status})")
