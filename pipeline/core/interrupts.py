"""Interrupts: Ctrl-C (SIGINT) and SIGTERM end a run promptly, and never as a result.

* :func:`handle_termination` makes SIGTERM raise :class:`KeyboardInterrupt` like SIGINT does, so
  both unwind through the runner (staging directory discarded, nothing committed, exit 130).
* IPOPT inside CasADi does not raise on Ctrl-C: CasADi's interrupt check stops the solver and
  ``solver.stats()["return_status"]`` is ``NonIpopt_Exception_Thrown`` or ``User_Requested_Stop``
  (and the Python exception is swallowed). Stage code calls :func:`raise_if_interrupted` right
  after every ``nlpsol`` call, before looking at the solution::

      sol = solver(x0=..., lbg=..., ubg=...)
      raise_if_interrupted(solver.stats())

  It raises KeyboardInterrupt for those statuses, and whenever a SIGINT/SIGTERM arrived while
  the solver ran (:func:`interrupted`), so a half-finished optimisation is never stored.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator, Mapping
from types import FrameType

#: IPOPT/CasADi return statuses that mean "stopped by an interrupt", not "failed"
INTERRUPT_STATUSES = frozenset({"NonIpopt_Exception_Thrown", "User_Requested_Stop", "User_Interrupt"})

_received: list[int] = []


def _on_signal(signum: int, frame: FrameType | None) -> None:
    _received.append(signum)
    raise KeyboardInterrupt(f"signal {signal.Signals(signum).name}")


def interrupted() -> bool:
    """A SIGINT/SIGTERM arrived while :func:`handle_termination` was active."""
    return bool(_received)


def caused_by_interrupt(exc: BaseException) -> bool:
    """``exc`` is, or came from, an interrupt: a KeyboardInterrupt in its chain (``__cause__`` /
    ``__context__``), or any error raised after a SIGINT/SIGTERM arrived. CasADi's SWIG wrappers
    turn the signal handler's KeyboardInterrupt inside ``DM.__array__`` into ``SystemError: ...
    returned a result with an exception set``."""
    seen: set[int] = set()
    chained: BaseException | None = exc
    while chained is not None and id(chained) not in seen:
        if isinstance(chained, KeyboardInterrupt):
            return True
        seen.add(id(chained))
        chained = chained.__cause__ or chained.__context__
    return interrupted()


def raise_if_interrupted(stats: Mapping[str, object] | str | None, what: str = "solver") -> None:
    """Raise KeyboardInterrupt when a solver was stopped by an interrupt.

    ``stats``: ``solver.stats()`` of a CasADi ``nlpsol`` (or its ``return_status`` string);
    ``what`` names the solve in the message.
    """
    status = stats.get("return_status") if isinstance(stats, Mapping) else stats
    if status in INTERRUPT_STATUSES or interrupted():
        raise KeyboardInterrupt(f"{what} stopped: {status}")


@contextlib.contextmanager
def handle_termination() -> Iterator[None]:
    """SIGINT and SIGTERM raise KeyboardInterrupt inside this block (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _received.clear()
    old = {sig: signal.signal(sig, _on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    except Exception as exc:    # an error an interrupt caused is the interrupt
        if caused_by_interrupt(exc):
            raise KeyboardInterrupt(f"interrupted ({type(exc).__name__})") from exc
        raise
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        _received.clear()
