"""The stage plan of a run: the selected stages and their upstream stages, in registry order.

A stage module exposes ``NAME``, ``DEPENDS``, ``Config``, ``run`` and optionally ``check`` and
``CONFIG_READS`` (:mod:`pipeline.run.runner`). A stage the robot cannot run (e.g. calibration
without a tracker) is left out with its reason (:func:`unavailable_stages`).

Provenance (:class:`~pipeline.stage_api.Provenance`): a stage whose ``RECORDED_INPUT`` field names
a file is *recorded*, one that declares ``SIMULATES`` is *simulated* otherwise, the others read the
robot files only. A recorded stage never depends on a simulated one: such an upstream stage is
neither pulled into the plan nor handed on to it (it starts from the nominal model, or from a
recorded upstream stage's robot), so a run with recorded inputs simulates only what its selected
stages need.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

from pipeline.core import config as config_mod
from pipeline.core.config import RunConfig
from pipeline.core.errors import ConfigError, PipelineError
from pipeline.robot.iso_search import POSE_AXES
from pipeline.robot.model import RobotModel
from pipeline.stage_api import ROBOT_FILES, Provenance, own_provenance, stage_config


@dataclass
class Plan:
    name: str
    module: ModuleType
    config: Any                   # Any: the stage's own Config dataclass instance (one type per stage)
    depends: tuple[str, ...]
    closure: list[str]            # all upstream stages (transitive), in run order
    inputs_sha256: str = ""
    inputs: dict[str, Any] = field(default_factory=dict)   # what the inputs hash covers (manifest)
    provenance: Provenance = field(default_factory=lambda: Provenance(ROBOT_FILES, ""))


def _check_stage_module(name: str, module: ModuleType) -> None:
    where = str(getattr(module, "__file__", None) or f"stage {name}")
    for attr in ("NAME", "DEPENDS", "Config", "run"):
        if not hasattr(module, attr):
            raise PipelineError(where, attr, f"stage {name!r} does not define {attr}")
    if module.NAME != name:
        raise PipelineError(where, "NAME", f"is {module.NAME!r}, registered as {name!r}")
    reads = getattr(module, "CONFIG_READS", ())
    if not isinstance(reads, (tuple, list)) or not all(isinstance(r, str) and r for r in reads):
        raise PipelineError(where, "CONFIG_READS", f"expected a tuple of dotted setting names, got {reads!r}")
    for attr in ("RECORDED_INPUT", "SIMULATES"):
        value = getattr(module, attr, "")
        if not isinstance(value, str):
            raise PipelineError(where, attr, f"expected a string, got {value!r}")
    for dotted in reads:
        if dotted.split(".")[0] not in config_mod.section_names():
            raise PipelineError(where, "CONFIG_READS", f"{dotted!r} is not in a section of the run "
                                f"configuration (sections: {', '.join(config_mod.section_names())})")


def unavailable_stages(robot: RobotModel) -> dict[str, str]:
    """Stages the robot cannot run, with the reason: no tracker in robot.yaml -> no calibration
    (the later stages use the nominal kinematics, and the model stage's report says so); fewer
    than ``POSE_AXES`` axes -> no control and no trajectory (the ISO 9283 path and the CP path hold
    a constant tool orientation, which such an arm cannot follow in general)."""
    out: dict[str, str] = {}
    if not robot.has_tracker:
        out["calibration"] = (f"robot {robot.name!r} has no tracker section in robot.yaml: no calibration "
                              "(the later stages use the nominal kinematics)")
    if robot.nq < POSE_AXES:
        for stage, path in (("control", "the ISO 9283 path"), ("trajectory", "the CP path")):
            out[stage] = (f"robot {robot.name!r} has {robot.nq} axes: {path} holds a 6-D tool pose, which needs "
                          f"at least {POSE_AXES}; run the stages model, calibration, identification")
    return out


def _left_out_note(name: str, left_out: Sequence[str], depends: Sequence[str]) -> str:
    if not left_out:
        return ""
    start = ("nominal kinematics" if "calibration" not in depends else "the recorded calibration's robot")
    return (f"{name} is recorded: the simulated {', '.join(left_out)} is not used (starts from {start})")


def plan_stages(cfg: RunConfig, unavailable: Mapping[str, str] | None = None) -> list[Plan]:
    """Needed stages (selected + their transitive dependencies) in registry order.

    ``unavailable``: stage -> reason (:func:`unavailable_stages`); such a stage is left out of
    the plan and of its dependants' upstream stages; asking for it explicitly (``--stages``, the
    config's ``stages``) is an error naming the reason."""
    unavailable = dict(unavailable or {})
    if "stages" in cfg.origins:
        for name in cfg.stages:
            if name in unavailable:
                raise ConfigError(cfg.origins["stages"], "stages", f"{name}: {unavailable[name]}")
    order = config_mod.stage_names()
    modules: dict[str, ModuleType] = {}

    def module_of(name: str) -> ModuleType:
        if name not in modules:
            modules[name] = config_mod.load_stage_module(name)
            _check_stage_module(name, modules[name])
        return modules[name]

    own: dict[str, Provenance] = {}

    def provenance_of(name: str) -> Provenance:
        if name not in own:
            module = module_of(name)
            own[name] = own_provenance(module, stage_config(cfg, name, module))
        return own[name]

    def used(name: str, dep: str) -> bool:
        """A recorded stage never uses a simulated one."""
        return dep not in unavailable and not (provenance_of(name).recorded and provenance_of(dep).simulated)

    needed: set[str] = set()
    stack = list(cfg.stages)
    while stack:
        name = stack.pop()
        if name in needed or name in unavailable:
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
            if used(name, dep):
                stack.append(dep)

    plans: dict[str, Plan] = {}
    for name in order:
        if name not in needed:
            continue
        module = module_of(name)
        section = stage_config(cfg, name, module)
        closure: set[str] = set()
        depends = tuple(d for d in module.DEPENDS if used(name, d))
        for dep in depends:
            closure.add(dep)
            closure.update(plans[dep].closure)
        upstream = [s for s in order if s in closure]
        left_out = tuple(d for d in module.DEPENDS if d not in unavailable and d not in depends)
        mine = provenance_of(name)
        provenance = Provenance(mine.kind, mine.source, tuple(upstream), left_out,
                                _left_out_note(name, left_out, depends))
        plans[name] = Plan(name, module, section, depends, upstream, provenance=provenance)
    return list(plans.values())
