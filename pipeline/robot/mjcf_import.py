"""An arm from a MuJoCo MJCF file: read by Pinocchio's MJCF parser, written out as a URDF.

Every stage reads its robot as URDF text (calibrated and identified models are handed on as URDF +
robot.yaml), so an MJCF model enters once, converted: ``pin.buildModelFromMJCF`` gives the joint
tree, placements, axes, limits and the link inertias (fixed bodies merged into their moving
parent, as MuJoCo does); ``pin.buildGeomFromMJCF`` gives the collision and visual geometry, written
as ``<collision>``/``<visual>`` elements of each moving link (meshes by absolute path). What MJCF
states differently from URDF:

* a joint without a range (``limited="false"``) becomes a ``continuous`` joint, which
  :mod:`pipeline.robot.loading` loads with one turn each way (stated there);
* the effort limit is the largest torque an actuator can apply to the joint
  (``|ctrlrange| x |gear|`` of a ``ctrllimited`` motor, ``forcerange`` when ``forcelimited``,
  the joint's ``actuatorfrcrange``), read through MuJoCo's own compiler when it is installed;
  0 (a placeholder, :mod:`pipeline.robot.vendor_urdf`) where no actuator bounds it;
* MJCF has no velocity limit: 0, a placeholder;
* body frames that are not the body of a joint (a hand, a site-like body) become links fixed to
  their joint's link, so a tool flange named in the MJCF is a URDF link.
"""

from __future__ import annotations

import hashlib
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.core.artefacts import write_text
from pipeline.core.errors import RobotFileError

MJCF_SUFFIXES = (".xml", ".mjcf")


def is_mjcf(path: str | Path) -> bool:
    """A path named as an MJCF file (``.xml``/``.mjcf``) whose root element is ``<mujoco>``."""
    path = Path(path)
    if path.suffix.lower() not in MJCF_SUFFIXES or not path.is_file():
        return False
    try:
        for _, element in ET.iterparse(path, events=("start",)):
            return element.tag == "mujoco"
    except ET.ParseError:
        return False
    return False


def _fmt(values: np.ndarray | list[float]) -> str:
    return " ".join(f"{float(v):.12g}" for v in values)


def _origin(parent: ET.Element, placement: pin.SE3) -> None:
    ET.SubElement(parent, "origin", xyz=_fmt(placement.translation), rpy=_fmt(pin.rpy.matrixToRpy(placement.rotation)))


def _actuator_efforts(xml: Path, joint_names: list[str]) -> dict[str, float]:
    """Largest actuator torque on each joint, from MuJoCo's compiled model (defaults resolved)."""
    try:
        import mujoco
    except ImportError:
        return {}
    try:
        m = mujoco.MjModel.from_xml_path(str(xml))
    except Exception:           # noqa: BLE001 (MuJoCo raises plain exceptions for files it cannot compile)
        return {}
    efforts: dict[str, float] = {}
    for j in range(m.njnt):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or ""
        if name in joint_names and m.jnt_actfrclimited[j]:
            efforts[name] = float(np.max(np.abs(m.jnt_actfrcrange[j])))
    for a in range(m.nu):
        if m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            continue
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, int(m.actuator_trnid[a, 0])) or ""
        if name not in joint_names:
            continue
        bounds = []
        if m.actuator_ctrllimited[a]:
            bounds.append(float(np.max(np.abs(m.actuator_ctrlrange[a])) * abs(m.actuator_gear[a, 0])))
        if m.actuator_forcelimited[a]:
            bounds.append(float(np.max(np.abs(m.actuator_forcerange[a]))))
        if bounds:
            efforts[name] = max(efforts.get(name, 0.0), min(bounds))
    return efforts


def _geometry(model: pin.Model, xml: Path, kind: pin.GeometryType) -> list[pin.GeometryObject]:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return list(pin.buildGeomFromMJCF(model, str(xml), kind).geometryObjects)
    except (RuntimeError, ValueError, OSError):
        return []


def _shape(parent: ET.Element, obj: pin.GeometryObject) -> bool:
    """``<geometry>`` of ``obj`` under ``parent``; False for a shape URDF cannot state."""
    shape, geometry = obj.geometry, ET.Element("geometry")
    name = type(shape).__name__
    mesh_path = str(getattr(obj, "meshPath", "") or "")
    if mesh_path and Path(mesh_path).is_file():
        ET.SubElement(geometry, "mesh", filename=str(Path(mesh_path).resolve()), scale=_fmt(obj.meshScale))
    elif name == "Box":
        ET.SubElement(geometry, "box", size=_fmt(2.0 * np.asarray(shape.halfSide)))
    elif name in ("Cylinder", "Capsule"):
        length = 2.0 * shape.halfLength + (2.0 * shape.radius if name == "Capsule" else 0.0)
        ET.SubElement(geometry, "cylinder", radius=f"{shape.radius:.12g}", length=f"{length:.12g}")
    elif name == "Sphere":
        ET.SubElement(geometry, "sphere", radius=f"{shape.radius:.12g}")
    else:
        return False
    parent.append(geometry)
    return True


def _joint_axis_and_type(model: pin.Model, j: int) -> tuple[str, np.ndarray]:
    joint = model.joints[j]
    short = joint.shortname()
    axes = {"X": np.array([1.0, 0, 0]), "Y": np.array([0, 1.0, 0]), "Z": np.array([0, 0, 1.0])}
    if short in ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelPX", "JointModelPY", "JointModelPZ"):
        axis = axes[short[-1]]
    elif short in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
        axis = np.asarray(joint.extract().axis, float)
    elif short == "JointModelFreeFlyer":
        return "floating", np.zeros(3)
    elif short in ("JointModelRUBX", "JointModelRUBY", "JointModelRUBZ"):
        return "continuous", axes[short[-1]]
    else:
        raise RobotFileError(None, f"joint {model.names[j]}", f"a {short} joint cannot be written as URDF")
    return ("prismatic" if "P" in short.replace("JointModel", "")[:1] else "revolute"), axis


def mjcf_to_urdf_text(xml: str | Path) -> str:
    """URDF text of the MJCF model ``xml`` (module docstring for what is carried over and how)."""
    xml = Path(xml)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = pin.buildModelFromMJCF(str(xml))
    except (RuntimeError, ValueError, OSError) as exc:
        raise RobotFileError(xml, "mjcf", f"Pinocchio could not read the MJCF model ({exc})") from None
    names = [str(n) for n in model.names]
    efforts = _actuator_efforts(xml, names[1:])
    body_of: dict[int, str] = {}
    fixed_frames: list[pin.Frame] = []
    for frame in model.frames:
        if frame.type != pin.FrameType.BODY or frame.name == "universe":
            continue
        if frame.parentJoint > 0 and frame.parentJoint not in body_of and frame.placement.isIdentity(1e-12):
            body_of[frame.parentJoint] = str(frame.name)
        else:
            fixed_frames.append(frame)
    link_of = {0: "world", **{j: body_of.get(j, f"{names[j]}_link") for j in range(1, model.njoints)}}
    robot = ET.Element("robot", name=str(model.name or xml.stem))
    links = {0: ET.SubElement(robot, "link", name="world")}
    for j in range(1, model.njoints):
        link = links[j] = ET.SubElement(robot, "link", name=link_of[j])
        inertia = model.inertias[j]
        if inertia.mass > 0:
            inertial = ET.SubElement(link, "inertial")
            _origin(inertial, pin.SE3(np.eye(3), inertia.lever))
            ET.SubElement(inertial, "mass", value=f"{inertia.mass:.12g}")
            i = inertia.inertia
            ET.SubElement(inertial, "inertia", ixx=f"{i[0, 0]:.12g}", ixy=f"{i[0, 1]:.12g}", ixz=f"{i[0, 2]:.12g}",
                          iyy=f"{i[1, 1]:.12g}", iyz=f"{i[1, 2]:.12g}", izz=f"{i[2, 2]:.12g}")
    for tag, kind in (("visual", pin.GeometryType.VISUAL), ("collision", pin.GeometryType.COLLISION)):
        for obj in _geometry(model, xml, kind):
            element = ET.Element(tag)
            _origin(element, obj.placement)
            if _shape(element, obj):
                links[int(obj.parentJoint)].append(element)
    for j in range(1, model.njoints):
        kind, axis = _joint_axis_and_type(model, j)
        lower, upper = model.lowerPositionLimit[model.idx_qs[j]], model.upperPositionLimit[model.idx_qs[j]]
        if kind == "revolute" and not (np.isfinite(lower) and np.isfinite(upper)):
            kind = "continuous"
        joint = ET.SubElement(robot, "joint", name=names[j], type=kind)
        _origin(joint, model.jointPlacements[j])
        ET.SubElement(joint, "parent", link=link_of[model.parents[j]])
        ET.SubElement(joint, "child", link=link_of[j])
        if kind in ("revolute", "continuous", "prismatic"):
            ET.SubElement(joint, "axis", xyz=_fmt(axis))
            limit = {"effort": f"{efforts.get(names[j], 0.0):.12g}", "velocity": "0"}
            if kind != "continuous":
                limit.update(lower=f"{lower:.12g}", upper=f"{upper:.12g}")
            ET.SubElement(joint, "limit", attrib=limit)
    for frame in fixed_frames:
        ET.SubElement(robot, "link", name=str(frame.name))
        joint = ET.SubElement(robot, "joint", name=f"{frame.name}_fixed", type="fixed")
        _origin(joint, frame.placement)
        ET.SubElement(joint, "parent", link=link_of[frame.parentJoint])
        ET.SubElement(joint, "child", link=str(frame.name))
    ET.indent(robot)
    return (f'<?xml version="1.0" encoding="utf-8"?>\n<!-- converted from the MJCF model {xml.resolve()} '
            "(pipeline.robot.mjcf_import) -->\n" + ET.tostring(robot, encoding="unicode") + "\n")


def write_urdf_of_mjcf(xml: str | Path, target: str | Path) -> Path:
    """Write the URDF of the MJCF model ``xml`` to ``target`` (atomically) and return it."""
    target = Path(target)
    write_text(target, mjcf_to_urdf_text(xml))
    return target


def cached_urdf_of_mjcf(xml: str | Path, cache_dir: Path) -> Path:
    """The URDF of ``xml`` under ``cache_dir``, named by the MJCF's stem and content hash (written
    once; an edited MJCF gives another file)."""
    xml = Path(xml)
    digest = hashlib.sha256(xml.read_bytes() + str(xml.resolve()).encode()).hexdigest()[:12]
    target = cache_dir / f"{xml.stem}_{digest}.urdf"
    return target if target.is_file() else write_urdf_of_mjcf(xml, target)
