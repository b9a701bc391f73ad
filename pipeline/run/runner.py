"""The stage runner: run stages in order, reuse finished ones, write ``report.md``
(:mod:`pipeline.run.report`).

The stages are the modules of :mod:`pipeline.run.stages`, each defining the names of
:class:`pipeline.stage_api.StageModule` (``NAME``, ``DEPENDS``, ``Config``, ``run``, ``check``,
``warm_up``, ``CONFIG_READS``, ``RECORDED_INPUT``, ``SIMULATES``).

:func:`run_pipeline` validates everything (stage modules, dependencies, the robot files, the
hidden robot) *before* creating any directory, then for every needed stage either reuses
``<run>/<stage>/`` (stored ``inputs.sha256`` equal to the new hash, :mod:`pipeline.run.inputs`) or
runs it (:mod:`pipeline.run.stage_run`) with a staging directory that is renamed to ``<stage>/``
only when complete.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from pipeline.core import artefacts
from pipeline.core.config import RunConfig, default_runs_dir, resolve_robot_dir
from pipeline.core.errors import ArtefactWriteError, ConfigError
from pipeline.core.interrupts import handle_termination
from pipeline.core.progress import Progress
from pipeline.core.run_names import check_run_robot
from pipeline.core.yaml12 import dump_yaml
from pipeline.robot.model import RobotModel
from pipeline.run import report as report_mod
from pipeline.run import second_pass, stage_io
from pipeline.run.inputs import config_reads, package_code_hash, run_key, stage_inputs_hashes, why_not_reuse
from pipeline.run.locking import RunLockedError, run_lock
from pipeline.run.stage_io import load_stage_output
from pipeline.run.stage_plan import Plan as _Plan
from pipeline.run.stage_plan import plan_stages, unavailable_stages
from pipeline.run.stage_run import make_real, run_one, write_error
from pipeline.run.stages import stage_names
from pipeline.run.warm_up import warmed_up
from pipeline.sim.truth import RealRobot
from pipeline.stage_api import StageOutput, declared

__all__ = [
    "RunResult", "run_pipeline", "prepare_run", "stage_inputs_hashes", "package_code_hash", "config_reads",
    "EXIT_BAD_INPUT", "EXIT_QUALITY_GATE", "EXIT_INTERRUPTED",
]

#: exit codes of ``python -m pipeline`` (docs/runner.md, "Exit codes")
EXIT_BAD_INPUT = 2          # a PipelineError: bad config/robot/data, a fault writing files, a locked run
EXIT_QUALITY_GATE = 3       # a stage failed its quality gate (result kept in <run>/<stage>.rejected/)
EXIT_INTERRUPTED = 130      # SIGINT / SIGTERM


@dataclass
class RunResult:
    run_dir: Path
    report: Path
    outputs: dict[str, StageOutput]       # every stage of this run, in order
    ran: list[str]                        # stages written by this call (run, or taken over from its first pass)
    reused: list[str]                     # stages loaded from disk


def _run_checks(plans: Sequence[_Plan], cfg: RunConfig, nominal: RobotModel) -> None:
    """The stages' optional ``check(config, robot)`` (bad data files ...), before any write."""
    for plan in plans:
        check = declared(plan.module, "check")
        if not callable(check):
            continue
        try:
            check(plan.config, nominal)
        except ConfigError as exc:  # name the file (or --set) the field's value came from
            if exc.file is not None:
                raise
            source = cfg.source_of(exc.field, None) if exc.field else cfg.origins.get(plan.name, cfg.source)
            raise ConfigError(source, exc.field, exc.problem) from None


@dataclass
class Prepared:
    """A validated run: what :func:`run_pipeline` would do (also ``python -m pipeline check``)."""

    cfg: RunConfig
    plans: list[_Plan]
    nominal: RobotModel
    real: RealRobot | None            # the hidden robot (None: every planned stage is recorded or reads files)
    run_dir: Path
    forced: set[str]
    reasons: dict[str, str | None]    # stage -> why it runs (None: reused)
    second_pass: str = ""             # whether the second calibration pass ran, and why (provenance.json)


def prepare_run(cfg: RunConfig, out_root: str | Path | None = None,
                force: bool | Sequence[str] = False) -> Prepared:
    """Validate everything a run needs (robot, stage modules, the hidden robot, every check()
    of a stage that would run, a run directory of another robot refused unless ``force`` is
    True) without writing anything."""
    robot_dir = resolve_robot_dir(cfg)         # user input first: the robot, then the stage modules
    nominal = RobotModel.load(robot_dir)
    plans = plan_stages(cfg, unavailable_stages(nominal))
    real = make_real(nominal, cfg) if any(p.provenance.simulated for p in plans) else None
    hashes = stage_inputs_hashes(cfg, plans, robot_dir)
    forced = set(hashes) if force is True else set(force or ())
    run_dir = (Path(out_root) if out_root is not None else default_runs_dir()) / cfg.name
    check_run_robot(run_dir, cfg.robot, force=force is True)     # never replace another robot's run
    reasons = {p.name: why_not_reuse(p, run_dir / p.name, forced, cfg, verify=True) for p in plans}
    _run_checks([p for p in plans if reasons[p.name] is not None], cfg, nominal)
    return Prepared(cfg, plans, nominal, real, run_dir, forced, reasons)


def run_pipeline(
    cfg: RunConfig,
    out_root: str | Path | None = None,
    force: bool | Sequence[str] = False,
    progress: Progress | None = None,
    log: Callable[[str], None] | None = None,
    warm_up: bool = False,
) -> RunResult:
    """Run the stages of ``cfg`` into ``<out_root>/<cfg.name>/`` (default ``data/runs``).

    ``force``: True re-runs every needed stage, a list re-runs those stages (reuse otherwise).
    ``log``: callable(str) for one-line progress messages (default: stderr).
    Raises :class:`PipelineError` (nothing written when it comes from validation),
    :class:`QualityGateError` (the result kept in ``<run>/<stage>.rejected/``) or
    KeyboardInterrupt (SIGINT/SIGTERM: the stage being run is discarded).
    ``warm_up``: build the compiled code of the stages that will run in the background meanwhile
    (:mod:`pipeline.run.warm_up`; ``python -m pipeline run`` does).
    """
    prog = progress if progress is not None else Progress()
    say = log if log is not None else prog.log
    with handle_termination():
        prep = prepare_run(cfg, out_root, force)
        tasks = [(p.name, functools.partial(fn, p.config, prep.nominal)) for p in prep.plans
                 if prep.reasons[p.name] is not None and callable(fn := declared(p.module, "warm_up"))]
        with warmed_up(tasks if warm_up else []):
            return _run_passes(prep, cfg, out_root, force, prog, say)


def _run_passes(prep: Prepared, cfg: RunConfig, out_root: str | Path | None, force: bool | Sequence[str],
                prog: Progress, say: Callable[[str], None]) -> RunResult:
    """The first calibration pass when the run needs one (:mod:`pipeline.run.second_pass`), then the run."""
    available = [n for n in stage_names() if n not in unavailable_stages(prep.nominal)]
    copied: list[str] = []
    arms = stage_io.combined_arms({p.name: p.provenance for p in prep.plans})
    if arms:
        say(f"warning: {arms}")
    first, why_not = second_pass.decision(cfg, [p.name for p in prep.plans], available)
    if first:
        prep, copied = _after_first_pass(prep, force, prog, say)
    elif why_not:
        say(f"calibration: {why_not}")
        prep = replace(prep, second_pass=why_not)
    result = _run_prepared(prep, out_root, prog, say)
    if copied:   # stages this run took over from the first pass: written in this call
        ran = [n for n in result.outputs if n in copied or n in result.ran]
        result = replace(result, ran=ran, reused=[n for n in result.reused if n not in ran])
    return result


def _after_first_pass(prep: Prepared, force: bool | Sequence[str], prog: Progress,
                      say: Callable[[str], None]) -> tuple[Prepared, list[str]]:
    """Run the first calibration pass (:mod:`pipeline.run.second_pass`) and prepare this run after it:
    with the identified inertias as gravity model, or reusing the first pass's stages. Also returns
    the stages this run takes over from the first pass (their folders are written in this call)."""
    cfg, run_dir = prep.cfg, prep.run_dir
    first_root = second_pass.first_pass_root(run_dir)
    say(f"calibration: first pass (calibration and identification) under {first_root / cfg.name}")
    first_prep = prepare_run(second_pass.first_pass_config(cfg), first_root, force)
    try:
        first = _run_prepared(first_prep, first_root, prog, say)
    except RunLockedError as exc:     # name the run directory the user gave, not its first pass
        raise RunLockedError(run_dir, None, exc.problem) from None
    second = second_pass.second_pass_config(cfg, first.outputs, run_dir)
    share = second_pass.gravity_share(first.outputs)
    share_text = "not predicted" if share is None else f"{share:.2f}"
    if second is None:
        say(f"calibration: gravity model's share of the predicted error {share_text} "
            f"< {second_pass.GRAVITY_SHARE_FOR_SECOND_PASS}: no second pass, the first pass's stages are reused")
        planned = [p.name for p in prep.plans]
        copied = second_pass.reuse_first_pass({n: o for n, o in first.outputs.items() if n in planned}, run_dir)
        # the first pass's stages ran (or were forced) already
        rest = planned if force is True else list(force or ())
        again = prepare_run(cfg, prep.run_dir.parent, [n for n in rest if n not in first.outputs])
        return replace(again, second_pass=f"no second calibration pass: the gravity model's share of the predicted "
                       f"error is {share_text} < {second_pass.GRAVITY_SHARE_FOR_SECOND_PASS}"), copied
    note = (f"second calibration pass with the inertias identified in the first pass "
            f"({first.outputs['identification'].path.parent}; gravity model's share of its predicted error "
            f"{share_text})")
    say(f"calibration: {note}")
    return replace(prepare_run(second, prep.run_dir.parent, force), second_pass=note), []


def _run_prepared(prep: Prepared, out_root: str | Path | None, prog: Progress,
                  say: Callable[[str], None]) -> RunResult:
    """Create the run directory and run (or reuse) the prepared stages under its lock."""
    run_dir = prep.run_dir
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError("--out" if out_root is not None else None, str(run_dir),
                          f"cannot create the run directory ({exc.strerror or exc})") from None
    with run_lock(run_dir) as lock:
        if lock is None:
            return _reuse_read_only(prep, say)
        return _run_locked(prep, prog, say)


def _reuse_read_only(prep: Prepared, say: Callable[[str], None]) -> RunResult:
    """A read-only run directory: fine when every stage can be reused (nothing is written)."""
    todo = [(n, r) for n, r in prep.reasons.items() if r is not None]
    if todo:
        name, reason = todo[0]
        raise ArtefactWriteError(prep.run_dir, None, f"the run directory is read-only and stage {name} "
                                 f"must run ({reason}); make it writable or use another --out")
    outputs = {p.name: load_stage_output(prep.run_dir / p.name) for p in prep.plans}
    say(f"{prep.run_dir} is read-only: every stage reused, nothing written")
    return RunResult(prep.run_dir, prep.run_dir / "report.md", outputs, [], list(outputs))


def _run_locked(prep: Prepared, prog: Progress, say: Callable[[str], None]) -> RunResult:
    cfg, run_dir = prep.cfg, prep.run_dir
    stage_io.clean_leftovers(run_dir)
    # decide again under the lock (another run may have finished a stage meanwhile)
    reasons = {p.name: why_not_reuse(p, run_dir / p.name, prep.forced, cfg, verify=True) for p in prep.plans}
    _run_checks([p for p in prep.plans if reasons[p.name] is not None and prep.reasons[p.name] is None],
                cfg, prep.nominal)
    # the stages this run consists of: the selected ones and the upstream ones they need (run
    # or reused), so that the config.yaml reproduces the run
    written = cfg.to_dict()
    written["stages"] = [p.name for p in prep.plans]
    text = dump_yaml(written)
    config_path = run_dir / "config.yaml"
    try:
        if not config_path.is_file() or config_path.read_text(encoding="utf-8") != text:
            artefacts.write_text(config_path, text)
    except OSError as exc:
        raise write_error(exc, config_path) from None
    outputs: dict[str, StageOutput] = {}
    ran: list[str] = []
    reused: list[str] = []
    handed_robot: dict[str, RobotModel] = {}       # stage -> robot it handed on
    current: str | None = None
    failure: tuple[str, str] | None = None  # (stage, one-line error) when a stage failed
    key = run_key(cfg)
    try:
        with prog:
            for plan in prep.plans:
                current = plan.name
                stage_dir = run_dir / plan.name
                reason = reasons[plan.name]
                if reason is None:
                    outputs[plan.name] = load_stage_output(stage_dir)
                    reused.append(plan.name)
                    say(f"{plan.name}: reused ({stage_dir}; {plan.provenance.sentence()})")
                else:
                    if reason != "not run yet":
                        say(f"{plan.name}: re-running because {reason}")
                    outputs[plan.name] = run_one(plan, cfg, run_dir, prep.nominal, outputs, handed_robot, key,
                                                 prog, say)
                    ran.append(plan.name)
                robot = outputs[plan.name].robot
                if robot is not None:
                    handed_robot[plan.name] = robot
            current = None
    except BaseException as exc:
        failure = (current or "", report_mod.one_line_error(exc))
        raise
    finally:
        try:
            stage_io.write_provenance(run_dir, {p.name: p.provenance for p in prep.plans}, prep.second_pass)
            report = report_mod.write_report(run_dir, cfg, [p.name for p in prep.plans],
                                             expected={p.name: p.inputs_sha256 for p in prep.plans},
                                             failure=failure)
        except OSError as exc:
            if failure is None:
                raise write_error(exc, run_dir / "report.md") from None
            report = run_dir / "report.md"     # keep the stage's own error, not this one
    say(f"report: {report}")
    return RunResult(run_dir, report, outputs, ran, reused)
