"""A robot from its URDF alone: the arm chain, locked extra joints, and stated assumptions.

What a URDF lacks is assumed from rules stated here (each becomes a line of
``RobotModel.assumptions`` that the report lists), sized by the URDF's own limits and reach:

* gear ratio 100 on axes 1-3 and 50 on the wrist, the sizes DESIGN.md gives for an industrial
  arm (RX130L: about 100 and 50-70);
* joint-side rotor inertia ``5e-3 s^2 x effort limit`` (the RX130L's 3 kg m^2 at 550 N m and
  0.1 kg m^2 at 30 N m, DESIGN.md), viscous friction ``0.1 x effort / velocity limit`` and
  Coulomb friction ``4 % of the effort limit`` (RX130L: 20 N m s/rad at 550 N m and 3.5 rad/s,
  25 N m at 550 N m);
* acceleration limits ``5 x velocity limit`` per second (full speed in 0.2 s);
* TCP at the flange (the tip link, or a ``tool0``/``flange`` link fixed to it), reflector on the
  flange z axis on the side facing away from the arm (``+z`` on ``tool0``, else the side the last
  body's tool/gripper geometry lies on, else away from the nearest upstream joint), 10 mm beyond
  the last body's capsules (at least 30 mm) and outside every other capsule, opening outwards;
* a laser tracker 1.5 reaches in front of the base (x), 0.2 reaches up (DESIGN.md: 2.5 m from an
  arm of 1.66 m reach), with DESIGN.md's noise model;
* one capsule per moving link fitted to its collision geometry (principal axis of the points,
  75th percentile radius: housings that stick out are not all covered, long links are not
  swollen), or, where no geometry or mesh is available (a vendor's mesh package not installed:
  stated), a capsule from the joint to the next joint with a radius of a quarter of that length.

Placeholders for what a vendor URDF leaves empty (inertials, effort and velocity limits) are
:mod:`pipeline.robot.vendor_urdf`'s.
"""

from __future__ import annotations

import os
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from pipeline.core.errors import RobotFileError
from pipeline.robot.grippers import gripper_joints, is_arm_joint
from pipeline.robot.reflector_check import capsules_holding
from pipeline.robot.repeatability import assumed_repeatability_m, repeatability_rule
from pipeline.robot.spec import ActuationSpec, Capsule, CollisionSpec, RobotSpec, ToolSpec, TrackerSpec

WRIST_GEAR_RATIO, ARM_GEAR_RATIO = 50.0, 100.0
ROTOR_INERTIA_PER_EFFORT_S2 = 5e-3
VISCOUS_FRACTION, COULOMB_FRACTION = 0.1, 0.04
ACCELERATION_PER_VELOCITY_1_S = 5.0
REFLECTOR_OFFSET_M = 0.03
#: a link fixed to the last arm link that is the tool flange (ROS-Industrial REP 199 names it tool0)
FLANGE_LINKS = ("tool0", "flange")
TRACKER_DISTANCE_REACHES, TRACKER_HEIGHT_REACHES = 1.5, 0.2


def package_dirs(urdf: Path) -> list[str]:
    """Folders where ``package://NAME/...`` is looked up: ROS_PACKAGE_PATH, then the URDF's folder
    and its parents (a package folder's parent holds ``NAME/``)."""
    dirs = [d for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
    folder = Path(urdf).resolve().parent
    dirs += [str(p) for p in [folder, *folder.parents][:8]]
    return dirs


def resolve_mesh(filename: str, urdf: Path) -> Path | None:
    """The file a URDF mesh reference names (``package://NAME/...`` or a path relative to the URDF)."""
    if filename.startswith("file://"):
        filename = filename[len("file://"):]
    if filename.startswith("package://"):
        relative = filename[len("package://"):]
        for folder in package_dirs(urdf):
            if (Path(folder) / relative).is_file():
                return Path(folder) / relative
        return None
    path = Path(filename) if Path(filename).is_absolute() else Path(urdf).resolve().parent / filename
    return path if path.is_file() else None


def absolute_mesh_paths(urdf_text: str, urdf: Path) -> str:
    """``urdf_text`` with every resolvable mesh reference replaced by its absolute path (so a copy
    written elsewhere, e.g. a stage's calibrated robot, still shows the meshes)."""
    root = ET.fromstring(urdf_text)
    for mesh in root.iter("mesh"):
        found = resolve_mesh(mesh.get("filename", ""), urdf)
        if found is not None:
            mesh.set("filename", str(found.resolve()))
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _link(joint: ET.Element, tag: str) -> str:
    """The ``link`` attribute of a joint's ``<parent>`` or ``<child>`` (checked by ``check_urdf_xml``)."""
    element = joint.find(tag)
    return "" if element is None else element.get("link", "")


def _name(element: ET.Element) -> str:
    """An element's ``name`` attribute ("" when absent)."""
    return element.get("name", "")


def flange_link(root: ET.Element, link: str) -> str:
    """``link``, or the first of :data:`FLANGE_LINKS` fixed to it (through fixed joints only): the
    ROS-Industrial tool flange (REP 199), which a vendor's last link frame need not be (a KUKA's
    ``link_6`` sits at the wrist centre, its ``tool0`` on the flange face)."""
    fixed_children: dict[str, list[str]] = {}
    for joint in root.findall("joint"):
        if joint.get("type") == "fixed":
            fixed_children.setdefault(_link(joint, "parent"), []).append(_link(joint, "child"))
    found, todo = [], [link]
    while todo:
        current = todo.pop()
        found.append(current)
        todo += fixed_children.get(current, [])
    for name in FLANGE_LINKS:
        if name in found:
            return name
    return link


def arm_chain(urdf: Path, root: ET.Element, *, base: str | None = None, tip: str | None = None,
              tip_is_frame: bool = False, lock: dict[str, float] | None = None) -> tuple[list[str], str, str]:
    """(movable joint names base->tip, base link, tip link).

    Default tip: the child link of the deepest revolute joint not part of a gripper or end effector
    (:func:`gripper_joints`; the most such joints between it and the root), or a ``tool0``/``flange`` link fixed to it
    (:func:`flange_link`); an ambiguous choice (several such chains) asks for ``--tip``. Joints in
    ``lock`` and prismatic/planar/floating joints below the first revolute one (a linear track under
    the arm) are not part of the chain (they are locked, :func:`build_arm_model`).
    """
    joints = root.findall("joint")
    parent_joint = {_link(j, "child"): j for j in joints}
    links = [_name(link) for link in root.findall("link")]

    def path_to_root(link: str) -> list[ET.Element]:
        path = []
        while link in parent_joint:
            joint = parent_joint[link]
            path.append(joint)
            link = _link(joint, "parent")
        return path[::-1]

    if tip is not None and tip not in links:
        if not tip_is_frame:
            raise RobotFileError(urdf, "tip", f"no link '{tip}' (links: {', '.join(links)})")
        tip = None          # a yaml flange frame that is not a link: default chain
    if tip is None:
        gripper = gripper_joints(root)
        depth = {link: sum(is_arm_joint(j, gripper) for j in path_to_root(link)) for link in links}
        deepest = max(depth.values(), default=0)
        ends = {link for link in links if depth[link] == deepest and link in parent_joint
                and is_arm_joint(parent_joint[link], gripper)}
        if deepest == 0 or not ends:
            raise RobotFileError(urdf, "joints", "no movable joint (expected a chain of revolute joints)")
        if len(ends) > 1:
            raise RobotFileError(urdf, "tip", f"several arm chains end {deepest} joints from the root "
                                 f"({', '.join(sorted(ends))}): choose one (python -m pipeline robot init "
                                 f"{urdf} --tip LINK --out DIR/robot.yaml, then run with --set robot=DIR)")
        tip = flange_link(root, ends.pop())
    path = path_to_root(tip)
    root_link = _link(path[0], "parent") if path else tip
    if base is not None:
        names = [_link(j, "parent") for j in path]
        if base not in names:
            raise RobotFileError(urdf, "base", f"link '{base}' is not between the root and '{tip}' "
                                 f"(links on that path: {', '.join(names)})")
        above = path[:names.index(base)]
        carried = [_name(j) for j in above if j.get("type") != "fixed"]
        if carried:
            raise RobotFileError(urdf, "base", f"link '{base}' is carried by movable joints {', '.join(carried)}; "
                                 "choose a base link fixed to the root")
        path = path[names.index(base):]
    moving = [j for j in path if j.get("type") != "fixed" and _name(j) not in (lock or {})]
    while moving and moving[0].get("type") not in ("revolute", "continuous"):
        moving = moving[1:]            # a track or lift below the arm: locked; one inside the arm is refused
    chain = [_name(j) for j in moving]
    if not chain:
        raise RobotFileError(urdf, "joints", f"no movable joint between '{base or root_link}' and '{tip}'")
    return chain, base or root_link, tip


def build_arm_model(urdf: Path, root: ET.Element, chain: list[str],
                    lock: dict[str, float] | None = None) -> tuple[pin.Model, dict[str, float | None]]:
    """Pinocchio model of the chain: every other joint locked (``pin.buildReducedModel``, which merges
    the locked links' inertia into the arm) at its ``lock`` value, else at 0 when its limits allow,
    else mid-range (:func:`lock_positions`). Returns the model and each locked joint's value (None: a
    multi-DOF joint held at its neutral configuration)."""
    try:     # from the checked tree (continuous chain joints turned revolute, loading.py)
        full = pin.buildModelFromXML(ET.tostring(root, encoding="unicode"))
    except (RuntimeError, ValueError) as exc:
        raise RobotFileError(urdf, "urdf", f"Pinocchio could not build the model ({exc})") from None
    locked = [str(n) for n in full.names[1:] if n not in chain]
    q_ref = lock_positions(urdf, full, locked, lock or {})
    if not locked:
        return full, {}
    reduced = pin.buildReducedModel(full, [full.getJointId(n) for n in locked], q_ref)
    held = {n: (float(q_ref[full.joints[full.getJointId(n)].idx_q]) if full.joints[full.getJointId(n)].nq == 1
                else None) for n in locked}
    return reduced, held


def lock_positions(urdf: Path, full: pin.Model, locked: list[str], lock: dict[str, float]) -> np.ndarray:
    """Configuration of the full model at which ``locked`` joints are held (the chain's entries unused)."""
    unknown = sorted(set(lock) - set(locked))
    if unknown:
        raise RobotFileError(urdf, "lock", f"no joint '{unknown[0]}' off the arm chain (locked joints: "
                             f"{', '.join(locked) or 'none'})")
    q_ref = pin.neutral(full)
    for name in locked:
        joint = full.joints[full.getJointId(name)]
        i, lo, hi = joint.idx_q, full.lowerPositionLimit[joint.idx_q], full.upperPositionLimit[joint.idx_q]
        if joint.nq != 1:
            if name in lock:
                raise RobotFileError(urdf, f"lock {name}", f"a {joint.shortname()} joint cannot be locked at one value")
            continue
        if name in lock:
            if not lo - 1e-12 <= lock[name] <= hi + 1e-12:
                raise RobotFileError(urdf, f"lock {name}", f"{lock[name]:g} is outside the joint's limits "
                                     f"[{lo:g}, {hi:g}]")
            q_ref[i] = lock[name]
        else:
            q_ref[i] = 0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi)
    return q_ref


#: how a Git LFS pointer file starts (a mesh a repository stores in LFS, cloned without it)
GIT_LFS_POINTER_START = b"version https://git-lfs"


def _unreadable_mesh(path: Path) -> str | None:
    """Why a mesh file that exists cannot be a mesh (empty, or a Git LFS pointer), else None."""
    with path.open("rb") as handle:
        start = handle.read(len(GIT_LFS_POINTER_START))
    if not start:
        return "empty"
    return "a Git LFS pointer, not the mesh" if start == GIT_LFS_POINTER_START else None


def missing_collision_meshes(urdf: Path) -> list[str]:
    """The packages (``package://NAME``) or files of collision meshes that cannot be found, and the
    files found that hold no mesh (empty, or a Git LFS pointer: ``FILE (why)``)."""
    missing = []
    for collision in ET.parse(urdf).getroot().iter("collision"):
        for mesh in collision.iter("mesh"):
            filename = mesh.get("filename", "")
            path = resolve_mesh(filename, urdf)
            if path is None:
                name = filename[len("package://"):].split("/")[0] if filename.startswith("package://") else filename
                missing.append(f"package {name}" if filename.startswith("package://") else filename)
            elif (why := _unreadable_mesh(path)) is not None:
                missing.append(f"{path} ({why})")
    return list(dict.fromkeys(missing))


def _geometry_points(model: pin.Model, urdf: Path) -> dict[int, np.ndarray]:
    """Collision-geometry points of each joint's links, in the joint frame (empty if none load, or
    if a mesh is missing: a vendor URDF whose mesh package is not installed)."""
    if missing_collision_meshes(urdf):
        return {}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            geometry = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION, package_dirs(urdf))
    except (RuntimeError, ValueError, OSError):
        return {}
    points: dict[int, list[np.ndarray]] = {}
    for obj in geometry.geometryObjects:
        shape = obj.geometry
        if hasattr(shape, "vertices"):
            local = np.asarray(shape.vertices(), float) * np.asarray(obj.meshScale, float)
        elif hasattr(shape, "halfLength"):       # cylinder / capsule along z
            r, h = shape.radius, shape.halfLength
            ring = np.array([[r * np.cos(a), r * np.sin(a)] for a in np.linspace(0, 2 * np.pi, 12)])
            local = np.vstack([np.c_[ring, np.full(12, z)] for z in (-h, h)])
        elif hasattr(shape, "halfSide"):
            local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * shape.halfSide
        elif hasattr(shape, "radius"):
            local = np.vstack([np.eye(3), -np.eye(3)]) * shape.radius
        else:
            continue
        if len(local):
            points.setdefault(int(obj.parentJoint), []).append(local @ obj.placement.rotation.T
                                                               + obj.placement.translation)
    return {j: np.vstack(p) for j, p in points.items()}


def _capsule_from_points(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Capsule around a point cloud: segment on the principal axis, radius the 95th percentile distance."""
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    axis = vt[0]
    t = (points - centre) @ axis
    radial = np.linalg.norm(points - centre - np.outer(t, axis), axis=1)
    radius = float(max(np.percentile(radial, 75), 1e-3))
    lo, hi = t.min() + radius, t.max() - radius
    if lo > hi:
        lo = hi = 0.5 * (t.min() + t.max())
    return centre + lo * axis, centre + hi * axis, radius


def fit_capsules(model: pin.Model, urdf: Path, flange: str, reach_m: float) -> tuple[list[Capsule], str]:
    """One capsule per moving link (and the base) and a sentence saying how they were made."""
    clouds = _geometry_points(model, urdf)
    capsules = []
    flange_local = model.frames[model.getFrameId(flange)].placement.translation
    for j in range(0, model.njoints):
        frame = "universe" if j == 0 else str(model.names[j])
        if j in clouds and len(clouds[j]) >= 4:
            p0, p1, radius = _capsule_from_points(clouds[j])
        elif j == 0:
            continue
        else:
            end = model.jointPlacements[j + 1].translation if j + 1 < model.njoints else flange_local
            p0, p1 = np.zeros(3), np.asarray(end, float).copy()
            radius = float(np.clip(0.25 * np.linalg.norm(p1), 0.02, 0.12 * reach_m))
        capsules.append(Capsule(f"link{j}" if j else "base", frame, p0, p1, radius))
    missing = missing_collision_meshes(urdf)
    why = (f"collision meshes not found or unreadable: {', '.join(missing)}; set ROS_PACKAGE_PATH to the folder "
           "holding them"
           if missing else "no collision geometry loaded")
    how = ("fitted to the URDF collision geometry" if clouds else
           f"from each joint to the next, radius a quarter of that length ({why})")
    return capsules, how


def _outward_sign(model: pin.Model, flange_frame: pin.Frame, last_body: list[Capsule], tie_m: float = 0.01) -> float:
    """+1 or -1: the side of the flange z axis facing away from the arm.

    1. The last body's geometry (tool, gripper, locked fingers merged into it): the side its
       capsules' mean lies on, when that lies beyond their mean radius (a body clearly on one side).
    2. Else away from the nearest joint origin upstream that is not at the flange's origin
       (``tie_m`` or more away), in the URDF's zero configuration, when it lies ``tie_m`` or more
       off the flange's xy plane.
    3. Else ``+z``."""
    if last_body:
        ends = np.array([flange_frame.placement.actInv(p) for c in last_body for p in (c.p0, c.p1)])
        mean_z, radius = float(ends[:, 2].mean()), float(np.mean([c.radius_m for c in last_body]))
        if abs(mean_z) > radius:
            return float(np.sign(mean_z))
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    flange = data.oMi[flange_frame.parentJoint] * flange_frame.placement
    for j in range(flange_frame.parentJoint, 0, -1):
        origin = flange.actInv(data.oMi[j].translation)
        if np.linalg.norm(origin) >= tie_m:
            return -1.0 if origin[2] >= tie_m else 1.0
    return 1.0


#: how far the assumed reflector stays from the surface of every capsule but its own link's: the
#: beam to the tracker must pass clear of the arm's other links (the calibration's default beam
#: margin is 20 mm), 10 mm more
REFLECTOR_BEAM_CLEARANCE_M = 0.03


def reflector_placement(model: pin.Model, flange: str, capsules: list[Capsule]) -> tuple[np.ndarray, np.ndarray]:
    """(position, opening axis) of the assumed reflector in the flange frame.

    On the flange z axis, on the side facing away from the arm (``+z`` on a ``tool0``/``flange``
    link, whose z axis points out of the flange by ROS-Industrial's REP 199; else
    :func:`_outward_sign`: ``-z`` for
    a URDF whose last link frame points back into the wrist, as Kinova's Jaco or Talos' arm),
    beyond every capsule of the last body (including locked fingers merged into it) by 10 mm, at
    least ``REFLECTOR_OFFSET_M`` from the flange. A reflector inside or behind the wrist would be
    hidden from the tracker in every pose; one that another capsule, grown by
    ``REFLECTOR_BEAM_CLEARANCE_M``, holds in most configurations (:mod:`pipeline.robot.reflector_check`:
    a wrist around the flange, or a reflector a few millimetres off the capsule of the forearm that
    turns about it, whose beam could never leave clear of that capsule) is moved further out along
    the axis."""
    flange_frame = model.frames[model.getFrameId(flange)]
    last_link = str(model.names[flange_frame.parentJoint])
    last_body = [c for c in capsules if c.frame == last_link]
    sign = 1.0 if flange in FLANGE_LINKS else _outward_sign(model, flange_frame, last_body)
    offset = REFLECTOR_OFFSET_M
    for capsule in last_body:
        ends = [flange_frame.placement.actInv(p) for p in (capsule.p0, capsule.p1)]
        offset = max(offset, max(sign * e[2] for e in ends) + capsule.radius_m + 0.01)
    axis = np.array([0.0, 0.0, sign])
    others = [c for c in capsules if c.frame != last_link]
    for _ in range(10):       # then out of every other capsule that holds it (a wrist around the flange)
        holding = [*capsules_holding(model, flange, offset * axis, last_body),
                   *capsules_holding(model, flange, offset * axis, others, REFLECTOR_BEAM_CLEARANCE_M)]
        if not holding:
            break
        offset += max(depth for _, _, depth in holding) + 0.01
    return float(offset) * axis, axis


def _floor_check_from_joint(model: pin.Model, capsules: list[Capsule], clearance_m: float = 0.06) -> int:
    """First joint (>= 2) whose capsule can leave the floor's neighbourhood: a link turning about an
    axis that stays within its capsule radius + ``clearance_m`` of the floor (a UR shoulder) is bolted
    near the floor and not checked against it."""
    data = model.createData()
    Q = np.random.default_rng(0).uniform(model.lowerPositionLimit, model.upperPositionLimit, (100, model.nq))
    heights = np.empty((len(Q), model.njoints))
    for n, q in enumerate(Q):
        pin.forwardKinematics(model, data, q)
        heights[n] = [data.oMi[j].translation[2] for j in range(model.njoints)]
    radius = {str(model.names[j]): 0.0 for j in range(model.njoints)}
    for capsule in capsules:
        radius[capsule.frame] = max(radius.get(capsule.frame, 0.0), capsule.radius_m)
    k = 2
    while (k < model.nq and np.ptp(heights[:, k]) < 1e-9
           and heights[0, k] < radius[str(model.names[k])] + clearance_m):
        k += 1
    return min(k, model.nq)


def reach_m(model: pin.Model, flange: str) -> float:
    data = model.createData()
    fid = model.getFrameId(flange)
    rng = np.random.default_rng(0)
    lo, hi = np.sort([model.lowerPositionLimit, model.upperPositionLimit], axis=0)   # swapped: refused later
    base = model.jointPlacements[1].translation
    reach = 0.0
    for q in rng.uniform(lo, hi, size=(300, model.nq)):
        pin.framesForwardKinematics(model, data, q)
        reach = max(reach, float(np.linalg.norm(data.oMf[fid].translation - base)))
    return reach


def assumed_tracker(reach_m: float) -> TrackerSpec:
    """DESIGN.md's tracker (8 µm + 3 µm/m, 30°) placed in front of the arm, scaled by its reach."""
    xyz = np.array([TRACKER_DISTANCE_REACHES * reach_m, 0.0, TRACKER_HEIGHT_REACHES * reach_m])
    return TrackerSpec(pin.SE3(np.eye(3), xyz), 8e-6, 3e-6, np.deg2rad(30.0))


def assumed_spec(urdf: Path, root: ET.Element, model: pin.Model, tip_link: str) -> tuple[RobotSpec, list[str]]:
    """RobotSpec of a URDF without robot.yaml, and the list of what was assumed (module docstring)."""
    nq = model.nq
    effort, velocity = model.effortLimit.copy(), model.velocityLimit.copy()
    gear = np.where(np.arange(nq) < 3, ARM_GEAR_RATIO, WRIST_GEAR_RATIO)
    reach = reach_m(model, tip_link)
    capsules, how = fit_capsules(model, urdf, tip_link, reach)
    tracker = assumed_tracker(reach)
    reflector_m, reflector_axis = reflector_placement(model, tip_link, capsules)
    spec = RobotSpec(
        path=urdf, name=root.get("name") or urdf.stem, urdf=urdf, flange_frame=tip_link, payload_kg=0.0,
        tool=ToolSpec(pin.SE3.Identity(), reflector_m, reflector_axis),
        actuation=ActuationSpec(gear, np.diag(gear), ROTOR_INERTIA_PER_EFFORT_S2 * effort,
                                VISCOUS_FRACTION * effort / velocity, COULOMB_FRACTION * effort,
                                np.full(nq, 0.01)),
        acceleration_rad_s2=ACCELERATION_PER_VELOCITY_1_S * velocity, limit_overrides={}, tracker=tracker,
        collision=CollisionSpec(0.0, _floor_check_from_joint(model, capsules)), capsules=capsules,
        repeatability_m=assumed_repeatability_m(reach))
    t = tracker.transform_tracker_to_base.translation
    assumptions = [
        f"no robot.yaml: the facts a URDF lacks are assumed (write one to edit: python -m pipeline robot init {urdf})",
        f"flange = tip link '{tip_link}', TCP at the flange, payload 0 kg, "
        f"reflector {np.linalg.norm(reflector_m) * 1e3:.0f} mm "
        f"along the flange {'+' if reflector_axis[2] > 0 else '-'}z axis, facing away from the arm "
        "(outside every capsule, so the beam can reach it)",
        f"gear ratios {ARM_GEAR_RATIO:g} (axes 1-3) and {WRIST_GEAR_RATIO:g} (wrist), no coupling",
        f"rotor inertia {ROTOR_INERTIA_PER_EFFORT_S2:g} s² x effort limit, viscous friction {VISCOUS_FRACTION:g} x "
        f"effort/velocity limit, Coulomb friction {COULOMB_FRACTION:.0%} of the effort limit",
        f"acceleration limits {ACCELERATION_PER_VELOCITY_1_S:g}/s x velocity limit",
        f"laser tracker at {np.round(t, 3).tolist()} m in the base frame (1.5 reaches in front), "
        "8 µm + 3 µm/m, incidence <= 30°",
        f"arm repeatability RP ±{1e3 * assumed_repeatability_m(reach):g} mm (ISO 9283; {repeatability_rule()}, "
        f"reach {reach:.2f} m)",
        f"collision capsules {how}; floor at z = 0, checked from joint {spec.collision.floor_check_from_joint} "
        "(links whose axis stays within their capsule radius + 6 cm of the floor are not checked)",
    ]
    return spec, assumptions
