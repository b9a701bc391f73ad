"""A stage's inputs hash and whether its folder can be reused.

A stage's inputs hash covers its own section (each ``FileInput`` field by the content of the file
it names, :func:`content_keyed`), the seed, the robot name and the ``truth`` section, every file of
the robot folder, the values of its ``CONFIG_READS`` (:func:`config_reads`), the hashes of its
upstream stages, the package version and the source code: every ``.py`` file of the whole
``pipeline`` package (any code change re-runs every stage: stages import each other's helpers,
correctness beats reuse) plus the stage module's own folder when it lives outside the package.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pipeline
from pipeline.core import artefacts
from pipeline.core import config as config_mod
from pipeline.core.config import RunConfig
from pipeline.core.typed_config import file_input_fields
from pipeline.run import stage_io
from pipeline.run.stage_io import changed_inputs, read_manifest, run_key_sha256, stage_problem
from pipeline.run.stage_plan import Plan
from pipeline.stage_api import StageModule, declared
from pipeline.summaries import StageSummary

__all__ = ["run_key", "package_code_hash", "code_hash", "config_reads", "content_keyed", "stage_inputs_hashes",
           "why_not_reuse", "accepted_poor"]

#: root of the source code every stage's inputs hash covers (tests point it at a copy)
PACKAGE_ROOT = Path(pipeline.__file__).resolve().parent


def run_key(cfg: RunConfig) -> str:
    """Hash of the run-level settings shared by every stage (:func:`pipeline.run.stage_io.run_key_sha256`)."""
    return run_key_sha256(cfg.seed, Path(cfg.robot).name or cfg.robot, cfg.sections.get("truth", {}))


def package_code_hash() -> str:
    """sha256 of every ``.py`` file of the ``pipeline`` package (``pipeline/robot`` included)."""
    return artefacts.hash_tree(PACKAGE_ROOT, suffixes=(".py",))


def code_hash(module: StageModule, package_sha256: str | None = None) -> str:
    """Hash of the source code a stage stands on: every .py file of the ``pipeline`` package
    (``package_sha256``, computed when None; a stage imports other subpackages' helpers, e.g.
    identification validates on the control stage's ISO path) plus the .py files of the stage
    module's own folder when that lies outside the package (a stage registered from elsewhere)."""
    code = package_code_hash() if package_sha256 is None else package_sha256
    path = getattr(module, "__file__", None)
    if path:
        folder = Path(path).resolve().parent
        if not folder.is_relative_to(PACKAGE_ROOT.resolve()):
            code += artefacts.hash_tree(folder, suffixes=(".py",))
    return code


def config_reads(cfg: RunConfig, module: StageModule) -> dict[str, Any]:
    """Plain values of the settings of other sections a stage declares it reads
    (``CONFIG_READS = ("control.iso", ...)``): dotted path -> value (None when the section is not
    validated (a plain dict) or has no such field: the stage then uses built-in defaults, which
    the code hash covers)."""
    out: dict[str, Any] = {}
    for dotted in tuple(declared(module, "CONFIG_READS") or ()):
        head, *rest = str(dotted).split(".")
        value: object = cfg.sections.get(head)
        for part in rest:
            if isinstance(value, Mapping):
                value = value.get(part)
            else:
                value = getattr(value, part, None)
        out[str(dotted)] = config_mod.to_plain(value)
    return out


def content_keyed(plain: dict[str, Any], config_class: type) -> dict[str, Any]:
    """The stage's plain config with each file or folder its ``FileInput`` fields name replaced by
    the sha256 of its content: the inputs hash never holds a path (a moved or copied run is reused)."""
    out = dict(plain)
    for name in file_input_fields(config_class):
        value = out.get(name)
        if isinstance(value, str) and value:
            path = Path(value)
            if path.is_dir():
                out[name] = "sha256:" + artefacts.hash_tree(path)
            elif path.is_file():
                out[name] = "sha256:" + hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def stage_inputs_hashes(cfg: RunConfig, plans: Sequence[Plan], robot_dir: Path) -> dict[str, str]:
    """Inputs hash of every planned stage (also stored in ``plan.inputs_sha256``)."""
    robot_sha = artefacts.hash_tree(robot_dir)
    code_sha = package_code_hash()
    run_key = {
        "seed": cfg.seed,
        "robot": robot_dir.name,
        "truth": config_mod.to_plain(cfg.sections.get("truth", {})),
    }
    by_name: dict[str, Plan] = {}
    for plan in plans:
        reads = config_reads(cfg, plan.module)
        key = {**run_key, "config_reads": reads} if reads else run_key
        config = content_keyed(config_mod.to_plain(plan.config), plan.module.Config)
        upstream = {d: by_name[d].inputs_sha256 for d in plan.closure}
        code = code_hash(plan.module, code_sha)
        plan.inputs_sha256 = stage_io.inputs_hash(plan.name, config, key, robot_sha, upstream,
                                                   pipeline.__version__, code)
        plan.inputs = {"config": config, "run": key, "robot_files": robot_sha, "upstream": upstream,
                       "version": pipeline.__version__, "code": code}
        by_name[plan.name] = plan
    return {name: plan.inputs_sha256 for name, plan in by_name.items()}


def why_not_reuse(plan: Plan, stage_dir: Path, forced: set[str], cfg: RunConfig, verify: bool) -> str | None:
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
    if not cfg.accept_poor and accepted_poor(stage_dir):
        return "it was accepted with --accept-poor and this run requires its quality gates"
    return None


def accepted_poor(stage_dir: Path) -> bool:
    """Whether the stage in ``stage_dir`` was handed on with ``--accept-poor``."""
    try:
        summary = artefacts.read_json(stage_dir / stage_io.SUMMARY)
    except (OSError, ValueError):
        return False
    return isinstance(summary, dict) and bool(StageSummary.read(summary).accepted_poor)
