"""One stage run: its context, its staging directory, the result committed as ``<run>/<stage>/``
or kept aside in ``<run>/<stage>.rejected/`` after a failed quality gate.

The stage gets a private copy of the latest robot handed on upstream, a fresh hidden robot (none
for a recorded stage: it simulates nothing), the loaded results of its upstream stages and a
generator seeded by (run seed, stage name); what it returns is written, committed, and handed on as
read back from disk (:func:`pipeline.run.stage_io.load_stage_output`).
"""

from __future__ import annotations

import errno
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pipeline.core.config import RunConfig
from pipeline.core.errors import ArtefactWriteError, QualityGateError
from pipeline.core.interrupts import caused_by_interrupt, interrupted
from pipeline.core.progress import Progress
from pipeline.robot.model import RobotModel
from pipeline.run import stage_io
from pipeline.run.stage_io import REJECTED_SUFFIX, load_stage_output, write_rejected, write_stage_result
from pipeline.run.stage_plan import Plan
from pipeline.sim.mujoco_robot import create_hidden_robot
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.stage_api import StageContext, StageOutput, StageResult, stage_rng

__all__ = ["make_real", "write_error", "run_one"]


def make_real(nominal: RobotModel, cfg: RunConfig) -> RealRobot:
    """The hidden robot of the run (``truth`` section, seeded by the run)."""
    truth_cfg = cfg.sections.get("truth")
    if not isinstance(truth_cfg, TruthConfig):
        truth_cfg = TruthConfig()
    return create_hidden_robot(nominal, cfg.seed, truth_cfg)


def write_error(exc: OSError, path: Path | str) -> ArtefactWriteError:
    """The error of a failed write, naming the file; earlier results are intact."""
    return ArtefactWriteError(getattr(exc, "filename", None) or path, None,
                              f"cannot write ({exc.strerror or exc}); earlier results are intact")


def _copy_robot(robot: RobotModel) -> RobotModel:
    copy = getattr(robot, "copy", None)
    return copy() if callable(copy) else robot


def _check_result(name: str, result: object) -> StageResult:
    where = f"stage {name}"
    if not isinstance(result, StageResult):
        raise TypeError(f"{where}: run() returned {type(result).__name__}, expected StageResult")
    if not isinstance(result.summary, dict):
        raise TypeError(f"{where}: StageResult.summary must be a dict")
    for key in result.figures:
        if not str(key).replace("_", "").replace("-", "").isalnum():
            raise ValueError(f"{where}: figure name {key!r} must be a plain file stem")
    return result


def _context(plan: Plan, cfg: RunConfig, nominal: RobotModel, outputs: dict[str, StageOutput],
             handed_robot: dict[str, RobotModel], staging: Path, prog: Progress) -> StageContext[Any]:
    robot = nominal
    for up in plan.closure:                   # latest robot handed on upstream
        if up in handed_robot:
            robot = handed_robot[up]
    # a fresh hidden robot per stage: its sensors draw noise from generators seeded by the run, so a
    # stage measures the same whether the earlier stages ran in this process or were reused
    # a recorded stage gets no hidden robot: it simulates nothing
    real = None if plan.provenance.recorded else make_real(nominal, cfg)
    return StageContext(run=cfg, config=plan.config, robot=_copy_robot(robot), real=real,
                        upstream={u: outputs[u] for u in plan.closure}, out_dir=staging,
                        rng=stage_rng(cfg.seed, plan.name), progress=prog, provenance=plan.provenance)


def run_one(plan: Plan, cfg: RunConfig, run_dir: Path, nominal: RobotModel, outputs: dict[str, StageOutput],
            handed_robot: dict[str, RobotModel], key: str, prog: Progress,
            say: Callable[[str], None]) -> StageOutput:
    """Run stage ``plan`` into a staging directory and commit it as ``run_dir/<stage>/``."""
    try:
        staging = stage_io.new_stage_dir(run_dir, plan.name)
    except OSError as exc:
        raise write_error(exc, run_dir) from None
    ctx = _context(plan, cfg, nominal, outputs, handed_robot, staging, prog)
    say(f"{plan.name}: running ({plan.provenance.sentence()})")
    t0 = time.perf_counter()
    rejected = run_dir / f"{plan.name}{REJECTED_SUFFIX}"
    try:
        result = _check_result(plan.name, plan.module.run(ctx))
        result.summary["provenance"] = plan.provenance.to_dict()
        if interrupted():             # the stage swallowed the signal: never commit its result
            raise KeyboardInterrupt(f"stage {plan.name} interrupted")
        duration = time.perf_counter() - t0
        write_stage_result(staging, plan.name, result, plan.inputs_sha256, duration, key, plan.inputs)
        final = stage_io.commit_stage_dir(staging, run_dir / plan.name)
    except QualityGateError as exc:
        if isinstance(exc.result, StageResult):
            exc.result.summary["provenance"] = plan.provenance.to_dict()
            try:
                write_rejected(staging, rejected, plan.name, exc.result, exc.one_line())
                say(f"{plan.name}: quality gate failed; its result is kept for inspection in {rejected} "
                    "(not handed on)")
            except OSError:
                stage_io.discard_stage_dir(staging)
        else:
            stage_io.discard_stage_dir(staging)
        raise
    except OSError as exc:
        stage_io.discard_stage_dir(staging)
        if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG):
            raise write_error(exc, staging) from None
        raise
    except BaseException as exc:
        stage_io.discard_stage_dir(staging)
        if not isinstance(exc, KeyboardInterrupt) and caused_by_interrupt(exc):
            raise KeyboardInterrupt(f"stage {plan.name} interrupted") from exc
        raise
    stage_io.discard_stage_dir(rejected)       # an older rejected result is out of date now
    say(f"{plan.name}: done in {duration:.1f} s")
    # hand on what is on disk (the robot read back exactly): later stages then see the same
    # inputs whether this stage ran in this process or is reused in another one
    return load_stage_output(final, verify=False)
