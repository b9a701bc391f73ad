"""Registry of studies: ``python -m pipeline study <name> [args...]``.

A study is a longer experiment (a paper reproduction, a benchmark sweep) that is not part of
the pipeline run. Its code lives in :mod:`pipeline.papers` (never in a stage package), and it is
registered by adding one line to :data:`STUDIES`::

    "calib-kpi": "pipeline.papers.calib_kpi:kpi_study",

The function is imported only when its study is run. It is called as ``fn(argv)`` with the
remaining command-line arguments (a list of strings; parse them with argparse) and returns an
exit code (``int``) or ``None`` for success. Raise :class:`pipeline.core.errors.PipelineError` for
bad input. Write outputs under ``data/studies/<name>/`` (see :func:`study_dir`) and the result
with :func:`save_result`.

Committed evidence: ``python -m pipeline study NAME [ARGS...] --results DIR`` runs the study as
usual and also writes what it printed to ``DIR/tables.md`` and its result to ``DIR/results.json``
(``{"study", "command", "variant", "provenance", "result"}``; ``variant``: ``quick`` with
``--quick``, ``full`` with the study's defaults, else ``custom`` — the command says which).
``docs/papers/results/<study>/`` holds the committed ones; ``tests/papers/test_papers_evidence.py``
checks docs/PAPERS.md against them.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import math
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from pipeline.core.artefacts import write_text
from pipeline.core.config import REPO_ROOT
from pipeline.core.errors import PipelineError

#: study name -> "module:function" (modules in :mod:`pipeline.papers`).
STUDIES: dict[str, str] = {
    # calibration
    "calib-004": "pipeline.papers.calib_004:study_004",
    "calib-000": "pipeline.papers.calib_000:study",
    "calib-002": "pipeline.papers.calib_002:study_002",
    "calib-003": "pipeline.papers.calib_003:study_003",
    "calib-003-sizes": "pipeline.papers.calib_003_sizes:study",
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
        raise PipelineError("pipeline/papers/registry.py", name, f"expected 'module:function', got {target!r}")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and module_name.startswith(exc.name):
            raise PipelineError("pipeline/papers/registry.py", name, f"module {module_name} does not exist") from None
        raise
    fn = getattr(module, func_name, None)
    if not callable(fn):
        raise PipelineError("pipeline/papers/registry.py", name, f"{module_name} has no function {func_name}")
    return fn


#: the evidence folder of the study being run with ``--results`` (None: no evidence written)
_EVIDENCE: dict[str, Path | None] = {"dir": None}
_EVIDENCE_META: dict[str, object] = {}


class _Tee(io.TextIOBase):
    """Write to the terminal and keep a copy (the study's printed tables)."""

    def __init__(self, stream) -> None:
        self.stream = stream
        self.copy = io.StringIO()

    def write(self, text: str) -> int:
        self.copy.write(text)
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()


def _variant(argv: Sequence[str]) -> str:
    """``quick`` (``--quick``), ``full`` (the study's defaults; ``--jobs``/``--scheduler`` aside) or
    ``custom`` (other arguments: the command in the file says which)."""
    if "--quick" in argv:
        return "quick"
    rest = [a for i, a in enumerate(argv) if a not in ("--jobs", "--scheduler")
            and (i == 0 or argv[i - 1] not in ("--jobs", "--scheduler"))]
    return "custom" if rest else "full"


@contextlib.contextmanager
def _capture(results_dir: Path, name: str, argv: Sequence[str]) -> Iterator[None]:
    variant = _variant(argv)
    command = " ".join(["python -m pipeline study", name, *argv, "--results", str(results_dir)])
    _EVIDENCE["dir"] = results_dir
    _EVIDENCE_META.clear()
    _EVIDENCE_META.update({"study": name, "command": command, "variant": variant,
                           "provenance": "simulated (the study's hidden robots)"})
    tee = _Tee(sys.stdout)
    old, sys.stdout = sys.stdout, tee
    try:
        yield
    finally:
        sys.stdout = old
        _EVIDENCE["dir"] = None
        header = (f"<!-- written by `{command}` ({variant} variant); provenance: simulated -->\n"
                  f"# {name} ({variant} variant): printed output\n\n```\n")
        write_text(results_dir / "tables.md", header + tee.copy.getvalue() + "```\n")


def _finite(node: object) -> object:
    """``node`` with every non-finite number (a standard error of one seed, an infinite factor)
    written as None (JSON has no NaN or infinity)."""
    if isinstance(node, float) and not math.isfinite(node):
        return None
    if isinstance(node, dict):
        return {k: _finite(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_finite(v) for v in node]
    return node


def shallow_json(node: object, depth: int = 3, level: int = 0) -> str:
    """JSON indented down to ``depth`` levels, each deeper value on one line: a committed result
    with thousands of rows stays readable and diffable at a third of its fully indented size."""
    if level >= depth or not isinstance(node, (dict, list)) or not node:
        return json.dumps(node, separators=(",", ":"), allow_nan=False)
    pad, end = " " * (level + 1), " " * level
    if isinstance(node, dict):
        items = [f"{pad}{json.dumps(k)}: {shallow_json(v, depth, level + 1)}" for k, v in node.items()]
        return "{\n" + ",\n".join(items) + "\n" + end + "}"
    return "[\n" + ",\n".join(pad + shallow_json(v, depth, level + 1) for v in node) + "\n" + end + "]"


def save_result(name: str, result: dict, filename: str = "result.json") -> Path:
    """Write ``result`` to ``data/studies/<name>/<filename>``; under ``--results DIR`` also
    ``DIR/results.json`` with the command, variant and provenance of the run."""
    path = study_dir(name) / filename
    path.write_text(json.dumps(result, indent=1, default=float))
    print(f"written {path}")
    evidence = _EVIDENCE["dir"]
    if evidence is not None:
        text = json.dumps({**_EVIDENCE_META, "result": result}, indent=1, default=float)
        write_text(evidence / "results.json", shallow_json(_finite(json.loads(text))) + "\n")
        print(f"written {evidence / 'results.json'}")
    return path


def run_study(name: str, argv: Sequence[str] = (), results_dir: str | Path | None = None) -> int:
    """Run a registered study; returns its exit code (0 when it returned None). With
    ``results_dir`` its printed output and result are also written there (module docstring)."""
    fn = resolve(name)
    if results_dir is None:
        result = fn(list(argv))
    else:
        folder = Path(results_dir)
        folder.mkdir(parents=True, exist_ok=True)
        with _capture(folder, name, argv):
            result = fn(list(argv))
    return 0 if result is None else int(result)


def study_dir(name: str, root: str | Path | None = None) -> Path:
    """``<repo>/data/studies/<name>/`` (created)."""
    base = Path(root) if root is not None else REPO_ROOT / "data" / "studies"
    path = base / name
    path.mkdir(parents=True, exist_ok=True)
    return path
