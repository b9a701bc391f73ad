"""The stage runner: run stages in order, reuse finished ones, write ``report.md``
(:mod:`pipeline.report`).

Each stage is a module (registry :data:`pipeline.config.STAGES`) exposing::

    NAME = "calibration"
    DEPENDS = ("model",)           # upstream stages whose results it reads
    Config = CalibrationConfig     # dataclass with defaults
    def run(ctx: StageContext) -> StageResult
    def check(config, robot) -> None   # optional: raise PipelineError early (bad data file...)
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

import hashlib
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import yaml

import pipeline
from pipeline import artefacts
from pipeline import config as config_mod
from pipeline import report as report_mod
from pipeline.artefacts import StageOutput, load_stage_output
from pipeline.config import REPO_ROOT, RunConfig, resolve_robot_dir
from pipeline.errors import ConfigError, PipelineError
from pipeline.progress import Progress

__all__ = [
    "StageContext", "StageResult", "StageOutput", "RunResult", "run_pipeline", "load_run",
    "load_stage_output", "default_runs_dir", "resolve_robot_dir", "stage_rng", "stable_stage_hash",
    "stage_inputs_hashes", "package_code_hash", "config_reads",
]


# --------------------------------------------------------------------------------------------
# The contract (docs/ARCHITECTURE.md, "Stages and the runner")
# --------------------------------------------------------------------------------------------
@dataclass
class StageContext:
    run: RunConfig                        # name, seed, robot, profile (+ all sections)
    config: Any                           # this stage's Config instance
    robot: Any                            # RobotModel: best model so far (a private copy)
    real: Any                             # RealRobot: sensors of the hidden robot (None if unavailable)
    upstream: dict[str, StageOutput]      # loaded results of the earlier stages it depends on
    out_dir: Path                         # staging directory (write extra files here)
    rng: np.random.Generator              # seeded from (run seed, stage name)
    progress: Progress                    # ctx.progress.track(iterable, "description")


@dataclass
class StageResult:
    summary: dict                                           # -> summary.json (headline figures)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)   # -> results.npz
    data: dict = field(default_factory=dict)                # -> results.json
    figures: dict[str, Any] = field(default_factory=dict)   # matplotlib Figures -> <name>.png
    robot: Any = None                                       # RobotModel handed on -> robot/
    report_md: str = ""                                     # extra markdown for report.md


@dataclass
class RunResult:
    run_dir: Path
    report: Path
    outputs: dict[str, StageOutput]       # every stage of this run, in order
    ran: list[str]                        # stages whose run() was called
    reused: list[str]                     # stages loaded from disk


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------
def default_runs_dir() -> Path:
    """``<repo>/data/runs`` in a source checkout, else ``./data/runs``."""
    if (REPO_ROOT / "pyproject.toml").exists():
        return REPO_ROOT / "data" / "runs"
    return Path.cwd() / "data" / "runs"


def stable_stage_hash(name: str) -> int:
    """32-bit integer from sha256(name): stable across processes (unlike ``hash()``)."""
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "little")


def stage_rng(seed: int, stage: str) -> np.random.Generator:
    """``np.random.default_rng([seed, stable_stage_hash(stage)])``."""
    return np.random.default_rng([seed, stable_stage_hash(stage)])


def _load_robot(robot_dir: Path) -> Any:
    from pipeline.robot.model import RobotModel

    return RobotModel.load(robot_dir)


def _make_real(nominal: Any, cfg: RunConfig) -> Any:
    try:
        from pipeline.robot.truth import RealRobot
    except ModuleNotFoundError as exc:
        if exc.name and "pipeline.robot.truth".startswith(exc.name):
            print("warning: pipeline.robot.truth does not exist yet; ctx.real is None", file=sys.stderr)
            return None
        raise
    truth_cfg = cfg.sections.get("truth")
    if isinstance(truth_cfg, dict) or truth_cfg is None:
        from pipeline.robot.truth import TruthConfig

        truth_cfg = TruthConfig()
    return RealRobot.create(nominal, cfg.seed, truth_cfg)


#: root of the source code every stage's inputs hash covers (tests point it at a copy)
_PACKAGE_ROOT = Path(__file__).resolve().parent


def package_code_hash() -> str:
    """sha256 of every ``.py`` file of the ``pipeline`` package (``pipeline/robot`` included)."""
    return artefacts.hash_tree(_PACKAGE_ROOT, suffixes=(".py",))


def _code_hash(module: Any, package_sha256: str | None = None) -> str:
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


def config_reads(cfg: RunConfig, module: Any) -> dict[str, Any]:
    """Plain values of the settings of other sections a stage declares it reads
    (``CONFIG_READS = ("control.iso", ...)``): dotted path -> value (None when the section is not
    validated (a plain dict) or has no such field: the stage then uses built-in defaults, which
    the code hash covers)."""
    out: dict[str, Any] = {}
    for dotted in tuple(getattr(module, "CONFIG_READS", ()) or ()):
        head, *rest = str(dotted).split(".")
        value: Any = cfg.sections.get(head)
        for part in rest:
            if isinstance(value, Mapping):
                value = value.get(part)
            else:
                value = getattr(value, part, None)
        out[str(dotted)] = config_mod.to_plain(value)
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
        plan.inputs_sha256 = artefacts.inputs_hash(
            plan.name, config_mod.to_plain(plan.config), key, robot_sha,
            {d: by_name[d].inputs_sha256 for d in plan.closure}, pipeline.__version__,
            _code_hash(plan.module, code_sha),
        )
        by_name[plan.name] = plan
    return {name: plan.inputs_sha256 for name, plan in by_name.items()}


def _copy_robot(robot: Any) -> Any:
    copy = getattr(robot, "copy", None)
    return copy() if callable(copy) else robot


@dataclass
class _Plan:
    name: str
    module: Any
    config: Any
    depends: tuple[str, ...]
    closure: list[str]            # all upstream stages (transitive), in run order
    inputs_sha256: str = ""


def _check_stage_module(name: str, module: Any) -> None:
    where = str(getattr(module, "__file__", None) or f"stage {name}")
    for attr in ("NAME", "DEPENDS", "Config", "run"):
        if not hasattr(module, attr):
            raise PipelineError(where, attr, f"stage {name!r} does not define {attr}")
    if module.NAME != name:
        raise PipelineError(where, "NAME", f"is {module.NAME!r}, registered as {name!r}")
    reads = getattr(module, "CONFIG_READS", ())
    if not isinstance(reads, (tuple, list)) or not all(isinstance(r, str) and r for r in reads):
        raise PipelineError(where, "CONFIG_READS", f"expected a tuple of dotted setting names, got {reads!r}")
    for dotted in reads:
        if dotted.split(".")[0] not in config_mod.section_names():
            raise PipelineError(where, "CONFIG_READS", f"{dotted!r} is not in a section of the run "
                                f"configuration (sections: {', '.join(config_mod.section_names())})")


def plan_stages(cfg: RunConfig) -> list[_Plan]:
    """Needed stages (selected + their transitive dependencies) in registry order."""
    order = config_mod.stage_names()
    modules: dict[str, Any] = {}

    def module_of(name: str) -> Any:
        if name not in modules:
            modules[name] = config_mod.load_stage_module(name)
            _check_stage_module(name, modules[name])
        return modules[name]

    needed: set[str] = set()
    stack = list(cfg.stages)
    while stack:
        name = stack.pop()
        if name in needed:
            continue
        if name not in order:
            raise ConfigError(cfg.origins.get("stages", cfg.source), "stages", f"unknown stage {name!r}")
        needed.add(name)
        module = module_of(name)
        where = str(getattr(module, "__file__", None) or name)
        for dep in tuple(module.DEPENDS):
            if dep not in order:
                raise PipelineError(where, "DEPENDS", f"unknown stage {dep!r}")
            if order.index(dep) >= order.index(name):
                raise PipelineError(where, "DEPENDS",
                                    f"{dep!r} does not run before {name!r}")
            stack.append(dep)

    plans: dict[str, _Plan] = {}
    for name in order:
        if name not in needed:
            continue
        module = module_of(name)
        section = cfg.sections.get(name)
        if section is None or isinstance(section, dict):
            section = config_mod.build_dataclass(module.Config, section or {}, name, cfg.source)
            cfg.sections[name] = section
        closure: set[str] = set()
        for dep in module.DEPENDS:
            closure.add(dep)
            closure.update(plans[dep].closure)
        plans[name] = _Plan(name, module, section, tuple(module.DEPENDS), [s for s in order if s in closure])
    return list(plans.values())


def _check_result(name: str, result: Any) -> StageResult:
    where = f"stage {name}"
    if not isinstance(result, StageResult):
        raise TypeError(f"{where}: run() returned {type(result).__name__}, expected StageResult")
    if not isinstance(result.summary, dict):
        raise TypeError(f"{where}: StageResult.summary must be a dict")
    for key in result.figures:
        if not str(key).replace("_", "").replace("-", "").isalnum():
            raise ValueError(f"{where}: figure name {key!r} must be a plain file stem")
    return result


def write_stage_result(stage_dir: Path, name: str, result: StageResult, inputs_sha256: str,
                       duration_s: float) -> None:
    """Write a StageResult into a (staging) directory; ``inputs.sha256`` last."""
    artefacts.write_json(stage_dir / artefacts.SUMMARY, result.summary)
    artefacts.write_npz(stage_dir / artefacts.RESULTS_NPZ, result.arrays)
    artefacts.write_json(stage_dir / artefacts.RESULTS_JSON, result.data)
    figures = []
    for key, fig in result.figures.items():
        artefacts.save_figure(stage_dir / f"{key}.png", fig)
        figures.append(f"{key}.png")
    if result.report_md:
        artefacts.write_text(stage_dir / artefacts.REPORT_MD, result.report_md.rstrip() + "\n")
    if result.robot is not None:
        result.robot.save(stage_dir / artefacts.ROBOT_DIR)
    artefacts.write_json(stage_dir / artefacts.MANIFEST, {
        "stage": name,
        "inputs_sha256": inputs_sha256,
        "figures": figures,
        "has_robot": result.robot is not None,
        "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "duration_s": round(duration_s, 3),
        "package_version": pipeline.__version__,
    })
    artefacts.write_text(stage_dir / artefacts.INPUTS_HASH, inputs_sha256 + "\n")


# --------------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------------
def run_pipeline(
    cfg: RunConfig,
    out_root: str | Path | None = None,
    force: bool | Sequence[str] = False,
    progress: Progress | None = None,
    log: Any = None,
) -> RunResult:
    """Run the stages of ``cfg`` into ``<out_root>/<cfg.name>/`` (default ``data/runs``).

    ``force``: True re-runs every needed stage, a list re-runs those stages (reuse otherwise).
    ``log``: callable(str) for one-line progress messages (default: stderr).
    Raises :class:`PipelineError` (nothing written when it comes from validation).
    """
    prog = progress if progress is not None else Progress()
    say = log if log is not None else prog.log
    # ---- validate everything before touching the disk --------------------------------------
    robot_dir = resolve_robot_dir(cfg)         # user input first: the robot, then the stage modules
    nominal = _load_robot(robot_dir)
    plans = plan_stages(cfg)
    real = _make_real(nominal, cfg)
    hashes = stage_inputs_hashes(cfg, plans, robot_dir)
    forced = set(hashes) if force is True else set(force or ())
    run_dir = Path(out_root) if out_root is not None else default_runs_dir()
    run_dir = run_dir / cfg.name
    for plan in plans:               # optional early checks (e.g. measurement files) of stages to run
        check = getattr(plan.module, "check", None)
        will_run = plan.name in forced or artefacts.read_inputs_hash(run_dir / plan.name) != plan.inputs_sha256
        if callable(check) and will_run:
            try:
                check(plan.config, nominal)
            except ConfigError as exc:  # name the file (or --set) the field's value came from
                if exc.file is not None:
                    raise
                source = cfg.source_of(exc.field, None) if exc.field else cfg.origins.get(plan.name, cfg.source)
                raise ConfigError(source, exc.field, exc.problem) from None

    # ---- run --------------------------------------------------------------------------------
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError("--out" if out_root is not None else None, str(run_dir),
                          f"cannot create the run directory ({exc.strerror or exc})") from None
    artefacts.clean_leftovers(run_dir)
    # the stages this run consists of: the selected ones and the upstream ones they need (run
    # or reused), so that the config.yaml reproduces the run
    written = cfg.to_dict()
    written["stages"] = [p.name for p in plans]
    artefacts.write_text(run_dir / "config.yaml", yaml.safe_dump(written, sort_keys=False))
    outputs: dict[str, StageOutput] = {}
    ran: list[str] = []
    reused: list[str] = []
    handed_robot: dict[str, Any] = {}       # stage -> robot it handed on
    current: str | None = None
    failure: tuple[str, str] | None = None  # (stage, one-line error) when a stage failed
    try:
        with prog:
            for plan in plans:
                current = plan.name
                stage_dir = run_dir / plan.name
                if plan.name not in forced and artefacts.read_inputs_hash(stage_dir) == plan.inputs_sha256:
                    outputs[plan.name] = load_stage_output(stage_dir)
                    reused.append(plan.name)
                    say(f"{plan.name}: reused ({stage_dir})")
                else:
                    outputs[plan.name] = _run_one(plan, cfg, nominal, real, outputs, handed_robot,
                                                  run_dir, prog, say)
                    ran.append(plan.name)
                if outputs[plan.name].robot is not None:
                    handed_robot[plan.name] = outputs[plan.name].robot
            current = None
    except BaseException as exc:
        failure = (current or "", report_mod.one_line_error(exc))
        raise
    finally:
        report = report_mod.write_report(run_dir, cfg, [p.name for p in plans],
                              expected={p.name: p.inputs_sha256 for p in plans}, failure=failure)
    say(f"report: {report}")
    return RunResult(run_dir, report, outputs, ran, reused)


def _run_one(plan: _Plan, cfg: RunConfig, nominal: Any, real: Any, outputs: dict[str, StageOutput],
             handed_robot: dict[str, Any], run_dir: Path, prog: Progress, say: Any) -> StageOutput:
    robot = nominal
    for up in plan.closure:                   # latest robot handed on upstream
        if up in handed_robot:
            robot = handed_robot[up]
    staging = artefacts.new_stage_dir(run_dir, plan.name)
    ctx = StageContext(
        run=cfg,
        config=plan.config,
        robot=_copy_robot(robot),
        real=real,
        upstream={u: outputs[u] for u in plan.closure},
        out_dir=staging,
        rng=stage_rng(cfg.seed, plan.name),
        progress=prog,
    )
    say(f"{plan.name}: running")
    t0 = time.perf_counter()
    try:
        result = _check_result(plan.name, plan.module.run(ctx))
        duration = time.perf_counter() - t0
        write_stage_result(staging, plan.name, result, plan.inputs_sha256, duration)
        final = artefacts.commit_stage_dir(staging, run_dir / plan.name)
    except BaseException:
        artefacts.discard_stage_dir(staging)
        raise
    say(f"{plan.name}: done in {duration:.1f} s")
    out = load_stage_output(final, robot=result.robot)
    return out


def load_run(run_dir: str | Path) -> dict[str, StageOutput]:
    """Every finished stage of a run directory, in run order (unknown stage dirs last)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise PipelineError(run_dir, None, "run directory not found")
    names = [s for s in config_mod.stage_names() if (run_dir / s / artefacts.INPUTS_HASH).exists()]
    names += sorted(p.name for p in run_dir.iterdir() if p.is_dir() and not p.name.startswith(".")
                    and p.name not in names and (p / artefacts.INPUTS_HASH).exists())
    return {n: load_stage_output(run_dir / n) for n in names}
