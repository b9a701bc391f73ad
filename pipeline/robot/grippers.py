"""Grippers and end effectors in a URDF: the joints that are not the arm's.

The arm chain of a URDF alone (:func:`pipeline.robot.urdf_import.arm_chain`) ends at the deepest
revolute joint that is not a gripper's; every gripper joint is locked. A gripper's joints are
recognised by name (:data:`GRIPPER_WORDS`), by ``<mimic>`` (a Robotiq 2F-85's knuckles and finger
tips follow one driver), and by being carried by one of those.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

#: words that mark a joint as part of a gripper or end effector, not the arm. Not "palm": a hand's
#: palm is fixed to the arm, and a joint that turns it is the arm's last axis (a Barrett WAM's
#: seventh joint is ``palm_yaw_joint``)
GRIPPER_WORDS = ("finger", "gripper", "hand", "knuckle", "robotiq", "jaw", "claw", "thumb")


def _link(joint: ET.Element, tag: str) -> str:
    element = joint.find(tag)
    return "" if element is None else element.get("link", "")


def _name(element: ET.Element) -> str:
    return element.get("name", "")


def gripper_joints(root: ET.Element) -> set[str]:
    """Joints of a gripper or end effector: named with one of :data:`GRIPPER_WORDS`; mimicking
    another joint or mimicked by one (a Robotiq's knuckles follow one driver) when no other
    revolute joint lies below it (a mimic inside an arm is the arm's, and refused on its chain);
    or carried by such a joint (a finger tip below a knuckle, everything below a fixed
    ``robotiq_85_base_joint``). The link a joint moves does not count: an arm's last joint often
    moves a ``gripper_link``."""
    joints = root.findall("joint")
    parent_joint = {_link(j, "child"): j for j in joints}
    above = {_name(j): _ancestors(j, parent_joint) for j in joints}
    mimicked = {m.get("joint", "") for j in joints for m in j.findall("mimic")}
    named = {_name(j) for j in joints if any(w in _name(j).lower() for w in GRIPPER_WORDS)}
    mimic = {_name(j) for j in joints if j.find("mimic") is not None or _name(j) in mimicked} - named
    independent_below = {a for j in joints if j.get("type") in ("revolute", "continuous")
                         and _name(j) not in named | mimic for a in above[_name(j)]}
    marked = named | (mimic - independent_below)
    return {_name(j) for j in joints if _name(j) in marked or marked & set(above[_name(j)])}


def _ancestors(joint: ET.Element, parent_joint: dict[str, ET.Element]) -> list[str]:
    """Names of the joints between ``joint`` and the root (``joint`` excluded)."""
    names, link = [], _link(joint, "parent")
    while link in parent_joint:
        names.append(_name(parent_joint[link]))
        link = _link(parent_joint[link], "parent")
    return names


def is_arm_joint(joint: ET.Element, gripper: set[str] | frozenset[str] = frozenset()) -> bool:
    """A revolute joint not part of a gripper or end effector (the default tip's rule)."""
    name = (joint.get("name") or "").lower()
    return (joint.get("type") in ("revolute", "continuous") and _name(joint) not in gripper
            and not any(w in name for w in GRIPPER_WORDS))
