"""Registry of studies: ``python -m pipeline study <name> [args...]``.

A study is a longer experiment (a paper reproduction, a benchmark sweep) that is not part of
the pipeline run. Its code lives in :mod:`pipeline.papers` (never in a stage package), and it is
registered by adding one line to :data:`STUDIES`::

    "calib-kpi": "pipeline.papers.calib_kpi:kpi_study",

The function is imported only when its study is run. It is called as ``fn(argv)`` with the
remaining command-line arguments (a list of strings; parse them with argparse) and returns an
exit code (``int``) or ``None`` for success. Raise :class:`pipeline.errors.PipelineError` for
bad input. Write outputs under ``data/studies/<name>/`` (see :func:`study_dir`).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from pathlib import Path

from pipeline.config import REPO_ROOT
from pipeline.errors import PipelineError

#: study name -> "module:function" (modules in :mod:`pipeline.papers`).
STUDIES: dict[str, str] = {
    # calibration
    "calib-004": "pipeline.papers.calib_004:study_004",
    "calib-000": "pipeline.papers.calib_000:study",
    "calib-002": "pipeline.papers.calib_002:study_002",
    "calib-003": "pipeline.papers.calib_003:study_003",
    "calib-design": "pipeline.papers.calib_design:study_design",
    # whole-chain paper reproductions
    "paper-004": "pipeline.papers.chain_004:study_paper_004",
}


def list_studies() -> list[str]:
    return sorted(STUDIES)


def resolve(name: str) -> Callable[[list[str]], int | None]:
    """The callable of study ``name`` (imported now)."""
    if name not in STUDIES:
        known = ", ".join(list_studies()) or "none registered"
        raise PipelineError("study", name, f"unknown study (known: {known})")
    target = STUDIES[name]
    module_name, _, func_name = target.partition(":")
    if not func_name:
        raise PipelineError("pipeline/studies.py", name, f"expected 'module:function', got {target!r}")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and module_name.startswith(exc.name):
            raise PipelineError("pipeline/studies.py", name, f"module {module_name} does not exist") from None
        raise
    fn = getattr(module, func_name, None)
    if not callable(fn):
        raise PipelineError("pipeline/studies.py", name, f"{module_name} has no function {func_name}")
    return fn


def run_study(name: str, argv: Sequence[str] = ()) -> int:
    """Run a registered study; returns its exit code (0 when it returned None)."""
    result = resolve(name)(list(argv))
    return 0 if result is None else int(result)


def study_dir(name: str, root: str | Path | None = None) -> Path:
    """``<repo>/data/studies/<name>/`` (created)."""
    base = Path(root) if root is not None else REPO_ROOT / "data" / "studies"
    path = base / name
    path.mkdir(parents=True, exist_ok=True)
    return path
