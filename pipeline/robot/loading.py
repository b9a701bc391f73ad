"""Reading a robot from disk: URDF checks, the arm chain, limits, and the robot.yaml (or its assumed stand-in).

``load_robot_files`` returns what :class:`pipeline.robot.model.RobotModel` is assembled from:
a robot folder (``robot.yaml`` + URDF), a URDF + yaml pair, or a URDF alone (the facts it lacks
are assumed by :mod:`pipeline.robot.urdf_import` and listed). The URDF is parsed from its file
path (so relative and ``package://`` meshes can be resolved later); joints off the base->tip
chain (grippers, fingers) are locked with Pinocchio's ``buildReducedModel``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.core.codegen import cache_root
from pipeline.core.errors import RobotFileError
from pipeline.robot.mjcf_import import cached_urdf_of_mjcf, is_mjcf
from pipeline.robot.spec import RobotSpec, load_robot_spec
from pipeline.robot.urdf_checks import check_urdf_values
from pipeline.robot.urdf_import import arm_chain, assumed_spec, build_arm_model, reach_m
from pipeline.robot.vendor_urdf import (
    placeholder_inertias,
    placeholder_limits,
    repair_inertias,
    typo_inertia_placeholders,
)

ROBOTS_DIR = Path(__file__).resolve().parents[2] / "robots"
_JOINT_TYPES = {"revolute", "continuous", "prismatic", "fixed", "floating", "planar"}


@dataclass
class JointLimits:
    lower_rad: np.ndarray
    upper_rad: np.ndarray
    velocity_rad_s: np.ndarray
    effort_Nm: np.ndarray
    acceleration_rad_s2: np.ndarray


def resolve_robot_files(robot: str | Path, yaml_path: str | Path | None = None) -> tuple[Path | None, Path]:
    """(robot.yaml or None, folder) for a robot name under ``robots/``, a folder, or a URDF (+ yaml).

    A URDF without a ``robot.yaml`` beside it gives ``None``: the facts it lacks are assumed.
    """
    candidate = Path(robot)
    if yaml_path is not None:
        return Path(yaml_path), Path(yaml_path).parent
    if candidate.suffix == ".urdf":
        if not candidate.is_file():
            raise RobotFileError(candidate, "urdf", "file not found")
        guess = candidate.parent / "robot.yaml"
        return (guess if guess.is_file() else None), candidate.parent
    for folder in (candidate, ROBOTS_DIR / str(robot)):
        if folder.is_dir() and (folder / "robot.yaml").is_file():
            return folder / "robot.yaml", folder
    known = sorted(p.name for p in ROBOTS_DIR.iterdir() if (p / "robot.yaml").is_file()) if ROBOTS_DIR.is_dir() else []
    raise RobotFileError(None, "robot", f"'{robot}' is neither a URDF, a folder with a robot.yaml nor a robot "
                         f"under {ROBOTS_DIR} (known: {', '.join(known)})")


#: how the lines of an unresolved Git merge conflict start
MERGE_CONFLICT_MARKERS = ("<<<<<<< ", "=======", ">>>>>>> ")


def _conflict_note(urdf: Path) -> str:
    """``: an unresolved merge conflict (<<<<<<< on line N)`` when the file holds Git's conflict
    markers (a file committed mid-merge), else ``""``."""
    with urdf.open(encoding="utf-8", errors="replace") as text:
        for number, line in enumerate(text, 1):
            if line.startswith(MERGE_CONFLICT_MARKERS):
                return f": an unresolved merge conflict ({line.split()[0]} on line {number})"
    return ""


def check_urdf_xml(urdf: Path) -> ET.Element:
    """Parse the URDF and check what urdfdom would reject with lines of C++ errors on stderr."""
    if not urdf.is_file():
        raise RobotFileError(urdf, "urdf", "file not found")
    try:
        root = ET.parse(urdf).getroot()
    except ET.ParseError as exc:
        raise RobotFileError(urdf, "xml", f"not valid XML ({exc}){_conflict_note(urdf)}") from None
    if root.tag != "robot":
        raise RobotFileError(urdf, "xml", f"root element is <{root.tag}>, expected <robot>")
    links = {link.get("name") for link in root.findall("link")}
    for joint in root.findall("joint"):
        name, kind = joint.get("name"), joint.get("type")
        for tag in ("parent", "child"):
            element = joint.find(tag)
            if element is None or element.get("link") not in links:
                raise RobotFileError(urdf, f"joint {name}: <{tag}>", "missing or names an unknown link")
        if kind not in _JOINT_TYPES:
            raise RobotFileError(urdf, f"joint {name}: type", f"{kind!r} is not a URDF joint type "
                                 f"({', '.join(sorted(_JOINT_TYPES))})")
    check_urdf_values(urdf, root)
    return root


#: limits given to a continuous arm joint: one turn each way (cables and hoses of a real arm allow
#: no more; set tighter ones in the URDF)
CONTINUOUS_LIMIT_RAD = 2.0 * np.pi


def continuous_as_revolute(root: ET.Element, chain: list[str]) -> list[str]:
    """Turn the ``continuous`` joints of the arm chain into revolute ones with ``±CONTINUOUS_LIMIT_RAD``
    (in place; velocity and effort limits are kept and still required). Pinocchio models a
    continuous joint by (cos, sin) with nq = 2, which no stage's joint-space maths expects.
    Returns the names of the joints turned."""
    turned = []
    for joint in root.findall("joint"):
        if joint.get("name") in chain and joint.get("type") == "continuous":
            joint.set("type", "revolute")
            limit = joint.find("limit")
            if limit is None:
                limit = ET.SubElement(joint, "limit")
            limit.set("lower", repr(-CONTINUOUS_LIMIT_RAD))
            limit.set("upper", repr(CONTINUOUS_LIMIT_RAD))
            turned.append(str(joint.get("name")))
    return turned


def check_chain_joints(urdf: Path, root: ET.Element, chain: list[str]) -> bool:
    """Arm joints must be revolute with finite limits and no ``<mimic>`` (the error model, the
    symbolic bridge and calibration assume independent revolute axes); other joints are locked.
    A missing velocity or effort limit is set to 0 in the tree (a placeholder follows); True when
    the tree was changed."""
    changed = False
    joints = {j.get("name"): j for j in root.findall("joint")}
    for name in chain:
        joint = joints[name]
        kind = joint.get("type")
        if kind != "revolute":
            raise RobotFileError(urdf, f"joint {name}: type", f"'{kind}' joints are not supported on the arm chain; "
                                 "only revolute joints move (fixed joints place frames; joints off the base->tip "
                                 "chain are locked)")
        if joint.find("mimic") is not None:
            raise RobotFileError(urdf, f"joint {name}: <mimic>", "a mimic joint on the arm chain is not supported "
                                 "(its motion is not independent); choose another --tip or remove the mimic tag")
        limit = joint.find("limit")
        missing = [a for a in ("lower", "upper") if limit is None or limit.get(a) is None]
        if limit is None or missing:
            raise RobotFileError(urdf, f"joint {name}: <limit>", f"a revolute joint needs {', '.join(missing)}")
        for attribute in ("velocity", "effort"):       # missing: a placeholder (vendor_urdf), like 0
            if limit.get(attribute) is None:
                limit.set(attribute, "0")
                changed = True
        for attribute in ("lower", "upper", "velocity", "effort"):
            try:
                value = float(limit.get(attribute, ""))
            except ValueError:
                value = None
            if value is None or not np.isfinite(value):
                raise RobotFileError(urdf, f"joint {name}: <limit {attribute}>",
                                     f"not a finite number: {limit.get(attribute)!r}")
    return changed


def validate_inertials(urdf: Path, model: pin.Model) -> None:
    for j in range(1, model.njoints):
        inertia = model.inertias[j]
        name = model.names[j]
        if not inertia.mass > 0:
            raise RobotFileError(urdf, f"joint {name}: link inertial.mass", f"must be positive, got {inertia.mass}")
        eig = np.linalg.eigvalsh(inertia.inertia)
        if eig.min() <= 0:
            raise RobotFileError(urdf, f"joint {name}: link inertial.inertia",
                                 f"not positive definite (eigenvalues {np.round(eig, 6).tolist()})")
        a, b, c = np.sort(eig)
        if a + b < c * (1 - 1e-9):
            raise RobotFileError(urdf, f"joint {name}: link inertial.inertia",
                                 "violates the triangle inequality of principal moments")


def validate_joint_limits(spec: RobotSpec, model: pin.Model, limits: JointLimits) -> None:
    """Each joint must be able to move (lower < upper) and have positive velocity and effort limits.

    A limit comes from the URDF unless ``robot.yaml`` overrides it (``limits.lower_rad`` ...); the
    error names the file and field the offending value came from.
    """
    urdf, overrides = spec.urdf, spec.limit_overrides
    for i in range(model.nq):
        name = model.names[i + 1]
        lower, upper = float(limits.lower_rad[i]), float(limits.upper_rad[i])
        if not lower < upper:
            _raise_limit_order(spec, urdf, overrides, f"joint {name}", i, lower, upper)
        if not limits.velocity_rad_s[i] > 0:
            raise RobotFileError(urdf, f"joint {name}: limit.velocity", "must be positive")
        if not limits.effort_Nm[i] > 0:
            raise RobotFileError(urdf, f"joint {name}: limit.effort", "must be positive")


def _raise_limit_order(spec: RobotSpec, urdf: Path, overrides: dict[str, np.ndarray], joint: str, i: int, lower: float,
                       upper: float) -> None:
    """Report ``lower >= upper`` against the file and field each of the two values came from."""
    relation = "is above" if lower > upper else "equals"
    stuck = "" if lower > upper else " (the joint could not move)"
    entry = f"{joint} (entry {i})"
    if "lower_rad" in overrides and "upper_rad" in overrides:
        raise RobotFileError(spec.path, "limits.lower_rad", f"{entry}: {lower} {relation} limits.upper_rad "
                             f"{upper}; the lower limit must be below the upper{stuck}")
    if "lower_rad" in overrides:
        raise RobotFileError(spec.path, "limits.lower_rad", f"{entry}: {lower} {relation} the upper limit "
                             f"{upper} in {urdf.name}; the lower limit must be below it{stuck}")
    if "upper_rad" in overrides:
        below = "is below" if lower > upper else "equals"
        raise RobotFileError(spec.path, "limits.upper_rad", f"{entry}: {upper} {below} the lower limit "
                             f"{lower} in {urdf.name}; the upper limit must be above it{stuck}")
    raise RobotFileError(urdf, f"{joint}: limit", f"lower {lower} {relation} upper {upper}; "
                         f"the lower limit must be below the upper{stuck}")


def load_robot_files(robot: str | Path, yaml_path: str | Path | None = None, *, base: str | None = None,
                     tip: str | None = None, lock: dict[str, float] | None = None,
                     urdf_alone: bool = False) -> tuple[RobotSpec, pin.Model, str, list[str]]:
    """(spec, reduced Pinocchio model, URDF text, assumptions) of a robot folder, URDF + yaml, URDF alone
    or MJCF model alone (converted to a URDF once, :mod:`pipeline.robot.mjcf_import`).

    With a ``robot.yaml`` the arm chain ends at its ``flange_frame`` (its link) and starts at its
    ``base_link``, its ``locked_joints`` held; without one (or with ``urdf_alone``, which ignores a
    robot.yaml beside the URDF) at ``tip`` or, by default, at the child link of the deepest revolute
    joint (a ``tool0``/``flange`` link fixed to it when there is one). Joints in ``lock`` (name ->
    position, rad or m) and every other joint off the chain are locked. What a vendor URDF leaves
    empty (inertials, effort and velocity limits) gets placeholders (:mod:`pipeline.robot.vendor_urdf`).
    """
    if is_mjcf(robot):       # an MJCF model alone: read through its URDF (mjcf_import), written once
        robot = cached_urdf_of_mjcf(robot, cache_root() / "mjcf")
        urdf_alone = True
    yaml_file, _ = resolve_robot_files(robot, yaml_path)
    if urdf_alone and str(robot).endswith(".urdf"):
        yaml_file = None
    spec = load_robot_spec(yaml_file) if yaml_file is not None else None
    if str(robot).endswith(".urdf"):
        urdf = Path(robot)
    else:
        assert spec is not None          # a robot that is not a URDF file was resolved to its robot.yaml
        urdf = spec.urdf
    root = check_urdf_xml(urdf)
    flange = spec.flange_frame if spec is not None else tip
    if spec is not None:
        base = base or spec.base_link
        lock = {**spec.locked_joints, **(lock or {})}
    chain, base_link, tip_link = arm_chain(urdf, root, base=base, tip=flange, tip_is_frame=spec is not None,
                                           lock=lock)
    turned = continuous_as_revolute(root, chain)
    filled = check_chain_joints(urdf, root, chain)
    model, locked = build_arm_model(urdf, root, chain, lock)
    if model.nq != model.nv:  # guard: chain joints are revolute
        raise RobotFileError(urdf, "joints", f"expected revolute joints only (nq={model.nq}, nv={model.nv})")
    reach = reach_m(model, tip_link)
    keep = {k for k in ("velocity", "effort") if spec is not None
            and f"{k}_{'rad_s' if k == 'velocity' else 'Nm'}" in spec.limit_overrides}
    flange_local = model.frames[model.getFrameId(tip_link)].placement.translation
    inertials = placeholder_inertias(model, root, flange_local, reach, urdf)
    typos = typo_inertia_placeholders(model, root, flange_local, reach)
    assumptions: list[str] = [*inertials, *typos, *repair_inertias(model, root),
                              *placeholder_limits(model, root, reach, keep, masses_stated=not inertials)]
    validate_inertials(urdf, model)
    if turned:
        assumptions.append(f"continuous joints loaded as revolute ones with limits of one turn each way "
                           f"(±{CONTINUOUS_LIMIT_RAD:.4f} rad): {', '.join(turned)}")
    if locked:
        held = ", ".join(f"{n} at its neutral configuration" if v is None else
                         f"{n} = {v:g}" for n, v in locked.items())
        assumptions.append(f"joints off the arm chain {base_link} -> {tip_link} locked (at 0 when the limits "
                           f"allow, else mid-range, unless given with --lock NAME=VALUE): {held}")
    if spec is None:
        spec, assumed = assumed_spec(urdf, root, model, tip_link)
        spec.base_link = base
        spec.locked_joints = {n: v for n, v in locked.items() if v is not None}
        assumptions += assumed
    else:
        assert yaml_file is not None     # spec was read from it above
        spec = load_robot_spec(yaml_file, nq=model.nq)
        spec.urdf = urdf
    text = ET.tostring(root, encoding="unicode") if turned or filled else urdf.read_text()
    return spec, model, text, assumptions
