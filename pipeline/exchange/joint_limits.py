"""MoveIt-style ``joint_limits.yaml`` and the URDF handed on with the joint types of its source.

``joint_limits.yaml`` (the layout of MoveIt's setup assistant, ``joint_limits`` per joint)::

    joint_limits:
      <joint>:
        has_position_limits: true
        min_position: <rad>
        max_position: <rad>
        has_velocity_limits: true
        max_velocity: <rad/s>
        has_acceleration_limits: true
        max_acceleration: <rad/s²>
        has_effort_limits: true
        max_effort: <N·m>

The values are the limits the plans were verified against (for a continuous joint: the one-turn
position limits the stages used, the URDF keeps it continuous). The URDF: the model's placements,
inertials and limits written into its source URDF (:func:`pipeline.robot.urdf_export.export_urdf`),
each arm joint's viscous and Coulomb friction in ``<dynamics damping friction>``, with every joint that
the source URDF declares ``continuous`` continuous again (no position limits).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.core.artefacts import write_text
from pipeline.core.errors import DataFileError
from pipeline.core.yaml12 import YAMLError, load_yaml, yaml_key, yaml_problem
from pipeline.robot.model import RobotModel
from pipeline.robot.urdf_export import export_urdf
from pipeline.robot.urdf_import import absolute_mesh_paths


@dataclass(frozen=True)
class JointLimitTable:
    """Per-joint limits in the order of ``joint_names``: rad, rad/s, rad/s², N·m."""

    joint_names: tuple[str, ...]
    lower_rad: np.ndarray
    upper_rad: np.ndarray
    velocity_rad_s: np.ndarray
    acceleration_rad_s2: np.ndarray
    effort_Nm: np.ndarray

    @classmethod
    def of_model(cls, robot: RobotModel) -> JointLimitTable:
        """The limits a model's stages verify plans against."""
        lim = robot.limits
        return cls(tuple(robot.model.names[1:]), lim.lower_rad, lim.upper_rad, lim.velocity_rad_s,
                   lim.acceleration_rad_s2, lim.effort_Nm)


def joint_limits_yaml(table: JointLimitTable, note: str = "") -> str:
    """The text of a MoveIt ``joint_limits.yaml`` for ``table`` (17 significant digits; a joint name that a
    YAML reader would take for another type, or that is no identifier, double-quoted: :func:`yaml_key`)."""
    lines = ["# joint limits (rad, rad/s, rad/s^2, N m) the exported motions were verified against"]
    if note:
        lines += [f"# {line}" for line in note.splitlines()]
    lines += ["default_velocity_scaling_factor: 1.0", "default_acceleration_scaling_factor: 1.0", "joint_limits:"]
    def limit(flag: str, pairs: list[tuple[str, float]]) -> list[str]:
        """``has_<flag>_limits`` and its values; false (no values) when one is not finite."""
        if not all(math.isfinite(v) for _, v in pairs):
            return [f"    has_{flag}_limits: false"]
        return [f"    has_{flag}_limits: true", *(f"    {key}: {v:.17g}" for key, v in pairs)]

    for k, name in enumerate(table.joint_names):
        lines += [f"  {yaml_key(name)}:",
                  *limit("position", [("min_position", float(table.lower_rad[k])),
                                      ("max_position", float(table.upper_rad[k]))]),
                  *limit("velocity", [("max_velocity", float(table.velocity_rad_s[k]))]),
                  *limit("acceleration", [("max_acceleration", float(table.acceleration_rad_s2[k]))]),
                  *limit("effort", [("max_effort", float(table.effort_Nm[k]))])]
    return "\n".join(lines) + "\n"


def write_joint_limits_yaml(path: str | Path, table: JointLimitTable, note: str = "") -> Path:
    """``joint_limits.yaml`` at ``path`` (atomic)."""
    return write_text(path, joint_limits_yaml(table, note))


#: a value tagged ``!degrees`` (ur_description's joint_limits.yaml writes ``max_position: !degrees 360.0``)
#: YAML 1.1 booleans (yaml-cpp, which MoveIt reads the file with, takes ``no`` and ``off`` for false)
YAML11_BOOLEANS = {"true": True, "yes": True, "on": True, "false": False, "no": False, "off": False}
_DEGREES = re.compile(r"!degrees\s+([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")


def read_joint_limits_yaml(path: str | Path, joint_names: Sequence[str] | None = None,
                           missing_ok: bool = False) -> JointLimitTable:
    """A MoveIt ``joint_limits.yaml``; a limit flagged absent (``has_*: false``) reads as ±inf, a value tagged
    ``!degrees`` (ur_description's files) is converted to rad.

    ``joint_names`` picks and orders the joints (default: the file's order); with ``missing_ok`` a joint the
    file does not list has every limit absent.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(path, None, f"cannot read: {exc}") from None
    try:
        data = load_yaml(_DEGREES.sub(lambda m: repr(math.radians(float(m.group(1)))), text))
    except YAMLError as exc:
        field, problem = yaml_problem(exc)
        raise DataFileError(path, field, problem) from None
    if not isinstance(data, dict) or not isinstance(data.get("joint_limits"), dict):
        raise DataFileError(path, "joint_limits", "missing or not a mapping of joints")
    entries = {str(k): v for k, v in data["joint_limits"].items()}   # an unquoted 1: is the joint "1"
    names = list(entries) if joint_names is None else list(joint_names)

    def value(name: str, flag: str, key: str, default: float) -> float:
        entry = entries.get(name)
        if entry is None and missing_ok:
            return default
        if not isinstance(entry, dict):
            raise DataFileError(path, f"joint_limits.{name}", "missing or not a mapping")
        stated = entry.get(flag, key in entry)
        if isinstance(stated, str) and stated.strip().lower() in YAML11_BOOLEANS:   # yaml-cpp's, as MoveIt reads
            stated = YAML11_BOOLEANS[stated.strip().lower()]
        if not isinstance(stated, bool):
            raise DataFileError(path, f"joint_limits.{name}.{flag}", f"{stated!r} is not true or false")
        if not stated:
            return default
        number = entry.get(key)
        if not isinstance(number, int | float) or isinstance(number, bool) or not math.isfinite(number):
            raise DataFileError(path, f"joint_limits.{name}.{key}", f"{number!r} is not a finite number")
        if key.startswith("max_") and key != "max_position" and number < 0:
            raise DataFileError(path, f"joint_limits.{name}.{key}", f"{number!r} is negative")
        return float(number)

    def column(flag: str, key: str, default: float) -> np.ndarray:
        return np.array([value(name, flag, key, default) for name in names])

    lower, upper = column("has_position_limits", "min_position", -np.inf), column("has_position_limits",
                                                                                  "max_position", np.inf)
    crossed = np.flatnonzero(lower > upper)
    if crossed.size:
        raise DataFileError(path, f"joint_limits.{names[int(crossed[0])]}", "min_position above max_position")
    return JointLimitTable(tuple(names), lower, upper,
                           column("has_velocity_limits", "max_velocity", np.inf),
                           column("has_acceleration_limits", "max_acceleration", np.inf),
                           column("has_effort_limits", "max_effort", np.inf))


def source_joint_types(urdf_file: str | Path) -> dict[str, str]:
    """``{joint: type}`` of a URDF file as written (before loading turned continuous joints revolute)."""
    try:
        root = ET.parse(urdf_file).getroot()
    except (OSError, ET.ParseError) as exc:
        raise DataFileError(urdf_file, None, f"cannot read the source URDF: {exc}") from exc
    return {str(j.get("name")): str(j.get("type")) for j in root.findall("joint")}


def restore_joint_types(urdf_text: str, types: dict[str, str]) -> str:
    """``urdf_text`` with every joint that ``types`` calls ``continuous`` continuous (position limits dropped)."""
    root = ET.fromstring(urdf_text)
    for joint in root.findall("joint"):
        if types.get(str(joint.get("name"))) == "continuous" and joint.get("type") != "continuous":
            joint.set("type", "continuous")
            limit = joint.find("limit")
            if limit is not None:
                limit.attrib.pop("lower", None)
                limit.attrib.pop("upper", None)
    return ET.tostring(root, encoding="unicode")


def with_joint_friction(urdf_text: str, joint_names: Sequence[str], viscous_Nms_rad: np.ndarray,
                        coulomb_Nm: np.ndarray) -> str:
    """``urdf_text`` with ``<dynamics damping="viscous" friction="Coulomb"/>`` on each named joint (joint side,
    N m s/rad and N m: what Gazebo, MuJoCo's and Drake's URDF import read as viscous damping and dry friction)."""
    root = ET.fromstring(urdf_text)
    index = {name: k for k, name in enumerate(joint_names)}
    for joint in root.findall("joint"):
        k = index.get(str(joint.get("name")))
        if k is None:
            continue
        dynamics = joint.find("dynamics")
        if dynamics is None:
            dynamics = ET.SubElement(joint, "dynamics")
        dynamics.set("damping", f"{float(viscous_Nms_rad[k]):.17g}")
        dynamics.set("friction", f"{float(coulomb_Nm[k]):.17g}")
    return ET.tostring(root, encoding="unicode")


def handed_on_urdf(robot: RobotModel, source_urdf: str | Path | None = None) -> str:
    """The model as URDF text with the joint types of its source URDF (``robot.urdf_path`` by default) and
    each arm joint's viscous and Coulomb friction in ``<dynamics>`` (:func:`with_joint_friction`)."""
    act = robot.spec.actuation
    text = with_joint_friction(export_urdf(robot.model, robot.urdf_text), [str(n) for n in robot.model.names[1:]],
                               act.viscous_Nms_rad, act.coulomb_Nm)
    source = Path(source_urdf) if source_urdf is not None else robot.urdf_path
    if source is not None and Path(source).is_file():
        text = restore_joint_types(text, source_joint_types(source))
        text = absolute_mesh_paths(text, Path(source))     # meshes still found from the export folder
    return text
