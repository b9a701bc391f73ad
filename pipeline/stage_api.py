"""The stage contract: what a stage module declares, what its ``run(ctx)`` gets and returns, and
what later stages read.

``StageModule`` (the names a stage module defines, checked by mypy where the run layer lists the
stages, :mod:`pipeline.run.stages`), ``StageContext`` (inputs of ``run``, generic in the stage's
``Config``), ``StageResult`` (its return value, written to the stage directory by
:mod:`pipeline.run.stage_io`) and ``StageOutput`` (a finished stage loaded back).
Every stage imports them from here, never from :mod:`pipeline.run.runner` (docs/ARCHITECTURE.md, "Layers").
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

import numpy as np
from matplotlib.figure import Figure

from pipeline.core.config import RunConfig
from pipeline.core.progress import Progress
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot

__all__ = ["StageModule", "StageContext", "StageResult", "StageOutput", "stage_rng", "stable_stage_hash",
           "Provenance", "RECORDED", "SIMULATED", "ROBOT_FILES", "own_provenance", "declared"]

ConfigT = TypeVar("ConfigT")

#: provenance kinds: a file the user measured, the simulated world (:mod:`pipeline.sim`), the robot files only
RECORDED, SIMULATED, ROBOT_FILES = "recorded", "simulated", "robot files"
PROVENANCE_KINDS = (RECORDED, SIMULATED, ROBOT_FILES)
#: the run's provenance record: each stage's :class:`Provenance` and the second-pass decision
#: (written by the runner, read by the headline)
PROVENANCE_FILE = "provenance.json"


@dataclass(frozen=True)
class Provenance:
    """Where a stage's inputs come from (decided by the stage plan, :mod:`pipeline.run.stage_plan`).

    ``kind``: ``recorded`` (a file of the stage's ``RECORDED_INPUT`` field), ``simulated`` (what the
    stage's ``SIMULATES`` names, on the hidden robot) or ``robot files`` (no measurement at all).
    ``upstream``: the stages whose results it uses; ``left_out``: the simulated stages a recorded
    stage does not use (it starts from the nominal model or a recorded stage's robot instead);
    ``note``: one sentence for the report (e.g. which kinematics a recorded stage starts from)."""

    kind: str
    source: str
    upstream: tuple[str, ...] = ()
    left_out: tuple[str, ...] = ()
    note: str = ""

    def __post_init__(self) -> None:
        if self.kind not in PROVENANCE_KINDS:
            raise ValueError(f"provenance kind {self.kind!r} is not one of {PROVENANCE_KINDS}")

    @property
    def recorded(self) -> bool:
        return self.kind == RECORDED

    @property
    def simulated(self) -> bool:
        return self.kind == SIMULATED

    def label(self) -> str:
        """``recorded (<file name>)``, ``simulated (<what>)`` or ``robot files``."""
        if self.kind == ROBOT_FILES:
            return ROBOT_FILES
        source = Path(self.source).name if self.recorded else self.source
        return f"{self.kind} ({source})" if source else self.kind

    def sentence(self) -> str:
        """The label, the stages used and the note: one line of the console and of report.md."""
        text = self.label()
        if self.upstream:
            text += f"; uses {', '.join(self.upstream)}"
        return f"{text}; {self.note}" if self.note else text

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "source": self.source, "upstream": list(self.upstream),
                "left_out": list(self.left_out), "note": self.note}

    @classmethod
    def from_dict(cls, data: object) -> Provenance | None:
        """The record saved by :meth:`to_dict` (None: no such record, e.g. a summary of older code)."""
        if not isinstance(data, dict) or data.get("kind") not in PROVENANCE_KINDS:
            return None
        return cls(str(data["kind"]), str(data.get("source") or ""), tuple(map(str, data.get("upstream") or ())),
                   tuple(map(str, data.get("left_out") or ())), str(data.get("note") or ""))


@dataclass
class StageContext(Generic[ConfigT]):
    """What ``run(ctx)`` of a stage gets: ``ctx.config`` is its own section (``StageContext[Config]``)."""

    run: RunConfig                        # name, seed, robot, profile (+ all sections)
    config: ConfigT                       # this stage's own Config dataclass
    robot: RobotModel                     # best model so far (a private copy)
    real: RealRobot | None                # sensors of the hidden robot (None if unavailable)
    upstream: dict[str, StageOutput]      # loaded results of the earlier stages it depends on
    out_dir: Path                         # staging directory (write extra files here)
    rng: np.random.Generator              # seeded from (run seed, stage name)
    progress: Progress                    # ctx.progress.track(iterable, "description")
    provenance: Provenance | None = None  # recorded or simulated inputs (None: a context built by hand)


@dataclass
class StageResult:
    summary: dict[str, Any]                                 # -> summary.json (headline figures)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)   # -> results.npz
    data: dict[str, Any] = field(default_factory=dict)      # -> results.json
    figures: dict[str, Figure] = field(default_factory=dict)  # matplotlib Figures -> <name>.png
    robot: RobotModel | None = None                         # RobotModel handed on -> robot/
    report_md: str = ""                                     # extra markdown for report.md


@dataclass
class StageOutput:
    """What later stages get from a finished stage."""

    summary: dict[str, Any]
    arrays: dict[str, np.ndarray]
    data: dict[str, Any]
    robot: RobotModel | None             # from ``<stage>/robot/`` (exact, see pipeline.robot.exact)
    path: Path


def stable_stage_hash(name: str) -> int:
    """32-bit integer from sha256(name): stable across processes (unlike ``hash()``)."""
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "little")


def stage_rng(seed: int, stage: str) -> np.random.Generator:
    """``np.random.default_rng([seed, stable_stage_hash(stage)])``."""
    return np.random.default_rng([seed, stable_stage_hash(stage)])


class StageModule(Protocol):
    """The names a stage module defines (docs/writing-a-stage.md).

    ``NAME``: the stage's name (its section of the run configuration); ``DEPENDS``: the upstream
    stages whose results it reads; ``Config``: the dataclass of its section, whose file inputs are
    ``Annotated[str | None, FileInput]`` fields (:class:`pipeline.core.typed_config.FileInput`: the
    inputs hash covers their content); ``CONFIG_READS``: settings of other sections ``run`` reads
    (dotted, e.g. ``"control.iso"``: in its inputs hash); ``RECORDED_INPUT``: the ``Config`` field
    naming a recorded measurement file ("" for none) and ``SIMULATES``: what it simulates without
    one ("" for nothing: the stage reads the robot files only), see :class:`Provenance`;
    ``check(config, robot)``: raise a PipelineError before anything runs (a bad data file ...);
    ``warm_up(config, robot)`` or None: compiled code built in the background
    (:mod:`pipeline.run.warm_up`); ``run(ctx)``: the stage.
    """

    @property
    def NAME(self) -> str: ...
    @property
    def DEPENDS(self) -> tuple[str, ...]: ...
    @property
    def Config(self) -> type[Any]: ...                 # Any: one dataclass per stage
    @property
    def CONFIG_READS(self) -> tuple[str, ...]: ...
    @property
    def RECORDED_INPUT(self) -> str: ...
    @property
    def SIMULATES(self) -> str: ...
    @property
    def check(self) -> Callable[[Any, RobotModel], None]: ...
    @property
    def warm_up(self) -> Callable[[Any, RobotModel], None] | None: ...
    @property
    def run(self) -> Callable[[StageContext[Any]], StageResult]: ...


#: the optional names of a stage module and their meaning when left out (a stage written for tests
#: or outside the package may define only NAME, DEPENDS, Config and run)
OPTIONAL_NAMES: dict[str, object] = {"CONFIG_READS": (), "RECORDED_INPUT": "", "SIMULATES": "",
                                     "check": None, "warm_up": None}


def declared(module: object, name: str) -> Any:  # Any: the declared value (its type: StageModule)
    """``module.<name>``, or its meaning when left out (:data:`OPTIONAL_NAMES`)."""
    return getattr(module, name, OPTIONAL_NAMES.get(name))


def own_provenance(module: object, config: object) -> Provenance:
    """Recorded when the stage's ``RECORDED_INPUT`` field names a file, simulated when it declares
    ``SIMULATES``, else robot files (upstream stages not yet filled in)."""
    field_name = str(declared(module, "RECORDED_INPUT") or "")
    record = getattr(config, field_name, None) if field_name else None
    if record:
        return Provenance(RECORDED, str(record))
    simulates = str(declared(module, "SIMULATES") or "")
    return Provenance(SIMULATED, simulates) if simulates else Provenance(ROBOT_FILES, "")
