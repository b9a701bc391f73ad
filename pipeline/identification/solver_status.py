"""IPOPT return statuses of the identification's solves: success, interrupt, anything else.

CasADi catches a ``KeyboardInterrupt`` raised inside a Python callback (or IPOPT's own SIGINT
handling) and returns ``NonIpopt_Exception_Thrown`` / ``User_Requested_Stop``; such a status is
turned back into :class:`KeyboardInterrupt` right after the solve so nothing half-optimised is
ever stored. (Private stand-in for the run-wide shared helper; same behaviour.)
"""

from __future__ import annotations

#: IPOPT statuses that are a converged result
SUCCESS_STATUSES = frozenset({"Solve_Succeeded", "Solved_To_Acceptable_Level"})
#: statuses that mean the solve was interrupted (Ctrl-C, SIGTERM, an exception in a callback)
INTERRUPT_STATUSES = frozenset({"NonIpopt_Exception_Thrown", "User_Requested_Stop"})


def raise_if_interrupted(status: str, what: str = "IPOPT") -> None:
    """Raise :class:`KeyboardInterrupt` when ``status`` says the solve was interrupted."""
    if str(status) in INTERRUPT_STATUSES:
        raise KeyboardInterrupt(f"{what} interrupted ({status})")


def is_success(status: str) -> bool:
    return str(status) in SUCCESS_STATUSES
