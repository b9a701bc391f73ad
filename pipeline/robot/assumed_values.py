"""Keys of robot.yaml that ``robot init`` writes: assumed values (tracked until edited), locked joints.

``python -m pipeline robot init`` writes, beside each value it assumed, a ``# ASSUMED: rule``
comment and, in the top-level ``assumed`` mapping, the value's dotted path with its rule and a
digest of the value as written::

    assumed:
      actuation.gear_ratio: {rule: "gear ratio 100 on axes 1-3, 50 on the wrist", sha256: 3f2a...}

On loading, an entry whose value still has that digest is an assumption in force (listed with
the robot's assumptions in every run); an edited value no longer matches and is not listed. The
digest is of the value with every number rounded to 12 significant digits (``100`` and ``100.0``
are the same value), so re-saving a file does not turn an assumption into a fact.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.core.errors import RobotFileError
from pipeline.core.typed_config import dotted_get

_MISSING = object()

#: robot.yaml ``actuation.torque_side``: motor (torques from motor currents) or link (joint torque sensors)
TORQUE_SIDES = ("link", "motor")
#: drive values ``robot init`` assumes (a URDF has none): while still assumed they are left out of
#: the nominal torque prediction, which then is the bare URDF's (identification fits them)
DRIVE_VALUES = ("rotor_inertia_kgm2", "viscous_Nms_rad", "coulomb_Nm")


def predicted_drive_values(actuation: Any, assumed: Mapping[str, object]) -> dict[str, np.ndarray]:  # Any: spec
    """Rotor inertia, viscous and Coulomb friction of the nominal torque prediction, by name.

    A value is 0 (left out, as in the bare URDF) when robot.yaml still holds it as ``robot init``
    assumed it (``assumed``: the entries in force), or when torques are measured on the link side
    (``actuation.torque_side: link``: a joint torque sensor after the gear sees neither the rotor's
    inertia nor the drive's friction). An assumed value can make the prediction worse than the bare
    URDF; left out, the nominal model is the bare URDF and the data identify the rest."""
    link = getattr(actuation, "torque_side", "motor") == "link"
    return {name: (np.zeros_like(np.asarray(getattr(actuation, name), float))
                   if link or f"actuation.{name}" in assumed else np.asarray(getattr(actuation, name), float).copy())
            for name in DRIVE_VALUES}


def _normal(value: object) -> object:
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, int | float):
        return float(f"{float(value):.12g}")
    if isinstance(value, dict):
        return {str(k): _normal(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_normal(v) for v in value]
    return str(value)


def value_digest(value: object) -> str:
    """Digest of a YAML value (numbers rounded to 12 significant digits)."""
    text = json.dumps(_normal(value), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def lookup(data: dict[str, Any], dotted: str) -> Any:  # Any: whatever robot.yaml holds there
    """The value at ``a.b.c`` in nested mappings, or ``_MISSING``."""
    return dotted_get(data, dotted, _MISSING)


def assumed_entry(data: dict[str, Any], dotted: str, rule: str) -> dict[str, str]:
    """The ``assumed`` entry of the value at ``dotted`` in ``data`` (as it is written)."""
    return {"rule": rule, "sha256": value_digest(lookup(data, dotted))}


def assumed_in_force(path: Path, data: dict[str, Any]) -> dict[str, dict[str, str]]:
    """The entries of ``data['assumed']`` whose value is unchanged (checked: one line per problem)."""
    raw = data.get("assumed")
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise RobotFileError(path, "assumed", f"expected a mapping of value path -> {{rule, sha256}}, got {raw!r}")
    kept = {}
    for dotted, entry in raw.items():
        if not (isinstance(entry, dict) and isinstance(entry.get("rule"), str)
                and isinstance(entry.get("sha256"), str)):
            raise RobotFileError(path, f"assumed.{dotted}", "expected {rule: text, sha256: digest}")
        value = lookup(data, str(dotted))
        if value is not _MISSING and value_digest(value) == entry["sha256"]:
            kept[str(dotted)] = {"rule": entry["rule"], "sha256": entry["sha256"]}
    return kept


def assumed_sentences(assumed: dict[str, dict[str, str]]) -> list[str]:
    """One line per assumption still in force: ``path: rule (robot.yaml, unedited)``."""
    return [f"{dotted}: {entry['rule']} (ASSUMED in robot.yaml, not edited)" for dotted, entry in assumed.items()]


def locked_joints(path: Path, data: dict[str, Any]) -> dict[str, float]:
    """robot.yaml's ``locked_joints``: joint name -> position (rad or m) held off the arm chain."""
    raw = data.get("locked_joints") or {}
    if not isinstance(raw, dict) or not all(isinstance(v, int | float) and not isinstance(v, bool)
                                            for v in raw.values()):
        raise RobotFileError(path, "locked_joints", f"expected a mapping of joint name -> position, got {raw!r}")
    return {str(k): float(v) for k, v in raw.items()}
