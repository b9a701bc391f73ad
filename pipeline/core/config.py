"""Run configuration: built-in defaults, a YAML file, ``--set key=value`` overrides, validation.

A run configuration has a few top-level keys (``name``, ``seed``, ``robot``, ``profile``,
``stages``) and one section per stage (plus ``truth`` for the hidden robot). Each section is
validated against a dataclass:

* stage ``<stage>``: the ``Config`` dataclass of the stage module (e.g.
  ``pipeline.calibration.stage.Config``);
* ``truth``: ``pipeline.sim.truth.TruthConfig``.

Which sections there are is not known here: the run layer, which owns the stages, registers them
(:func:`register_sections`, :mod:`pipeline.run.stages`); this module only layers and checks them.

Merging order (later wins): dataclass defaults < the robot's ``run_defaults`` (a section of its
``robot.yaml``: where the test path sits and which moves fit that arm) < YAML file < ``--set``
overrides.
Every problem raises :class:`pipeline.core.errors.ConfigError` naming the file (or ``--set``) and the
dotted field, e.g. ``configs/my.yaml: calibration.n_configurations: expected int, got 'abc'``.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar, overload

import pipeline
from pipeline.core.config_layers import (
    field_path,
    leaf_paths,
    lookup_origin,
    merge_layers,
    parse_set,
    read_yaml,
    related,
    to_plain,
)
from pipeline.core.errors import ConfigError, PipelineError
from pipeline.core.run_names import default_run_name
from pipeline.core.typed_config import DataclassInstance, build_dataclass, describe, unknown_key, with_source
from pipeline.core.yaml12 import YAMLError, dump_yaml, load_yaml

SectionT = TypeVar("SectionT")

TOP_LEVEL_KEYS = ("name", "seed", "robot", "profile", "stages")
PROFILES = ("full", "quick", "corpus")

#: the folder that holds the ``pipeline`` package (the repository in a source checkout)
REPO_ROOT = Path(pipeline.__file__).resolve().parent.parent
CONFIGS_DIR = REPO_ROOT / "configs"


def default_runs_dir() -> Path:
    """``<repo>/data/runs`` in a source checkout, else ``./data/runs``."""
    if (REPO_ROOT / "pyproject.toml").exists():
        return REPO_ROOT / "data" / "runs"
    return Path.cwd() / "data" / "runs"


class StageUnavailableError(PipelineError):
    """A stage module (or a section's config class) does not exist yet."""


# --------------------------------------------------------------------------------------------
# Sections: which there are is registered from above (the run layer owns the stages)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SectionRegistry:
    """The sections a run configuration holds: the stages in run order, then the sections that are
    not stages (the hidden robot's ``truth``); ``config_class(name)`` is a section's dataclass
    (None: its module does not exist yet, then ``missing(name)`` names that module)."""

    stages: tuple[str, ...]
    others: tuple[str, ...]
    config_class: Callable[[str], type | None]
    missing: Callable[[str], str]


_registry: Callable[[], SectionRegistry] | None = None


def register_sections(provider: Callable[[], SectionRegistry]) -> None:
    """Install the function that returns the run's sections (:mod:`pipeline.run.stages` does at
    import; it is called at every use, so a test may swap the stages it returns)."""
    global _registry
    _registry = provider


def sections_registry() -> SectionRegistry:
    """The registered sections (:func:`register_sections`)."""
    if _registry is None:
        raise StageUnavailableError(None, "stages", "no stage is registered: the run layer registers the "
                                    "stages (import pipeline.run, or load the configuration with "
                                    "pipeline.run.stages.load_config)")
    return _registry()


def stage_names() -> list[str]:
    """Registered stage names in run order."""
    return list(sections_registry().stages)


def section_names() -> list[str]:
    """All section names: the other sections (``truth``) then the stages."""
    registry = sections_registry()
    return [*registry.others, *registry.stages]


# --------------------------------------------------------------------------------------------
# RunConfig
# --------------------------------------------------------------------------------------------
@dataclass
class RunConfig:
    """A validated run configuration.

    ``sections`` maps each section name (``truth``, ``model``, ``calibration``, ...) to its
    validated dataclass instance (a section whose module does not exist yet is left out: settings
    for it are an error). Typed access: ``cfg.section("calibration", CalibrationConfig)``; sections
    are also reachable as attributes: ``cfg.calibration.n_configurations``.
    """

    name: str = "rx130l"                # without a name: default_run_name(robot, profile)
    seed: int = 0
    robot: str = "rx130l"
    profile: str = "full"
    stages: list[str] = field(default_factory=stage_names)
    sections: dict[str, DataclassInstance] = field(default_factory=dict)
    source: str = "<defaults>"          # where it came from, for messages
    base_dir: Path = field(default_factory=Path.cwd)   # relative robot paths resolve here first
    origins: dict[str, str] = field(default_factory=dict)  # top-level key or section -> file or "--set" (last)
    #: dotted field (``"model.pose_deg"``, ``"control.iso.edge_m"``) -> the layer that last set it
    #: (file, ``"--set"`` or ``"<robot.yaml> (run_defaults)"``); not part of :meth:`to_dict`
    field_origins: dict[str, str] = field(default_factory=dict, repr=False)
    #: hand on results that failed a quality gate (``--accept-poor``); recorded in the report
    accept_poor: bool = False

    def __getattr__(self, item: str) -> Any:
        # only called when normal lookup fails: expose sections as attributes
        sections = self.__dict__.get("sections")
        if sections is not None and item in sections:
            return sections[item]
        raise AttributeError(item)

    def source_of(self, dotted: str | None, default: str | None = None) -> str:
        """Where the value of field ``dotted`` (e.g. ``"model.pose_deg[2]"``) came from: the
        layer that last set it (or a part of it), else ``default``, else the section's last
        layer (:attr:`origins`), else :attr:`source`."""
        found = lookup_origin(self.field_origins, dotted) if dotted else None
        if found is not None:
            return found
        if default is not None:
            return default
        head = field_path(dotted)[0] if dotted else ""
        return self.origins.get(head, self.source)

    @overload
    def section(self, name: str) -> DataclassInstance: ...

    @overload
    def section(self, name: str, kind: type[SectionT]) -> SectionT: ...

    def section(self, name: str, kind: type[SectionT] | None = None) -> DataclassInstance | SectionT:
        """The config of section ``name`` (dataclass instance); with ``kind``, checked to be one."""
        if name not in self.sections:
            raise ConfigError(self.source, name, "no such section")
        value = self.sections[name]
        if kind is not None and not isinstance(value, kind):
            raise ConfigError(self.source, name, f"expected a {kind.__name__}, got {type(value).__name__}")
        return value

    def to_dict(self) -> dict[str, Any]:
        """Plain (YAML/JSON-able) dict that :func:`load_config` reads back to an equal config."""
        out: dict[str, Any] = {
            "name": self.name,
            "seed": self.seed,
            "robot": self.robot,
            "profile": self.profile,
            "stages": list(self.stages),
        }
        for key, value in self.sections.items():
            out[key] = to_plain(value)
        return out

    def to_yaml(self) -> str:
        return dump_yaml(self.to_dict())


# --------------------------------------------------------------------------------------------
# Parsing and validation
# --------------------------------------------------------------------------------------------
def _parse_stages(value: object, source: str) -> list[str]:
    if isinstance(value, str):
        items = [s.strip() for s in value.split(",") if s.strip()]
    elif isinstance(value, (list, tuple)) and all(isinstance(s, str) for s in value):
        items = list(value)
    else:
        raise ConfigError(source, "stages", f"expected a list of stage names, got {describe(value)}")
    known = stage_names()
    for s in items:
        if s not in known:
            raise ConfigError(source, "stages", f"unknown stage {s!r} (known: {', '.join(known)})")
    if not items:
        raise ConfigError(source, "stages", "no stage selected")
    # keep registry order, drop duplicates
    return [s for s in known if s in items]


def load_config(
    path: str | Path | None = None,
    overrides: Sequence[str] = (),
    stages: str | Sequence[str] | None = None,
    values: Mapping[str, Any] | None = None,
) -> RunConfig:
    """Build and validate a :class:`RunConfig`.

    ``path``: YAML file (None: built-in defaults only). ``overrides``: ``"dotted.key=value"``
    strings (``--set``), values parsed as YAML. ``stages``: ``"a,b"`` or a list, replaces the
    ``stages`` key (``--stages``). ``values``: ``{"dotted.key": value}`` applied after the
    overrides (Python API, e.g. notebooks). Raises :class:`ConfigError` naming the file and the field.
    """
    layers: list[tuple[str, dict[str, Any]]] = []
    base_dir = Path.cwd()
    source = "<defaults>"
    if path is not None:
        path = Path(path)
        layers.append((str(path), read_yaml(path)))
        base_dir = path.resolve().parent
        source = str(path)
    set_layer: dict[str, Any] = {}
    pairs = [parse_set(item) for item in overrides]
    pairs += [(str(k).split("."), v) for k, v in (values or {}).items()]
    for keys, value in pairs:
        node = set_layer
        for k in keys[:-1]:
            child = node.get(k)
            if not isinstance(child, dict):
                child = {}
                node[k] = child
            node = child
        node[keys[-1]] = value
    if set_layer:
        layers.append(("--set", set_layer))
    if stages is not None:
        layers.append(("--stages", {"stages": stages}))

    known = set(TOP_LEVEL_KEYS) | set(section_names())
    top: dict[str, tuple[str, Any]] = {}            # key -> (source, value)
    raw_sections: dict[str, list[tuple[str, Any]]] = {s: [] for s in section_names()}
    for src, layer in layers:
        for key, value in layer.items():
            if key not in known:
                raise ConfigError(src, str(key), unknown_key(key, sorted(known)))
            if key in TOP_LEVEL_KEYS:
                top[key] = (src, value)
            else:
                if value is None:
                    value = {}
                if not isinstance(value, Mapping):
                    raise ConfigError(src, key, f"expected a mapping of settings, got {describe(value)}")
                raw_sections[key].append((src, value))

    cfg = RunConfig(source=source, base_dir=base_dir)
    for key, (src, value) in top.items():
        cfg.origins[key] = src
        if key == "name":
            if not isinstance(value, (str, int)) or isinstance(value, bool) or not str(value).strip():
                raise ConfigError(src, "name", f"expected a non-empty string, got {describe(value)}")
            value = str(value)
            if "/" in value or "\\" in value or value.startswith("."):
                raise ConfigError(src, "name", f"must be a plain directory name, got {value!r}")
            cfg.name = value
        elif key == "seed":
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ConfigError(src, "seed", f"expected a non-negative int, got {describe(value)}")
            cfg.seed = value
        elif key == "robot":
            if not isinstance(value, (str, Path)) or not str(value).strip():
                raise ConfigError(src, "robot", f"expected a robot name or folder, got {describe(value)}")
            cfg.robot = str(value)
        elif key == "profile":
            if value not in PROFILES:
                raise ConfigError(src, "profile",
                                  f"expected one of {', '.join(PROFILES)}, got {describe(value)}")
            cfg.profile = value
        elif key == "stages":
            cfg.stages = _parse_stages(value, src)
    if "name" not in top:        # named after the robot and profile: runs of two robots never collide
        cfg.name = default_run_name(cfg.robot, cfg.profile)

    robot_layer = robot_run_defaults(cfg)
    if robot_layer is not None:
        src, defaults = robot_layer
        for key, value in defaults.items():
            if key not in raw_sections:
                raise ConfigError(src, f"run_defaults.{key}",
                                  f"not a section of the run configuration (sections: {', '.join(section_names())})")
            if not isinstance(value, Mapping):
                raise ConfigError(src, f"run_defaults.{key}", f"expected a mapping of settings, got {describe(value)}")
            raw_sections[key].insert(0, (src, value))

    registry = sections_registry()
    for section, items in raw_sections.items():
        cls = registry.config_class(section)
        if cls is None:
            for src, value in items:
                if value:
                    raise ConfigError(
                        src, section,
                        f"cannot check these settings: {registry.missing(section)} does not exist yet",
                    )
            continue
        # validate the merged section after each layer; a problem of the final section is blamed
        # on the layer that introduced it (a bad value in a file that a later --set repairs is
        # no error), see _blame
        for src, value in items:
            for path in leaf_paths(value, (section,)):
                key = ".".join(path)
                cfg.field_origins.pop(key, None)       # keep the dict ordered by last setting
                cfg.field_origins[key] = src
        merged: dict[str, Any] = {}
        errors: list[ConfigError | None] = []
        instance: DataclassInstance | None = None
        for src, value in items:
            merged = merge_layers(merged, value)
            try:
                instance = build_dataclass(cls, merged, section, src)
                _semantic_check(instance, src)
            except ConfigError as exc:
                errors.append(exc)
            else:
                errors.append(None)
        if items:
            cfg.origins[section] = items[-1][0]
        else:
            instance = build_dataclass(cls, {}, section, source)
            _semantic_check(instance, source)
        if errors and errors[-1] is not None:
            raise _blame(errors, items, section)
        assert instance is not None       # every layer's error is raised above
        cfg.sections[section] = instance
    return cfg


def resolve_robot_dir(cfg: RunConfig) -> Path:
    """The robot folder named by ``cfg.robot``: a path (absolute, relative to the config
    file, or to the working directory) or a folder name under ``robots/``."""
    value = cfg.robot
    p = Path(value).expanduser()
    candidates = [p] if p.is_absolute() else [cfg.base_dir / p, Path.cwd() / p, REPO_ROOT / "robots" / p]
    for c in candidates:
        if c.is_dir() or (c.suffix == ".urdf" and c.is_file()):   # a URDF alone: facts assumed (urdf_import)
            return c.resolve()
    source = cfg.origins.get("robot", cfg.source)
    robots = REPO_ROOT / "robots"
    known = sorted(d.name for d in robots.iterdir() if d.is_dir()) if robots.is_dir() else []
    hint = f" (built-in robots: {', '.join(known)})" if known else ""
    raise ConfigError(source, "robot", f"no robot folder or URDF file {value!r}{hint}")


def robot_run_defaults(cfg: RunConfig) -> tuple[str, Mapping[str, Any]] | None:
    """(source, sections) of the ``run_defaults`` mapping in the robot's ``robot.yaml``, or None
    (no such section, or no robot folder yet: the runner reports a missing robot)."""
    try:
        robot_dir = resolve_robot_dir(cfg)
        robot_yaml = (robot_dir.parent if robot_dir.is_file() else robot_dir) / "robot.yaml"
    except ConfigError:
        return None
    if not robot_yaml.is_file():
        return None
    try:
        data = load_yaml(robot_yaml.read_text(encoding="utf-8"))
    except (OSError, YAMLError):
        return None                      # the robot loader reports a broken robot.yaml
    if not isinstance(data, dict) or data.get("run_defaults") is None:
        return None
    defaults = data["run_defaults"]
    src = f"{robot_yaml} (run_defaults)"
    if not isinstance(defaults, Mapping):
        raise ConfigError(src, "run_defaults", f"expected a mapping of sections, got {describe(defaults)}")
    return src, defaults


def _blame(errors: list[ConfigError | None], items: list[tuple[str, Any]], section: str) -> ConfigError:
    """The final error of a section (``errors[-1]``, one entry per layer in ``items``) naming
    the layer that introduced the bad value.

    The culprit is the first layer from which on the section stays invalid; when a layer at or
    after it set the field the error names (or a part of it), the last such layer is blamed
    instead (two bad values from different layers: each error names its own layer).
    """
    final = errors[-1]
    assert final is not None
    sources = {src for src, _ in items}
    if final.file not in sources:          # the check named a file of its own (a data file ...)
        return final
    k = len(errors) - 1
    while k > 0 and errors[k - 1] is not None:
        k -= 1
    blame = items[k][0]
    target = field_path(final.field or "")
    if len(target) >= 2 and target[0] == section:
        for src, value in items[k:]:
            if any(related(path, target) for path in leaf_paths(value, (section,))):
                blame = src
    return ConfigError(blame, final.field, final.problem)


def _semantic_check(instance: object, source: str) -> None:
    """Call the section's own ``validate(source)`` (or ``validate()``) when it has one.

    Stage owners may add ``def validate(self, source: str) -> None`` to their Config that
    raises ConfigError(source, "<stage>.<field>", problem) for values of the right type but
    out of range (e.g. a negative count).
    """
    validate = getattr(instance, "validate", None)
    if not callable(validate):
        return
    try:
        params = inspect.signature(validate).parameters
    except (TypeError, ValueError):
        params = {}
    try:
        if params:
            validate(source)
        else:
            validate()
    except ConfigError as exc:
        raise with_source(exc, source) from None


def quick_config(**overrides: object) -> RunConfig:
    """The quick profile (``configs/quick.yaml``) with optional dotted overrides.

    ``quick_config(**{"calibration.n_configurations": 20})``.
    """
    return load_config(CONFIGS_DIR / "quick.yaml", values=overrides)
