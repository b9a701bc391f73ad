"""Task dispatch: one function over many items, serially, on local worker processes (joblib) or on
a Dask distributed cluster, with a progress bar; the results in input order.

Used by ``python -m pipeline sweep`` (:mod:`pipeline.run.sweep`, one run per grid point) and by studies
that run many independent tasks (e.g. ``study calib-000``, one arm per task). ``jobs=1`` runs the
tasks in this process; ``jobs=N`` in ``N`` joblib (loky) worker processes; ``scheduler`` (an address
such as ``tcp://host:8786``, or a ``distributed.Client``) sends them to a Dask cluster instead
(``jobs`` is then ignored): its workers need this package installed and any file a task reads at
the same path. Tasks finish in any order; each result is put back at its item's position, so the
output does not depend on where or in which order the tasks ran when ``fn`` is a pure function of
its item (every random number from a generator seeded by the item).
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Callable, Sequence
from types import ModuleType
from typing import TypeVar

import joblib

from pipeline.core.errors import ConfigError
from pipeline.core.progress import Progress, current


def _lazy_optional(name: str) -> ModuleType | None:
    """The installed module ``name``, executed at its first attribute access
    (:class:`importlib.util.LazyLoader`), or None when it is not installed."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:
        return None
    spec.loader = importlib.util.LazyLoader(spec.loader)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


#: the optional extra ``cluster`` (dask[distributed]): loaded when a cluster is asked for, not by every
#: process that imports the package (its import takes about a second)
distributed = _lazy_optional("distributed")

T = TypeVar("T")
R = TypeVar("R")

__all__ = ["map_tasks"]


def _indexed(fn: Callable[[T], R], index: int, item: T) -> tuple[int, R]:
    return index, fn(item)


def _run_local(fn: Callable[[T], R], items: Sequence[T], jobs: int, progress: Progress,
               description: str) -> list[R]:
    if jobs == 1:
        return [fn(item) for item in progress.track(items, f"{description} (local)")]
    results: dict[int, R] = {}
    parallel = joblib.Parallel(n_jobs=jobs, return_as="generator_unordered")
    done = parallel(joblib.delayed(_indexed)(fn, i, item) for i, item in enumerate(items))
    for i, result in progress.track(done, f"{description} (joblib)", total=len(items)):
        results[i] = result
    return [results[i] for i in range(len(items))]


def _run_dask(fn: Callable[[T], R], items: Sequence[T], scheduler: object, progress: Progress,
              description: str) -> list[R]:
    if distributed is None:
        raise ConfigError("--scheduler", str(scheduler),
                          "dask distributed is not installed (pip install 'pipeline[cluster]')")
    own = not isinstance(scheduler, distributed.Client)
    try:
        client = distributed.Client(scheduler) if own else scheduler
    except OSError as exc:
        raise ConfigError("--scheduler", str(scheduler), f"cannot connect: {exc}") from None
    try:
        futures = [client.submit(_indexed, fn, i, item, pure=False) for i, item in enumerate(items)]
        results: dict[int, R] = {}
        for future in progress.track(distributed.as_completed(futures), f"{description} (dask)", total=len(futures)):
            i, result = future.result()
            results[i] = result
    finally:
        if own:
            client.close()
    return [results[i] for i in range(len(items))]


def map_tasks(fn: Callable[[T], R], items: Sequence[T], jobs: int = 1, scheduler: object = None,
              progress: Progress | None = None, description: str = "tasks") -> list[R]:
    """``[fn(item) for item in items]`` on ``jobs`` local processes or the Dask ``scheduler``
    (address or ``distributed.Client``), one bar ``description`` on ``progress`` (default: the
    active display). ``fn`` and the items must be picklable for ``jobs > 1`` or a scheduler."""
    if jobs < 1:
        raise ConfigError("--jobs", str(jobs), "must be >= 1")
    prog = progress if progress is not None else current()
    with prog:
        if scheduler is not None:
            return _run_dask(fn, items, scheduler, prog, description)
        return _run_local(fn, items, jobs, prog, description)
