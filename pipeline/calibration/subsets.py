"""Parameter subsets of the calibration (``calibration.parameters``).

- ``auto`` (default): with a measurement file, the subset (and the residual map) chosen by
  cross-validation (:mod:`pipeline.calibration.model_selection`); in simulation ``all``;
- ``all``: every geometric error of the error model and the joint compliances
  (elastostatic model, :mod:`pipeline.calibration.error_model`);
- ``geometric``: the geometric errors only (the rigid-arm calibration of earlier versions);
- ``joint_offsets``: the joint zero offsets ``j{i}.dq``;
- ``joint_axes``: the zero offsets and the rotational errors of every joint placement (SE(3) error
  model: ``j{i}.rx..rz``; modified DH: ``j{i}.dalpha``, ``j{i}.dtheta`` and Hayati's ``j{i}.beta``),
  the directions of the joint axes about their stated origins, with the link lengths and offsets
  as the description states them. Between ``joint_offsets`` and ``geometric``: it describes an arm
  whose links are machined to the drawing while assembly tilts its axes; a small angle about a
  joint's origin moves the tool by the lever to it, so with few poses this model can fit the
  dominant errors without the link-length columns' variance (the model selection decides, by
  held-out data, whether the lengths must be freed);
- ``joint_offsets+compliance``: zero offsets and compliances ``j{i}.c``;
- a list of parameter names (``[j2.dq, j3.dq, j2.c]``).

The measurement set-up (``tracker.*`` pose, ``reflector.*`` offset, and for 6-D readings the marker
frame's rotation ``tool.rx..rz``) is always estimated. Among the
selected parameters the identifiability analysis keeps the identifiable base set.
"""

from __future__ import annotations

from pipeline.calibration.error_model import MDH_ROTATIONS, is_compliance
from pipeline.core.errors import ConfigError
from pipeline.robot.parameters import KINEMATIC_COMPONENTS

NAMED_SUBSETS = ("auto", "all", "geometric", "joint_axes", "joint_offsets", "joint_offsets+compliance")
#: the rotational components of a joint placement's error (SE(3) and modified-DH error models)
AXIS_COMPONENTS = KINEMATIC_COMPONENTS[3:] + MDH_ROTATIONS


def _setup(name: str) -> bool:
    """Tracker pose, reflector offset and the marker's rotation on the flange (tool rotations: only
    6-D readings see them; position readings leave them unidentifiable)."""
    return name.startswith(("tracker.", "reflector.", "tool.r"))


def _zero_offset(name: str) -> bool:
    return name.startswith("j") and name.endswith(".dq")


def _axis_direction(name: str) -> bool:
    """A rotational error of a joint placement (``j{i}.rx``, ``j{i}.dalpha``, ...)."""
    head, _, component = name.partition(".")
    return head[:1] == "j" and head[1:].isdigit() and component in AXIS_COMPONENTS


def wants_compliance(parameters: str | list[str]) -> bool:
    """Whether the subset needs the elastostatic error model."""
    if isinstance(parameters, str):
        return parameters in ("auto", "all", "joint_offsets+compliance")
    return any(is_compliance(p) for p in parameters)


def check_parameters(parameters: object, source: str = "config") -> None:
    """Robot-independent check of ``calibration.parameters`` (names are checked by :func:`select`)."""
    if isinstance(parameters, str):
        if parameters not in NAMED_SUBSETS:
            raise ConfigError(source, "calibration.parameters",
                              f"must be one of {NAMED_SUBSETS} or a list of parameter names, got {parameters!r}")
        return
    if not isinstance(parameters, list) or not parameters or not all(isinstance(p, str) for p in parameters):
        raise ConfigError(source, "calibration.parameters",
                          f"must be one of {NAMED_SUBSETS} or a non-empty list of parameter names, got {parameters!r}")


def select(parameters: str | list[str], names: list[str]) -> list[int]:
    """Column indices of ``names`` (the error model's parameters) in the subset."""
    if parameters in ("auto", "all"):   # auto: "all" until the model selection has chosen
        return list(range(len(names)))
    if parameters == "geometric":
        return [i for i, n in enumerate(names) if not is_compliance(n)]
    if parameters == "joint_offsets":
        return [i for i, n in enumerate(names) if _setup(n) or _zero_offset(n)]
    if parameters == "joint_axes":
        return [i for i, n in enumerate(names) if _setup(n) or _zero_offset(n) or _axis_direction(n)]
    if parameters == "joint_offsets+compliance":
        return [i for i, n in enumerate(names) if _setup(n) or _zero_offset(n) or is_compliance(n)]
    unknown = [p for p in parameters if p not in names]
    if unknown:
        raise ConfigError(None, "calibration.parameters",
                          f"unknown parameter(s) {', '.join(unknown)}; the error model has: {', '.join(names)}")
    chosen = set(parameters)
    return [i for i, n in enumerate(names) if _setup(n) or n in chosen]
