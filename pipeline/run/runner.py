"""The stage runner: run stages in order, reuse finished ones, write ``report.md``
(:mod:`pipeline.run.report`).

Each stage is a module (registry :data:`pipeline.core.config.STAGES`) exposing::

    NAME = "calibration"
    DEPENDS = ("model",)           # upstream stages whose results it reads
    Config = CalibrationConfig     # dataclass with defaults
    def run(ctx: StageContext) -> StageResult
    def check(config, robot) -> None   # optional: raise PipelineError early (bad data file...)
    def warm_up(config, robot) -> None # optional: compiled code built in the background (pipeline.run.warm_up)
    CONFIG_READS = ("control.iso",)    # optional: settings of other sections run() reads

:func:`run_pipeline` validates everything (stage modules, dependencies, the robot files, the
hidden robot) *before* creating any directory, then for every needed stage either reuses
``<run>/<stage>/`` (stored ``inputs.sha256`` equal to the new hash) or calls ``run(ctx)`` with
a staging directory that is renamed to ``<stage>/`` only when complete.

A stage's inputs hash covers its own section, the seed, the robot name and the ``truth``
section, every file of the robot folder, the values of its ``CONFIG_READS``, the hashes of its
upstream stages, the package version and the source code: every ``.py`` file of the whole
``pipeline`` package (any code change re-runs every stage: stages import each other's helpers,
correctness beats reuse) plus the stage module's own folder when it lives outside the package.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from types import ModuleType
from typing import Any

import yaml

import pipeline
from pipeline.core import artefacts
from pipeline.core import config as config_mod
from pipeline.core.config import RunConfig, default_runs_dir, resolve_robot_dir
from pipeline.core.errors import ArtefactWriteError, ConfigError, QualityGateError
from pipeline.core.interrupts import caused_by_interrupt, handle_termination, interrupted
from pipeline.core.progress import Progress
from pipeline.core.run_names import check_run_robot
from pipeline.robot.model import RobotModel
from pipeline.run import report as report_mod
from pipeline.run import second_pass, stage_io
from pipeline.run.locking import RunLockedError, run_lock
from pipeline.run.stage_io import (
    REJECTED_SUFFIX,
    changed_inputs,
    load_stage_output,
    read_manifest,
    run_key_sha256,
    stage_problem,
    write_rejected,
    write_stage_result,
)
from pipeline.run.stage_plan import Plan as _Plan
from pipeline.run.stage_plan import plan_stages, unavailable_stages
from pipeline.run.warm_up import warmed_up
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.stage_api import StageContext, StageOutput, StageResult, stage_rng

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


def _make_real(nominal: RobotModel, cfg: RunConfig) -> RealRobot:
    truth_cfg = cfg.sections.get("truth")
    if not isinstance(truth_cfg, TruthConfig):
        truth_cfg = TruthConfig()
    return RealRobot.create(nominal, cfg.seed, truth_cfg)


def run_key(cfg: RunConfig) -> str:
    """Hash of the run-level settings shared by every stage (:func:`pipeline.run.stage_io.run_key_sha256`)."""
    return run_key_sha256(cfg.seed, Path(cfg.robot).name or cfg.robot, cfg.sections.get("truth", {}))


#: root of the source code every stage's inputs hash covers (tests point it at a copy)
_PACKAGE_ROOT = Path(pipeline.__file__).resolve().parent


def package_code_hash() -> str:
    """sha256 of every ``.py`` file of the ``pipeline`` package (``pipeline/robot`` included)."""
    return artefacts.hash_tree(_PACKAGE_ROOT, suffixes=(".py",))


def _code_hash(module: ModuleType, package_sha256: str | None = None) -> str:
    """Hash of the source code a stage stands on: every .py file of the ``pipeline`` package
    (``package_sha256``, computed when None; a stage imports other subpackages' helpers, e.g.
    identification validates on the control stage's ISO path) plus the .py files of the stage
    module's own folder when that lies outside the package (a stage registered from elsewhere)."""
    code = package_code_hash() if package_sha256 is None else package_sha256
    path = getattr(module, "__file__", None)
    if path:
        folder = Path(path).resolve().parent
        if not folder.is_relative_to(_PACKAGE_ROOT.resolve()):
            code += artefacts.hash_tree(folder, suffixes=(".py",))
    return code


def config_reads(cfg: RunConfig, module: ModuleType) -> dict[str, Any]:
    """Plain values of the settings of other sections a stage declares it reads
    (``CONFIG_READS = ("control.iso", ...)``): dotted path -> value (None when the section is not
    validated (a plain dict) or has no such field: the stage then uses built-in defaults, which
    the code hash covers)."""
    out: dict[str, Any] = {}
    for dotted in tuple(getattr(module, "CONFIG_READS", ()) or ()):
        head, *rest = str(dotted).split(".")
        value: object = cfg.sections.get(head)
        for part in rest:
            if isinstance(value, Mapping):
                value = value.get(part)
            else:
                value = getattr(value, part, None)
        out[str(dotted)] = config_mod.to_plain(value)
    return out


def content_keyed(plain: dict[str, Any], module: ModuleType) -> dict[str, Any]:
    """The stage's plain config with each file or folder its ``FILE_INPUTS`` fields name replaced by
    the sha256 of its content: the inputs hash never holds a path (a moved or copied run is reused)."""
    out = dict(plain)
    for name in tuple(getattr(module, "FILE_INPUTS", ()) or ()):
        value = out.get(name)
        if isinstance(value, str) and value:
            path = Path(value)
            if path.is_dir():
                out[name] = "sha256:" + artefacts.hash_tree(path)
            elif path.is_file():
                out[name] = "sha256:" + hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def stage_inputs_hashes(cfg: RunConfig, plans: Sequence[_Plan], robot_dir: Path) -> dict[str, str]:
    """Inputs hash of every planned stage (also stored in ``plan.inputs_sha256``)."""
    robot_sha = artefacts.hash_tree(robot_dir)
    code_sha = package_code_hash()
    run_key = {
        "seed": cfg.seed,
        "robot": robot_dir.name,
        "truth": config_mod.to_plain(cfg.sections.get("truth", {})),
    }
    by_name: dict[str, _Plan] = {}
    for plan in plans:
        reads = config_reads(cfg, plan.module)
        key = {**run_key, "config_reads": reads} if reads else run_key
        config = content_keyed(config_mod.to_plain(plan.config), plan.module)
        upstream = {d: by_name[d].inputs_sha256 for d in plan.closure}
        code = _code_hash(plan.module, code_sha)
        plan.inputs_sha256 = stage_io.inputs_hash(plan.name, config, key, robot_sha, upstream,
                                                   pipeline.__version__, code)
        plan.inputs = {"config": config, "run": key, "robot_files": robot_sha, "upstream": upstream,
                       "version": pipeline.__version__, "code": code}
        by_name[plan.name] = plan
    return {name: plan.inputs_sha256 for name, plan in by_name.items()}


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


# --------------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------------
def _why_not_reuse(plan: _Plan, stage_dir: Path, forced: set[str], cfg: RunConfig, verify: bool) -> str | None:
    """Why stage ``plan`` must run (a short reason), or None when ``stage_dir`` can be reused."""
    if plan.name in forced:
        return "--force"
    stored = stage_io.read_inputs_hash(stage_dir)
    if stored is None:
        return "not run yet"
    if stored != plan.inputs_sha256:
        return "inputs changed" + changed_inputs(read_manifest(stage_dir).get("inputs"), plan.inputs, plan.name)
    if not verify:
        return None
    problem = stage_problem(stage_dir)
    if problem is not None:
        return f"its files are damaged: {problem}"
    if not cfg.accept_poor and _accepted_poor(stage_dir):
        return "it was accepted with --accept-poor and this run requires its quality gates"
    return None


def _accepted_poor(stage_dir: Path) -> bool:
    try:
        return bool(artefacts.read_json(stage_dir / stage_io.SUMMARY).get("accepted_poor"))
    except (OSError, ValueError, AttributeError):
        return False


def _run_checks(plans: Sequence[_Plan], cfg: RunConfig, nominal: RobotModel) -> None:
    """The stages' optional ``check(config, robot)`` (bad data files ...), before any write."""
    for plan in plans:
        check = getattr(plan.module, "check", None)
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
    real = _make_real(nominal, cfg) if any(p.provenance.simulated for p in plans) else None
    hashes = stage_inputs_hashes(cfg, plans, robot_dir)
    forced = set(hashes) if force is True else set(force or ())
    run_dir = (Path(out_root) if out_root is not None else default_runs_dir()) / cfg.name
    check_run_robot(run_dir, cfg.robot, force=force is True)     # never replace another robot's run
    reasons = {p.name: _why_not_reuse(p, run_dir / p.name, forced, cfg, verify=True) for p in plans}
    _run_checks([p for p in plans if reasons[p.name] is not None], cfg, nominal)
    return Prepared(cfg, plans, nominal, real, run_dir, forced, reasons)


def _write_error(exc: OSError, path: Path | str) -> ArtefactWriteError:
    return ArtefactWriteError(getattr(exc, "filename", None) or path, None,
                              f"cannot write ({exc.strerror or exc}); earlier results are intact")


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
                 if prep.reasons[p.name] is not None and callable(fn := getattr(p.module, "warm_up", None))]
        with warmed_up(tasks if warm_up else []):
            return _run_passes(prep, cfg, out_root, force, prog, say)


def _run_passes(prep: Prepared, cfg: RunConfig, out_root: str | Path | None, force: bool | Sequence[str],
                prog: Progress, say: Callable[[str], None]) -> RunResult:
    """The first calibration pass when the run needs one (:mod:`pipeline.run.second_pass`), then the run."""
    available = [n for n in config_mod.stage_names() if n not in unavailable_stages(prep.nominal)]
    copied: list[str] = []
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
    reasons = {p.name: _why_not_reuse(p, run_dir / p.name, prep.forced, cfg, verify=True) for p in prep.plans}
    _run_checks([p for p in prep.plans if reasons[p.name] is not None and prep.reasons[p.name] is None],
                cfg, prep.nominal)
    # the stages this run consists of: the selected ones and the upstream ones they need (run
    # or reused), so that the config.yaml reproduces the run
    written = cfg.to_dict()
    written["stages"] = [p.name for p in prep.plans]
    text = yaml.safe_dump(written, sort_keys=False)
    config_path = run_dir / "config.yaml"
    try:
        if not config_path.is_file() or config_path.read_text(encoding="utf-8") != text:
            artefacts.write_text(config_path, text)
    except OSError as exc:
        raise _write_error(exc, config_path) from None
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
                    outputs[plan.name] = _run_one(plan, prep, outputs, handed_robot, key, prog, say)
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
                raise _write_error(exc, run_dir / "report.md") from None
            report = run_dir / "report.md"     # keep the stage's own error, not this one
    say(f"report: {report}")
    return RunResult(run_dir, report, outputs, ran, reused)


def _run_one(plan: _Plan, prep: Prepared, outputs: dict[str, StageOutput], handed_robot: dict[str, RobotModel],
             key: str, prog: Progress, say: Callable[[str], None]) -> StageOutput:
    cfg, run_dir = prep.cfg, prep.run_dir
    robot = prep.nominal
    for up in plan.closure:                   # latest robot handed on upstream
        if up in handed_robot:
            robot = handed_robot[up]
    try:
        staging = stage_io.new_stage_dir(run_dir, plan.name)
    except OSError as exc:
        raise _write_error(exc, run_dir) from None
    # a fresh hidden robot per stage: its sensors draw noise from generators seeded by the run, so a
    # stage measures the same whether the earlier stages ran in this process or were reused
    # a recorded stage gets no hidden robot: it simulates nothing
    real = None if plan.provenance.recorded else _make_real(prep.nominal, cfg)
    ctx = StageContext(run=cfg, config=plan.config, robot=_copy_robot(robot), real=real,
                       upstream={u: outputs[u] for u in plan.closure}, out_dir=staging,
                       rng=stage_rng(cfg.seed, plan.name), progress=prog, provenance=plan.provenance)
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
            raise _write_error(exc, staging) from None
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
