"""Errors that name the file, the field and the problem.

The CLI prints a :class:`PipelineError` as one line and exits with code 2 (3 for a
:class:`QualityGateError`).
"""

from __future__ import annotations

from pathlib import Path

#: where a value came from, named in an error: a file, ``--set``, ... or None
Source = str | Path | None


#: the characters ``str.splitlines`` breaks at, as escapes (so a message stays one line)
_LINE_BREAK_ESCAPES = {ord(c): repr(c)[1:-1] for c in "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"}


class PipelineError(Exception):
    """A user-facing error: ``<file>: <field>: <problem>``."""

    def __init__(self, file: str | Path | None, field: str | None, problem: str) -> None:
        self.file = str(file) if file is not None else None
        self.field = field
        self.problem = problem
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """``file: field: problem``, line breaks inside a part (a key or value quoted from the input)
        written as escapes: one line whatever the input held."""
        parts = [p for p in (self.file, self.field) if p]
        return ": ".join([*parts, self.problem]).translate(_LINE_BREAK_ESCAPES)

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        """Pickled by its fields: an error raised in a worker process reaches its parent as itself."""
        return type(self), (self.file, self.field, self.problem)


class ConfigError(PipelineError):
    """The run configuration is invalid."""


class RobotFileError(PipelineError):
    """A URDF or robot.yaml is missing or invalid."""


class DataFileError(PipelineError):
    """A measurement file is missing or invalid."""


class SolverError(PipelineError):
    """A numerical solver failed; never returned as a result."""


class InfeasibleError(PipelineError):
    """A path point, pose or limit cannot be met."""


class ArtefactWriteError(PipelineError):
    """A file of the run could not be written (disk full, read-only, permissions)."""


class QualityGateError(PipelineError):
    """A stage's result failed one of its quality gates (:mod:`pipeline.quality`).

    ``result`` is the stage's unaccepted result (a ``StageResult``) when the stage had one, so
    the runner can keep it aside for inspection without handing it on.
    """

    def __init__(self, file: str | Path | None, field: str | None, problem: str, result: object = None) -> None:
        super().__init__(file, field, problem)
        self.result = result

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        return type(self), (self.file, self.field, self.problem, self.result)
