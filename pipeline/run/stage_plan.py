"""The stage plan of a run: the selected stages and their upstream stages, in registry order.

A stage module defines the names of :class:`pipeline.stage_api.StageModule` (the stages:
:mod:`pipeline.run.stages`); :func:`check_stage_module` checks them at run time. A stage the robot
cannot run (e.g. calibration without a tracker) is left out with its reason (:func:`unavailable_stages`).

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
from typing import Any

from pipeline.core import config as config_mod
from pipeline.core.config import RunConfig
from pipeline.core.errors import ConfigError, PipelineError
from pipeline.core.typed_config import file_input_fields
from pipeline.robot.iso_search import POSE_AXES
from pipeline.robot.model import RobotModel
from pipeline.run.stages import load_stage_module, stage_config, stage_names
from pipeline.stage_api import ROBOT_FILES, Provenance, StageModule, declared, own_provenance

#: most axes the control and trajectory stages plan for (6 for a pose, one redundant axis)
MAX_PLANNED_AXES = 7


@dataclass
class Plan:
    name: str
    module: StageModule
    config: Any                   # Any: the stage's own Config dataclass instance (one type per stage)
    depends: tuple[str, ...]
    closure: list[str]            # all upstream stages (transitive), in run order
    inputs_sha256: str = ""
    inputs: dict[str, Any] = field(default_factory=dict)   # what the inputs hash covers (manifest)
    provenance: Provenance = field(default_factory=lambda: Provenance(ROBOT_FILES, ""))


def check_stage_module(name: str, module: StageModule) -> None:
    """The names of :class:`~pipeline.stage_api.StageModule` as a stage module defines them: the
    required ones there, the optional ones of the right type, ``RECORDED_INPUT`` a ``FileInput``
    field of its ``Config`` (a renamed field is an error, not a silently simulated stage)."""
    where = str(getattr(module, "__file__", None) or f"stage {name}")
    for attr in ("NAME", "DEPENDS", "Config", "run"):
        if not hasattr(module, attr):
            raise PipelineError(where, attr, f"stage {name!r} does not define {attr}")
    if module.NAME != name:
        raise PipelineError(where, "NAME", f"is {module.NAME!r}, registered as {name!r}")
    reads = declared(module, "CONFIG_READS")
    if not isinstance(reads, (tuple, list)) or not all(isinstance(r, str) and r for r in reads):
        raise PipelineError(where, "CONFIG_READS", f"expected a tuple of dotted setting names, got {reads!r}")
    for attr in ("RECORDED_INPUT", "SIMULATES"):
        value = declared(module, attr)
        if not isinstance(value, str):
            raise PipelineError(where, attr, f"expected a string, got {value!r}")
    recorded = declared(module, "RECORDED_INPUT")
    if recorded and recorded not in file_input_fields(module.Config):
        raise PipelineError(where, "RECORDED_INPUT", f"{recorded!r} is not a field of {module.Config.__name__} "
                            "annotated Annotated[..., FileInput]")
    for attr in ("check", "warm_up"):
        value = declared(module, attr)
        if value is not None and not callable(value):
            raise PipelineError(where, attr, f"expected a function or None, got {value!r}")
    sections = config_mod.section_names()
    for dotted in reads:
        if dotted.split(".")[0] not in sections:
            raise PipelineError(where, "CONFIG_READS", f"{dotted!r} is not in a section of the run "
                                f"configuration (sections: {', '.join(sections)})")


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
    elif robot.nq > MAX_PLANNED_AXES:
        for stage, what in (("control", "the ISO 9283 path's joint reference"), ("trajectory", "the CP path and "
                                                                                  "the point-to-point move")):
            out[stage] = (f"robot {robot.name!r} has {robot.nq} axes: {what} is solved for at most "
                          f"{MAX_PLANNED_AXES} (one redundant axis, resolved by the IK seeds); run the stages "
                          "model, calibration, identification")
    return out


def stages_line(robot: RobotModel) -> str:
    """One line naming the stages ``robot`` can run and those it cannot (why), or "" when all can."""
    unavailable = unavailable_stages(robot)
    if not unavailable:
        return ""
    can = [n for n in stage_names() if n not in unavailable]
    reasons = "; ".join(dict.fromkeys(r.split(": ", 1)[-1].split("; run the stages")[0] for r in unavailable.values()))
    return (f"{robot.name}: {robot.nq} axes: stages {', '.join(can)} run; {', '.join(unavailable)} do not "
            f"({reasons})")


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
    order = stage_names()
    modules: dict[str, StageModule] = {}

    def module_of(name: str) -> StageModule:
        if name not in modules:
            modules[name] = load_stage_module(name)
            check_stage_module(name, modules[name])
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
