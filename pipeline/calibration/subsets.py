"""Parameter subsets of the calibration (``calibration.parameters``).

- ``auto`` (default): with a measurement file, the subset (and the residual map) chosen by
  cross-validation (:mod:`pipeline.calibration.model_selection`); in simulation ``all``;
- ``all``: every geometric error of the error model and the joint compliances
  (elastostatic model, :mod:`pipeline.calibration.error_model`);
- ``geometric``: the geometric errors only (the rigid-arm calibration of earlier versions);
- ``joint_offsets``: the joint zero offsets ``j{i}.dq``;
- ``joint_offsets+compliance``: zero offsets and compliances ``j{i}.c``;
- a list of parameter names (``[j2.dq, j3.dq, j2.c]``).

The measurement set-up (``tracker.*`` pose, ``reflector.*`` offset, and for 6-D readings the marker
frame's rotation ``tool.rx..rz``) is always estimated. Among the
selected parameters the identifiability analysis keeps the identifiable base set.
"""

from __future__ import annotations

from pipeline.calibration.error_model import is_compliance
from pipeline.core.errors import ConfigError

NAMED_SUBSETS = ("auto", "all", "geometric", "joint_offsets", "joint_offsets+compliance")


def _setup(name: str) -> bool:
    """Tracker pose, reflector offset and the marker's rotation on the flange (tool rotations: only
    6-D readings see them; position readings leave them unidentifiable)."""
    return name.startswith(("tracker.", "reflector.", "tool.r"))


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
        return [i for i, n in enumerate(names) if _setup(n) or (n.startswith("j") and n.endswith(".dq"))]
    if parameters == "joint_offsets+compliance":
        return [i for i, n in enumerate(names)
                if _setup(n) or (n.startswith("j") and n.endswith(".dq")) or is_compliance(n)]
    unknown = [p for p in parameters if p not in names]
    if unknown:
        raise ConfigError(None, "calibration.parameters",
                          f"unknown parameter(s) {', '.join(unknown)}; the error model has: {', '.join(names)}")
    chosen = set(parameters)
    return [i for i, n in enumerate(names) if _setup(n) or n in chosen]
