"""Independent tasks on forked worker processes, for state that cannot be pickled.

A CasADi solver whose objective is a Python callback (the excitation design's condition number)
cannot be sent to a worker process, but a forked child inherits it. :func:`fork_map` runs
``task(0) .. task(n-1)`` on up to :func:`available_cores` children forked after the task was built
and yields the results in order; only the results are pickled. Without ``fork`` (other platforms),
inside a daemonic worker (which may not have children) or with one core the tasks run here, one
after the other: the results do not depend on where they ran when ``task`` is a pure function of
its index. The children ignore SIGINT; Ctrl-C reaches this process, which stops them.

:func:`in_background` runs one computation in a forked child while this process goes on with
another (the trajectory stage's CP plan beside its PtP plans); the child is not daemonic, so it may
use :func:`fork_map` itself. Errors reach the caller as themselves (:class:`pipeline.core.errors.PipelineError`
pickles by its fields).
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
from collections.abc import Callable, Iterator
from multiprocessing.connection import Connection
from typing import TypeVar, cast

T = TypeVar("T")

#: the task of the pool being run (set before the fork, so every child has it)
_TASK: list[Callable[[int], object]] = []


def available_cores() -> int:
    """``$PIPELINE_JOBS`` when set, else the cores this process may run on (its CPU affinity); >= 1."""
    if os.environ.get("PIPELINE_JOBS"):
        return max(1, int(os.environ["PIPELINE_JOBS"]))
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def _call(k: int) -> object:
    return _TASK[-1](k)


def _child_signals() -> None:
    """Ctrl-C is the parent's to handle; SIGTERM (how the pool stops its workers) ends a child
    quietly, not through the parent's SIGTERM-as-KeyboardInterrupt handler (:mod:`pipeline.core.interrupts`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def fork_map(task: Callable[[int], T], n: int, jobs: int | None = None) -> Iterator[T]:
    """``task(k)`` for ``k = 0 .. n-1``, in order, on up to ``jobs`` (default: the available cores)
    forked processes, or here when forking is not possible (module docstring)."""
    jobs = min(n, available_cores() if jobs is None else jobs)
    if jobs <= 1 or "fork" not in mp.get_all_start_methods() or mp.current_process().daemon:
        for k in range(n):
            yield task(k)
        return
    _TASK.append(task)
    try:
        with mp.get_context("fork").Pool(jobs, initializer=_child_signals) as pool:
            for result in pool.imap(_call, range(n)):
                yield cast(T, result)    # what task returned, pickled by the child
            pool.close()
            pool.join()
    finally:
        _TASK.pop()


def _can_fork() -> bool:
    return "fork" in mp.get_all_start_methods() and not mp.current_process().daemon


def _send_result(fn: Callable[[], object], send: Connection) -> None:
    """The background child: ``fn()`` or its error, pickled to the parent."""
    _child_signals()
    try:
        outcome: tuple[bool, object] = (True, fn())
    except BaseException as exc:  # noqa: BLE001 -- handed to the parent, which raises it
        outcome = (False, exc)
    try:
        send.send(outcome)
    except Exception as exc:  # noqa: BLE001 -- a result or error that cannot be pickled
        send.send((False, RuntimeError(f"the background task's outcome could not be sent: {exc!r}")))
    send.close()


@contextlib.contextmanager
def in_background(fn: Callable[[], T]) -> Iterator[Callable[[], T]]:
    """``with in_background(fn) as result: ...; value = result()``: ``fn()`` runs in a forked child
    while the block goes on; ``result()`` waits for it and returns its value or raises its error.
    With one available core, without ``fork`` or inside a daemonic worker, ``fn()`` runs here on
    entering the block (the order of a serial program). Leaving the block stops a child still running."""
    if available_cores() < 2 or not _can_fork():
        value = fn()
        yield lambda: value
        return
    recv, send = mp.get_context("fork").Pipe(duplex=False)
    child = mp.get_context("fork").Process(target=_send_result, args=(fn, send), name="background")
    child.start()
    send.close()
    outcome: list[tuple[bool, object]] = []

    def result() -> T:
        if not outcome:
            try:
                outcome.append(recv.recv())
            except EOFError:
                child.join()
                raise RuntimeError(f"the background task ended without a result (exit code {child.exitcode})"
                                   ) from None
        ok, payload = outcome[0]
        if not ok:
            raise cast(BaseException, payload)
        return cast(T, payload)

    try:
        yield result
    finally:
        recv.close()
        if child.is_alive() and not outcome:
            child.terminate()
        child.join()
