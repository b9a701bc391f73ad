"""The stage contract: what a stage's ``run(ctx)`` gets and returns, and what later stages read.

``StageContext`` (inputs of ``run``), ``StageResult`` (its return value, written to the stage
directory by :mod:`pipeline.stage_io`) and ``StageOutput`` (a finished stage loaded back).
Every stage imports them from here, never from :mod:`pipeline.runner` (docs/ARCHITECTURE.md, "Layers").
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from pipeline.config import RunConfig
from pipeline.progress import Progress
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot

__all__ = ["StageContext", "StageResult", "StageOutput", "stage_rng", "stable_stage_hash"]


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


def stable_stage_hash(name: str) -> int:
    """32-bit integer from sha256(name): stable across processes (unlike ``hash()``)."""
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "little")


def stage_rng(seed: int, stage: str) -> np.random.Generator:
    """``np.random.default_rng([seed, stable_stage_hash(stage)])``."""
    return np.random.default_rng([seed, stable_stage_hash(stage)])
