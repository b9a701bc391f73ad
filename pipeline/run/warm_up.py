"""Compiled code built in the background while the earlier stages of a run work.

A stage module may expose ``warm_up(config, robot) -> None``: it builds, into the on-disk cache of
:mod:`pipeline.core.codegen`, compiled code the stage will need that depends only on the robot's
structure and the stage's own settings, never on an upstream result (the trajectory stage's PtP
NLP: the arm's parameters are inputs of its code). With an empty cache such a build is the longest
single step of a run (about 45 s of gcc for a 6-axis arm's PtP Hessian), and the stages before
it mostly keep one core busy: the runner starts the warm-ups of the stages that will run in one
forked process, one gcc at a time, so the build takes the idle core (with two gcc processes the
calibration's two-core steps were slowed by more than the build saved: a cold default run took 193 s
instead of 171 s). It runs at the run's own priority: at a lower one
a busy machine starves it (measured: a PtP build at ``nice`` 10 beside two test workers made no
progress in minutes), and the stage that waits for its library would wait longer than its own
build takes.

Nothing depends on the warm-up finishing. A stage that asks for a library while the warm-up
compiles it waits for the build's file lock (:func:`pipeline.core.codegen.build_library`) instead of
compiling it a second time; a warm-up that fails leaves nothing behind and the stage builds (and
reports) for itself. The process is stopped when the run ends, however it ends: a half-built
library is never renamed into the cache.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import sys
from collections.abc import Callable, Iterator, Sequence
from types import FrameType

#: seconds given to a stopped warm-up to clean its temporary build folder before it is killed
STOP_TIMEOUT_S = 5.0

Task = tuple[str, Callable[[], None]]


def _stop_quietly(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(0)     # unwinds the build: gcc killed, its temporary folder removed


def _run_tasks(tasks: Sequence[Task]) -> None:
    """The child: no output, each task in turn; a failing task is left to its stage."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)       # Ctrl-C is the run's; it stops this process
    signal.signal(signal.SIGTERM, _stop_quietly)
    os.environ["PIPELINE_JOBS"] = "1"   # one gcc at a time: the stages keep the other core
    with open(os.devnull, "w") as sink:
        sys.stdout = sys.stderr = sink
        for _name, task in tasks:
            try:
                task()
            except Exception:   # noqa: BLE001 -- the stage builds again and reports its own error
                continue


@contextlib.contextmanager
def warmed_up(tasks: Sequence[Task]) -> Iterator[mp.process.BaseProcess | None]:
    """Run ``tasks`` (``(stage name, callable)``) in a background process for the duration of the
    ``with`` block; yields the process (None: nothing to do, or no ``fork`` on this platform)."""
    if not tasks or "fork" not in mp.get_all_start_methods() or mp.current_process().daemon:
        yield None
        return
    process = mp.get_context("fork").Process(target=_run_tasks, args=(list(tasks),), name="warm-up", daemon=True)
    process.start()
    try:
        yield process
    finally:
        if process.is_alive():
            process.terminate()
            process.join(STOP_TIMEOUT_S)
            if process.is_alive():
                process.kill()
        process.join()
