"""Progress bars (rich) for anything that takes more than a few seconds.

Usage in stage code::

    for q in ctx.progress.track(configurations, "measuring"):
        ...
    with ctx.progress.task("solving NLP", total=n_iter) as task:
        ...
        task.advance()

Outside the runner, the module-level :func:`track` / :func:`task` use the active
:class:`Progress` if there is one, else a temporary one. When stderr is not a terminal
(tests, CI, pipes) nothing is drawn; the iterables pass through unchanged. Compiled code
being built shows as a task ``compiling <name> ...`` (:mod:`pipeline.core.codegen`).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from rich.progress import Progress as RichProgress
    from rich.progress import TaskID

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress

T = TypeVar("T")

_ACTIVE: Progress | None = None


class TaskHandle:
    """Handle of one progress task: ``advance(n)``, ``update(completed=..., total=...)``."""

    def __init__(self, progress: RichProgress | None, task_id: TaskID | None) -> None:
        self._progress = progress
        self._task_id = task_id

    def advance(self, n: float = 1.0) -> None:
        if self._progress is not None:
            self._progress.advance(self._task_id, n)

    def update(self, **kwargs: Any) -> None:  # Any: rich's own keyword arguments
        """Forwarded to ``rich.progress.Progress.update`` (completed, total, description)."""
        if self._progress is not None:
            self._progress.update(self._task_id, **kwargs)


class Progress:
    """A rich progress display, started/stopped as a context manager.

    ``enabled=None`` draws only when stderr is a terminal.
    """

    def __init__(self, enabled: bool | None = None, transient: bool = False) -> None:
        if enabled is None:
            enabled = sys.stderr.isatty()
        self.enabled = enabled
        self._rich: RichProgress | None = None
        self._transient = transient
        self._depth = 0
        self._previous: Progress | None = None
        self._pid = os.getpid()     # a forked child does not draw on its parent's display

    # context management ------------------------------------------------------------------
    def __enter__(self) -> Progress:
        global _ACTIVE
        if self._depth == 0:
            if self.enabled:
                self._rich = RichProgress(
                    SpinnerColumn(),
                    TextColumn("[progress.description]{task.description}"),
                    BarColumn(),
                    MofNCompleteColumn(),
                    TimeElapsedColumn(),
                    TimeRemainingColumn(),
                    console=Console(stderr=True),
                    transient=self._transient,
                )
                try:
                    self._rich.start()
                except Exception:  # another live display is active: stay quiet
                    self._rich = None
            self._previous = _ACTIVE
            _ACTIVE = self
        self._depth += 1
        return self

    def __exit__(self, *exc: object) -> None:
        global _ACTIVE
        self._depth -= 1
        if self._depth == 0:
            if self._rich is not None:
                self._rich.stop()
                self._rich = None
            _ACTIVE = self._previous

    # API -----------------------------------------------------------------------------------
    @contextlib.contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[TaskHandle]:
        """A progress task for work that is not a simple loop; removed when done."""
        with self:
            task_id = self._rich.add_task(description, total=total) if self._rich is not None else None
            try:
                yield TaskHandle(self._rich, task_id)
            finally:
                if self._rich is not None and task_id is not None:
                    self._rich.remove_task(task_id)

    def track(self, iterable: Iterable[T], description: str, total: float | None = None) -> Iterator[T]:
        """Yield from ``iterable`` while advancing a bar (total from ``len()`` when possible)."""
        if total is None:
            try:
                total = len(iterable)  # type: ignore[arg-type]
            except TypeError:
                total = None
        with self.task(description, total=total) as handle:
            for item in iterable:
                yield item
                handle.advance()

    def log(self, message: str) -> None:
        """Print a line above the bars (stderr), or plainly when not drawing."""
        if self._rich is not None:
            self._rich.console.print(message)
        else:
            print(message, file=sys.stderr)


def current() -> Progress:
    """The active progress display, or a new quiet-unless-terminal one; in a forked child of the
    process that owns the active display (a run's background warm-up, a worker of
    :mod:`pipeline.core.forks`), a quiet one: the terminal's display is the parent's, and its copy
    in the child holds the parent's locks as they were at the fork."""
    if _ACTIVE is None:
        return Progress()
    return _ACTIVE if _ACTIVE._pid == os.getpid() else Progress(enabled=False)


def track(iterable: Iterable[T], description: str, total: float | None = None) -> Iterator[T]:
    """Module-level :meth:`Progress.track` on the active display."""
    return current().track(iterable, description, total)


def task(description: str, total: float | None = None) -> contextlib.AbstractContextManager[TaskHandle]:
    """Module-level :meth:`Progress.task` on the active display."""
    return current().task(description, total)


#: name used in docs/ARCHITECTURE.md
progress = track
