"""Write a Pinocchio model back as URDF text (calibrated joint placements, identified inertials).

The source URDF is the template: joint origins, limits and link inertials are replaced by the
model's values; visuals and everything else are kept.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

from pipeline.core.errors import RobotFileError


def _fmt(values: np.ndarray) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)


def _link_of(joint: ET.Element, tag: str, name: str) -> str:
    """The ``link`` attribute of a joint's ``<parent>`` or ``<child>`` element."""
    element = joint.find(tag)
    link = None if element is None else element.get("link")
    if link is None:
        raise RobotFileError(None, f"joint {name}", f"no <{tag} link=...> in the template URDF")
    return link


def export_urdf(model: pin.Model, template_urdf: str) -> str:
    """URDF text of ``model``: the template with joint origins, limits and link inertials replaced.

    Fixed child links are merged into their moving parent by Pinocchio, so their inertials are
    removed here (the merged inertia is written on the moving link). The template's joint
    tree must be the model's (same joint names).
    """
    root = ET.fromstring(template_urdf)
    joints = {j.get("name"): j for j in root.findall("joint")}
    links = {link.get("name"): link for link in root.findall("link")}
    moving_children = set()
    for j in range(1, model.njoints):
        name = model.names[j]
        element = joints.get(name)
        if element is None:
            raise RobotFileError(None, f"joint {name}", "not in the template URDF")
        parent_link = _link_of(element, "parent", name)
        # Pinocchio folds fixed joints (a `world` root, flange adapters) into the joint placement: the
        # URDF origin is the placement seen from the parent link's frame
        if not model.existFrame(parent_link, pin.FrameType.BODY):
            raise RobotFileError(None, f"joint {name}", f"parent link '{parent_link}' is not a frame of the model")
        body = model.frames[model.getFrameId(parent_link, pin.FrameType.BODY)]
        placement = body.placement.actInv(model.jointPlacements[j])
        origin = element.find("origin")
        if origin is None:
            origin = ET.SubElement(element, "origin")
        origin.set("xyz", _fmt(placement.translation))
        origin.set("rpy", _fmt(pin.rpy.matrixToRpy(placement.rotation)))
        limit = element.find("limit")
        if limit is not None:
            limit.set("lower", f"{model.lowerPositionLimit[j - 1]:.17g}")
            limit.set("upper", f"{model.upperPositionLimit[j - 1]:.17g}")
            limit.set("velocity", f"{model.velocityLimit[j - 1]:.17g}")
            limit.set("effort", f"{model.effortLimit[j - 1]:.17g}")
        child = _link_of(element, "child", name)
        moving_children.add(child)
        link = links[child]
        for old in link.findall("inertial"):
            link.remove(old)
        inertia = model.inertias[j]
        inertial = ET.Element("inertial")
        ET.SubElement(inertial, "origin", xyz=_fmt(inertia.lever), rpy="0 0 0")
        ET.SubElement(inertial, "mass", value=f"{inertia.mass:.17g}")
        i = inertia.inertia
        ET.SubElement(inertial, "inertia", ixx=f"{i[0, 0]:.17g}", ixy=f"{i[0, 1]:.17g}", ixz=f"{i[0, 2]:.17g}",
                      iyy=f"{i[1, 1]:.17g}", iyz=f"{i[1, 2]:.17g}", izz=f"{i[2, 2]:.17g}")
        link.insert(0, inertial)
    base_links = {model.frames[f].name for f in range(len(model.frames))
                  if model.frames[f].parentJoint == 0}
    for name, link in links.items():
        if name not in moving_children and name not in base_links:
            for old in link.findall("inertial"):
                link.remove(old)
    ET.indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
