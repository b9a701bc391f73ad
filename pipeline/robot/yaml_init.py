"""``python -m pipeline robot init ARM.urdf``: a commented robot.yaml with the values assumed for a URDF.

:func:`write_robot_yaml` loads the URDF alone (:mod:`pipeline.robot.urdf_import` assumes what it
lacks; a robot.yaml beside it is ignored, so ``--tip``, ``--base`` and ``--lock`` always count),
and writes those values as a ``robot.yaml`` beside it (or at ``out``) for the user to edit, each
section headed by the rule it came from. Every value assumed carries a ``# ASSUMED: rule``
comment and an entry under ``assumed`` with its digest (:mod:`pipeline.robot.assumed_values`):
the robot's assumptions list it until the user edits the value. Placeholder velocity and effort
limits (``velocity="0"`` / ``effort="0"`` in the URDF) are written as ``limits`` overrides. Loading
the URDF again then reads this file instead of assuming. The file is written atomically and never
replaces an existing one unless ``force``.

Torque side (``actuation.torque_side``, ``--torque-side``): where a torque log of the arm is
measured. ``link``: joint torque sensors after the gear (Franka Panda/FR3, KUKA LBR iiwa/Med,
Kinova Gen3), whose torque holds neither rotor inertia nor drive friction: the prediction of a
logged torque leaves them out, while robot.yaml keeps the drive's values for the simulated plant
(its motor mass). ``motor``: torques from motor currents; rotor inertia and friction are assumed by
the rules below and left out of the nominal prediction while unedited
(:func:`pipeline.robot.assumed_values.predicted_drive_values`). Without the option the side is
detected (:func:`detect_torque_side`) and marked ASSUMED.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.core.artefacts import write_text
from pipeline.core.errors import RobotFileError
from pipeline.core.yaml12 import dump_yaml
from pipeline.robot.assumed_values import assumed_entry
from pipeline.robot.mjcf_import import is_mjcf, write_urdf_of_mjcf
from pipeline.robot.model import RobotModel
from pipeline.robot.repeatability import repeatability_rule
from pipeline.robot.spec import RobotSpec
from pipeline.robot.spec_yaml import robot_spec_to_yaml
from pipeline.robot.urdf_import import (
    ACCELERATION_PER_VELOCITY_1_S,
    ARM_GEAR_RATIO,
    COULOMB_FRACTION,
    ROTOR_INERTIA_PER_EFFORT_S2,
    VISCOUS_FRACTION,
    WRIST_GEAR_RATIO,
)

_HEADER = """\
# robot.yaml written by `python -m pipeline robot init` from {urdf}
# Values marked ASSUMED were assumed because the URDF does not carry them: edit what you know
# better (the mark is tracked under `assumed:` and stops counting once the value is edited);
# units are SI (m, rad, kg, N·m, s). Assumptions made on loading the URDF:
{assumptions}
"""

_SECTION_NOTES = {
    "tool": "# TCP pose and laser-tracker reflector in the flange frame",
    "actuation": "# drive train, joint side: gear ratios, rotor inertia, viscous and Coulomb friction; torque_side: "
                 "where a torque log is measured (link: joint torque sensors, motor: motor currents)",
    "limits": "# position, velocity and effort limits come from the URDF unless given here; accelerations "
              "are stated here",
    "tracker": "# nominal laser-tracker pose in the base frame (p_base = T * p_tracker); delete the section "
               "if there is no tracker (then no calibration stage)",
    "collision": "# floor height and the first joint whose capsules must stay above it",
    "capsules": "# collision capsules: segment p0-p1 in the frame `frame`, swept by a sphere of radius_m",
    "locked_joints": "# joints off the arm chain held at these positions (rad or m)",
}


#: arm names (URDF robot, link or joint names) of arms with a torque sensor in every joint
LINK_SIDE_ARMS = re.compile(r"panda|fr3|franka|iiwa|lbr|kuka_med|gen3", re.IGNORECASE)


def detect_torque_side(urdf: Path, arm_joints: list[str]) -> tuple[str, str]:
    """``(side, how)``: ``link`` when the URDF names an arm built with joint torque sensors (robot,
    link or joint names matching :data:`LINK_SIDE_ARMS`) or declares a ``force_torque`` sensor
    (Gazebo ``<sensor type="force_torque">``) on every arm joint; else ``motor``."""
    root = ET.parse(urdf).getroot()
    names = [root.get("name") or "", *(e.get("name") or "" for e in root.iter() if e.tag in ("link", "joint"))]
    if any(LINK_SIDE_ARMS.search(n) for n in names):
        return "link", "the URDF names an arm with a torque sensor in every joint (Franka, iiwa/LBR, Kinova Gen3)"
    sensed = {g.get("reference") for g in root.iter("gazebo")
              if any(x.get("type") == "force_torque" for x in g.iter("sensor"))}
    if arm_joints and set(arm_joints) <= sensed:
        return "link", "the URDF declares a force_torque sensor on every arm joint"
    return "motor", "no joint torque sensor found in the URDF: torques from motor currents"


def _rules(robot: RobotModel, *, tip_given: bool, lock: dict[str, float], placeholders: set[str]) -> dict[str, str]:
    """Dotted path -> rule of every value ``robot init`` assumed."""
    spec = robot.spec
    rules = {
        "payload_kg": "no payload",
        "repeatability_m": repeatability_rule(),
        "tool.transform_tcp_to_flange": "TCP at the flange",
        "tool.reflector_offset_m": "on the flange z axis facing away from the arm, outside every capsule",
        "tool.reflector_axis": "opening along the flange z axis, away from the arm",
        "actuation.gear_ratio": f"{ARM_GEAR_RATIO:g} on axes 1-3, {WRIST_GEAR_RATIO:g} on the wrist",
        "actuation.gear_coupling": "no coupling between axes",
        "actuation.rotor_inertia_kgm2": f"{ROTOR_INERTIA_PER_EFFORT_S2:g} s² x effort limit",
        "actuation.viscous_Nms_rad": f"{VISCOUS_FRACTION:g} x effort / velocity limit",
        "actuation.coulomb_Nm": f"{COULOMB_FRACTION:.0%} of the effort limit",
        "actuation.coulomb_smoothing_rad_s": "0.01 rad/s",
        "limits.acceleration_rad_s2": f"{ACCELERATION_PER_VELOCITY_1_S:g}/s x velocity limit",
        "tracker": "1.5 reaches in front of the base, 0.2 reaches up; 8 µm + 3 µm/m, 30°",
        "collision.floor_z_m": "floor at the base",
        "collision.floor_check_from_joint": "links bolted near the floor not checked",
        "capsules": "one per link, fitted to its collision geometry or from joint to joint",
    }
    if not tip_given:
        rules["flange_frame"] = "child of the deepest revolute joint (a tool0/flange link fixed to it if any)"
    if spec.collision.ignore_pairs:
        rules["collision.ignore_pairs"] = "capsule pairs overlapping in almost every configuration"
    if set(spec.locked_joints) - set(lock):
        rules["locked_joints"] = "0 when the limits allow, else mid-range (--lock NAME=VALUE to choose)"
    for kind, key in (("velocity", "velocity_rad_s"), ("effort", "effort_Nm")):
        if kind in placeholders:
            rules[f"limits.{key}"] = f"PLACEHOLDER: the URDF's {kind} limit is 0 or missing"
    return rules


def _commented(key: str, value: object, rules: dict[str, str]) -> str:
    """A top-level section as YAML, each assumed line ending in ``# ASSUMED: rule``."""
    flow = None if isinstance(value, dict | list) else False
    lines = dump_yaml({key: value}, width=100000, flow=flow).rstrip().split("\n")
    for n, line in enumerate(lines):
        indent = len(line) - len(line.lstrip())
        name = line.strip().split(":", 1)[0]
        dotted = key if n == 0 else f"{key}.{name}" if indent == 2 else None
        if dotted in rules and ":" in line:
            lines[n] = f"{line}  # ASSUMED: {rules[dotted]}"
    return "\n".join(lines)


@dataclass(frozen=True)
class StatedJointLimits:
    """Limits a file states per joint name (rad/s, rad/s², N·m; inf or NaN: not stated) and the file's name."""

    source: str
    velocity_rad_s: dict[str, float]
    acceleration_rad_s2: dict[str, float]
    effort_Nm: dict[str, float]


def stated_limits(robot: RobotModel, spec: RobotSpec, stated: StatedJointLimits,
                  placeholders: set[str]) -> dict[str, str | None]:
    """Take limits a file states into ``spec``: every joint's acceleration, and the velocity and effort limits
    the URDF left as placeholders (``placeholders``), where the file gives a number > 0 for the joint (a limit
    flagged absent, a 0 or a joint it does not list: not stated). Returns, per robot.yaml key it touched, the
    rule that remains assumed (None: stated for every joint)."""
    names = [str(n) for n in robot.model.names[1:]]
    out: dict[str, str | None] = {}
    velocity = np.asarray(robot.limits.velocity_rad_s, float)
    for key, wanted in (("velocity_rad_s", "velocity" in placeholders), ("effort_Nm", "effort" in placeholders),
                        ("acceleration_rad_s2", True)):
        given = np.array([getattr(stated, key).get(n, np.nan) for n in names], float)
        ok = np.isfinite(given) & (given > 0)
        if key == "acceleration_rad_s2":   # the rule's value follows a velocity the file replaced
            rule_values = ACCELERATION_PER_VELOCITY_1_S * velocity
            if ok.any() or "limits.velocity_rad_s" in out:
                spec.acceleration_rad_s2 = np.where(ok, given, rule_values)
            if not ok.any():
                continue
        elif not wanted or not ok.any():
            continue
        else:
            spec.limit_overrides[key] = np.where(ok, given, getattr(robot.limits, key))
            if key == "velocity_rad_s":
                velocity = spec.limit_overrides[key]
        missing = [n for n, k in zip(names, ok, strict=True) if not k]
        out[f"limits.{key}"] = None if not missing else (
            f"{ACCELERATION_PER_VELOCITY_1_S:g}/s x velocity limit on {missing} ({stated.source} states the others)"
            if key == "acceleration_rad_s2" else
            f"PLACEHOLDER: the URDF's {key.split('_')[0]} limit is 0 or missing on {missing} ({stated.source} "
            "states the others)")
    return out


def parse_locks(items: list[str]) -> dict[str, float]:
    """``["track=0.5", ...]`` (``--lock JOINT=VALUE``) -> ``{"track": 0.5}``."""
    locks = {}
    for item in items:
        name, _, value = item.partition("=")
        try:
            locks[name.strip()] = float(value)
        except ValueError:
            raise RobotFileError(None, "--lock", f"expected JOINT=VALUE with VALUE in rad or m, got {item!r}") from None
    return locks


def write_robot_yaml(urdf: str | Path, out: str | Path | None = None, *, base: str | None = None,
                     tip: str | None = None, lock: dict[str, float] | None = None, force: bool = False,
                     torque_side: str | None = None, joint_limits: StatedJointLimits | None = None) -> Path:
    """Write the commented robot.yaml of ``urdf`` (beside it unless ``out``) and return its path. An
    MJCF model (``model.xml``) is converted first: ``model.urdf`` beside the robot.yaml
    (:mod:`pipeline.robot.mjcf_import`).
    ``torque_side``: link | motor (None: :func:`detect_torque_side`, marked ASSUMED).
    ``joint_limits``: the limits of a MoveIt ``joint_limits.yaml`` (the arm's moveit_config or description
    package): its accelerations are taken as stated, and its velocity and effort limits where the URDF has
    none (:func:`stated_limits`)."""
    urdf = Path(urdf)
    target = Path(out) if out is not None else urdf.parent / "robot.yaml"
    if target.exists() and not force:
        raise RobotFileError(target, "robot.yaml", "already exists; remove it, write elsewhere (--out) or "
                             "replace it (--force)")
    if is_mjcf(urdf):        # an MJCF model: its URDF written beside robot.yaml, which names it
        urdf = write_urdf_of_mjcf(urdf, target.parent / f"{urdf.stem}.urdf")
    robot = RobotModel.load(urdf, base=base, tip=tip, lock=lock, urdf_alone=True)
    spec = robot.spec
    placeholders = {kind for kind in ("velocity", "effort")
                    if any(a.startswith(f"PLACEHOLDER {kind} limits") for a in robot.assumptions)}
    spec.limit_overrides.update({"velocity_rad_s": robot.limits.velocity_rad_s} if "velocity" in placeholders
                                else {})
    spec.limit_overrides.update({"effort_Nm": robot.limits.effort_Nm} if "effort" in placeholders else {})
    stated = {} if joint_limits is None else stated_limits(robot, spec, joint_limits, placeholders)
    side, how = (torque_side, "") if torque_side is not None else detect_torque_side(
        urdf, [str(robot.model.names[j]) for j in range(1, robot.model.njoints)])
    spec.actuation.torque_side = side
    data = robot_spec_to_yaml(spec, str(urdf.resolve()) if target.parent.resolve() != urdf.parent.resolve()
                              else urdf.name)
    data.pop("assumptions", None)
    rules = _rules(robot, tip_given=tip is not None, lock=lock or {}, placeholders=placeholders)
    for key, rule in stated.items():
        if rule is None:
            rules.pop(key, None)
        else:
            rules[key] = rule
    if how:
        rules["actuation.torque_side"] = how
    data["assumed"] = {dotted: assumed_entry(data, dotted, rule) for dotted, rule in rules.items()}
    kept = [a for a in robot.assumptions if not a.startswith(("PLACEHOLDER velocity", "PLACEHOLDER effort"))]
    lines = [_HEADER.format(urdf=urdf, assumptions="\n".join(f"#  - {a}" for a in kept))]
    for key, value in data.items():
        if key in _SECTION_NOTES:
            lines.append(_SECTION_NOTES[key])
        if key == "assumed":
            lines.append("# values above still as robot init assumed them: rule and digest (do not edit)")
        lines.append(_commented(key, value, rules) if key != "assumed" else
                     dump_yaml({key: value}, width=110).rstrip())
    write_text(target, "\n".join(lines) + "\n")
    return target
