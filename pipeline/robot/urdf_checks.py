"""Values of a URDF that urdfdom would take without a word, or only with lines of C++ errors on stderr.

urdfdom parses ``izz="nan"`` as NaN and ``mass="inf"`` as infinity; it drops an inertial element it
cannot parse (``izz="abc"``) with an ``Error:`` on stderr, after which the link has no inertia and a
placeholder follows. A joint whose lower limit is above its upper reaches numpy as
``ValueError: high - low < 0`` the first time a configuration is drawn. :func:`check_urdf_values`
refuses all three in one line naming the element, the attribute and the value, before Pinocchio
reads the file.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from pipeline.core.errors import RobotFileError

#: the numeric attributes of the URDF elements (ROS URDF XML specification), with how many numbers each holds
NUMERIC_ATTRIBUTES: dict[str, dict[str, int]] = {
    "origin": {"xyz": 3, "rpy": 3},
    "mass": {"value": 1},
    "inertia": {name: 1 for name in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")},
    "axis": {"xyz": 3},
    "limit": {"lower": 1, "upper": 1, "effort": 1, "velocity": 1},
    "dynamics": {"damping": 1, "friction": 1},
    "safety_controller": {"soft_lower_limit": 1, "soft_upper_limit": 1, "k_position": 1, "k_velocity": 1},
    "calibration": {"rising": 1, "falling": 1, "reference_position": 1},
    "mimic": {"multiplier": 1, "offset": 1},
    "box": {"size": 3},
    "cylinder": {"radius": 1, "length": 1},
    "capsule": {"radius": 1, "length": 1},
    "sphere": {"radius": 1},
    "mesh": {"scale": 3},
    "color": {"rgba": 4},
}


#: elements whose every attribute above urdfdom requires (an inertia without ``iyz`` is not parsed)
REQUIRED_ATTRIBUTE_TAGS = frozenset({"inertia"})


def _owner(element: ET.Element, kind: str) -> str:
    return f"{kind} {element.get('name', '?')}"


#: a number as urdfdom's ``strToDouble`` reads it (``std::istream >> double``, classic locale): ASCII
#: digits, an optional fraction and exponent; no ``nan``/``inf``, digit separators or non-ASCII digits
_CPP_DOUBLE = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_CPP_SPACE = " \t\n\r\f\v"
_NOT_FINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
#: the largest magnitude a URDF number may have: the loader multiplies up to three of them (a mass
#: times a squared lever arm, a rotation of an inertia), and a product of three numbers below 1e100
#: stays inside the double range (1.8e308); no quantity of an arm in SI units comes near it
MAX_MAGNITUDE = 1e100


def _number(token: str) -> float | None:
    """``token`` as urdfdom reads it: leading blanks skipped, then one number and nothing after it."""
    token = token.lstrip(_CPP_SPACE)
    if _CPP_DOUBLE.fullmatch(token) or _NOT_FINITE.fullmatch(token):
        return float(token)
    return None


def _numbers(text: str, count: int) -> list[float] | None:
    """The numbers of an attribute value: one scalar, or a vector split at ASCII spaces as urdfdom's
    ``Vector3::init`` does (a tab inside a vector is part of a token, and so refused)."""
    tokens = [text] if count == 1 else [token for token in text.split(" ") if token]
    numbers = [_number(token) for token in tokens]
    return None if any(x is None for x in numbers) else [float(x) for x in numbers if x is not None]


def check_urdf_values(urdf: Path, root: ET.Element) -> None:
    """Every number of every link, joint and material of ``root`` is finite, at most
    :data:`MAX_MAGNITUDE` in magnitude and of the right count,
    and no joint's ``<limit lower>`` is above its ``upper``; else :class:`RobotFileError`
    (``<urdf>: link l1: <inertia izz>: not a finite number: 'nan'``). Extension elements
    (``<gazebo>``, ``<transmission>``) are not URDF geometry and are not read."""
    for kind in ("link", "joint", "material"):
        for owner in root.findall(kind):
            for element in owner.iter():
                for attribute, count in NUMERIC_ATTRIBUTES.get(element.tag, {}).items():
                    text = element.get(attribute)
                    if text is None:
                        if element.tag in REQUIRED_ATTRIBUTE_TAGS:     # urdfdom drops the element with an Error
                            raise RobotFileError(urdf, f"{_owner(owner, kind)}: <{element.tag}>",
                                                 f"the {attribute} attribute is missing")
                        continue
                    numbers = _numbers(text, count)
                    where = f"{_owner(owner, kind)}: <{element.tag} {attribute}>"
                    if numbers is None or len(numbers) != count:
                        expected = "a number" if count == 1 else f"{count} numbers"
                        raise RobotFileError(urdf, where, f"expected {expected}, got {text!r}")
                    if not all(math.isfinite(x) for x in numbers):
                        raise RobotFileError(urdf, where, f"not a finite number: {text!r}")
                    if any(abs(x) > MAX_MAGNITUDE for x in numbers):
                        raise RobotFileError(urdf, where, f"{text!r} is beyond {MAX_MAGNITUDE:g} in magnitude "
                                             "(products of such numbers leave the floating-point range)")
    for joint in root.findall("joint"):
        limit = joint.find("limit")
        if limit is None or limit.get("lower") is None or limit.get("upper") is None:
            continue
        lower, upper = float(limit.get("lower", "0")), float(limit.get("upper", "0"))
        if lower > upper:
            raise RobotFileError(urdf, f"{_owner(joint, 'joint')}: limit", f"lower {lower} is above upper {upper}; "
                                 "the lower limit must be below the upper")
