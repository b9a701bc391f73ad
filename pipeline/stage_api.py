"""The stage contract: what a stage's ``run(ctx)`` gets and returns, and what later stages read.

``StageContext`` (inputs of ``run``), ``StageResult`` (its return value, written to the stage
directory by :mod:`pipeline.stage_io`) and ``StageOutput`` (a finished stage loaded back).
:mod:`pipeline.runner` re-exports all three (docs/ARCHITECTURE.md, "Stages and the runner").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.config import RunConfig
from pipeline.progress import Progress

if TYPE_CHECKING:          # type names only: the robot layer imports pipeline.artefacts
    from matplotlib.figure import Figure

    from pipeline.robot.model import RobotModel
    from pipeline.robot.truth import RealRobot

__all__ = ["StageContext", "StageResult", "StageOutput"]


@dataclass
class StageContext:
    run: RunConfig                        # name, seed, robot, profile (+ all sections)
    config: Any                           # Any: this stage's own Config dataclass (one type per stage)
    robot: RobotModel                     # best model so far (a private copy)
    real: RealRobot | None                # sensors of the hidden robot (None if unavailable)
    upstream: dict[str, StageOutput]      # loaded results of the earlier stages it depends on
    out_dir: Path                         # staging directory (write extra files here)
    rng: np.random.Generator              # seeded from (run seed, stage name)
    progress: Progress                    # ctx.progress.track(iterable, "description")


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
