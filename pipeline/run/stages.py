"""The stages of a run, in run order, and the other sections of its configuration: the run layer
owns this list (the core only layers and checks the sections it is given,
:func:`pipeline.core.config.register_sections`).

Every stage module satisfies :class:`pipeline.stage_api.StageModule` (mypy checks it here). A stage
written outside the package is added to :data:`STAGES` by name and module (or module path, imported
on first use); tests put fake stages there.
"""

from __future__ import annotations

import dataclasses
import importlib

from pipeline.calibration import stage as calibration
from pipeline.control import stage as control
from pipeline.core import config as config_mod
from pipeline.core.config import (  # noqa: F401 - the loaders, with this module's stages registered
    CONFIGS_DIR,
    ConfigError,
    RunConfig,
    SectionRegistry,
    StageUnavailableError,
    load_config,
    quick_config,
)
from pipeline.core.typed_config import DataclassInstance, build_dataclass
from pipeline.identification import stage as identification
from pipeline.model import stage as model
from pipeline.sim.truth import TruthConfig
from pipeline.stage_api import Provenance, StageModule, own_provenance
from pipeline.trajectory import stage as trajectory

#: stage name -> its module (or a module path imported on first use), in run order
STAGES: dict[str, StageModule | str] = {
    "model": model,
    "calibration": calibration,
    "identification": identification,
    "control": control,
    "trajectory": trajectory,
}

#: sections that are not stages: name -> their dataclass
OTHER_SECTIONS: dict[str, type] = {"truth": TruthConfig}


def stage_names() -> list[str]:
    """The stage names in run order."""
    return list(STAGES)


def load_stage_module(name: str) -> StageModule:
    """The module of stage ``name`` (see :data:`STAGES`).

    Raises :class:`StageUnavailableError` when a module path does not exist (not written yet) and
    :class:`ConfigError` for an unknown stage name. Other import errors propagate (they are bugs).
    """
    if name not in STAGES:
        raise ConfigError(None, "stages", f"unknown stage {name!r} (known: {', '.join(STAGES)})")
    target = STAGES[name]
    if not isinstance(target, str):
        return target
    try:
        module: StageModule = importlib.import_module(target)   # a module: its names checked by stage_plan
    except ModuleNotFoundError as exc:
        missing = exc.name or ""
        if missing and (target == missing or target.startswith(missing + ".")):
            raise StageUnavailableError(
                target.replace(".", "/") + ".py", name,
                f"stage {name!r} is not available: module {target} does not exist (not written yet?)",
            ) from None
        raise
    return module


def _config_class(section: str) -> type | None:
    """The dataclass of a section, or None when its stage module does not exist yet."""
    if section in OTHER_SECTIONS:
        return OTHER_SECTIONS[section]
    try:
        module = load_stage_module(section)
    except StageUnavailableError:
        return None
    cls = getattr(module, "Config", None)
    if not isinstance(cls, type) or not dataclasses.is_dataclass(cls):
        raise StageUnavailableError(str(getattr(module, "__file__", section)), "Config",
                                    f"stage {section!r} has no Config dataclass")
    return cls


def _missing(section: str) -> str:
    target = STAGES.get(section)
    return target if isinstance(target, str) else section


def registry() -> SectionRegistry:
    """The sections of a run configuration (registered with :mod:`pipeline.core.config`)."""
    return SectionRegistry(tuple(STAGES), tuple(OTHER_SECTIONS), _config_class, _missing)


config_mod.register_sections(registry)


def stage_config(cfg: RunConfig, name: str, module: StageModule) -> DataclassInstance:
    """The stage's section as its ``Config`` dataclass (built from defaults when the run has none, or
    from a plain mapping a test put there, and stored back)."""
    section = cfg.sections.get(name)
    if section is None or isinstance(section, dict):
        section = build_dataclass(module.Config, section or {}, name, cfg.source)
        cfg.sections[name] = section
    return section


def stage_provenance(cfg: RunConfig, name: str) -> Provenance:
    """The stage's own provenance from the run configuration (planned or not)."""
    module = load_stage_module(name)
    return own_provenance(module, stage_config(cfg, name, module))
