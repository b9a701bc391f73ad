"""The hidden arm as a MuJoCo model: compiled from the robot's own URDF, deviations set, truth read back.

MuJoCo (Todorov, Erez, Tassa, "MuJoCo: a physics engine for model-based control", IROS 2012) is an
engine no one here wrote: its own URDF compiler, its own joint armature, viscous damping and dry
friction (``frictionloss``, a friction constraint of its solver), its own integrator.

Compilation (:func:`compile_hidden_arm`): the URDF text the nominal :class:`RobotModel` was loaded
from goes through MuJoCo's URDF compiler (``mujoco.MjSpec.from_string``) with the visuals and
collision meshes removed (meshes behind ``package://`` paths MuJoCo cannot resolve) and the joints
the model locks made fixed; ``fusestatic`` folds fixed links into their moving parent, as Pinocchio
does. Then the seeded deviations of the hidden robot (:meth:`pipeline.sim.truth.RealRobot.create`)
are written into the spec, each as the quantity MuJoCo itself has for it:

- joint placements and zero offsets: the child body's ``pos``/``quat`` relative to its parent link
  (``X_parent_link^-1 M_i exp6(d_i) exp6(S_i dq_i)``, the truth's joint placement);
- link inertias: each moving body's ``mass``, ``ipos`` and ``fullinertia`` (the truth's merged link
  inertia in the joint frame; the fused fixed links carry none, their share is in it already);
- rotor inertia -> joint ``armature``; viscous friction -> ``damping``; Coulomb -> ``frictionloss``;
- the stages' capsules as capsule geoms (no contacts: ``contype = conaffinity = 0``; the own plant has
  none either), every frame of the truth on a moving joint as a site (TCP, reflector, flange, ...),
  one motor per joint (gear 1, control range the torque limits), joint limits off (as the own plant).

What MuJoCo leaves out of the own simulator (:mod:`pipeline.sim.transmission`): elastic joints, the
Stribeck excess and the load-dependent Coulomb friction, and the cyclic gear transmission error.

Truth readback (:func:`dynamic_parameters`, :func:`joint_placements`): from the compiled ``mjModel``,
not from the numbers that went in. MuJoCo stores a body's inertia in principal axes (``body_iquat``,
diagonal ``body_inertia``) about its centre of mass ``body_ipos``; the link's rotational inertia about
the COM in the body frame is ``R diag(I) R^T``, and the 10 dynamic parameters are those of
``pin.Inertia(mass, ipos - jnt_pos, R diag(I) R^T)`` in the joint frame (``toDynamicParameters``:
``m, m c, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz`` about the joint origin).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np
import pinocchio as pin

from pipeline.core.errors import RobotFileError
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import DynamicLayout

#: what MuJoCo leaves out of the own plant (the report states it)
EFFECTS_LEFT_OUT = ("elastic joints (two-mass transmissions)", "Stribeck friction and load-dependent Coulomb friction",
                    "cyclic gear transmission error")


def mujoco_urdf(robot: RobotModel) -> str:
    """The robot's URDF text for MuJoCo's compiler: no visuals or collision meshes, locked joints fixed,
    fixed links fused into their parents, no inertia from geometry."""
    root = ET.fromstring(robot.urdf_text)
    for child in list(root):
        if child.tag not in ("link", "joint"):
            root.remove(child)
    for link in root.findall("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    moving = set(robot.model.names[1:])
    for joint in root.findall("joint"):
        if joint.get("type") != "fixed" and joint.get("name") not in moving:
            joint.set("type", "fixed")
            for tag in ("limit", "dynamics", "mimic", "axis", "safety_controller", "calibration"):
                for element in joint.findall(tag):
                    joint.remove(element)
    extension = ET.SubElement(root, "mujoco")
    ET.SubElement(extension, "compiler", fusestatic="true", discardvisual="true", inertiafromgeom="false",
                  balanceinertia="false", strippath="false")
    return ET.tostring(root, encoding="unicode")


@dataclass
class MujocoArm:
    """The compiled hidden arm: the ``mjModel`` and where the robot's joints, frames and motors are in it."""

    model: mujoco.MjModel
    joint_names: tuple[str, ...]
    qpos_address: np.ndarray     # (nq,) of the model's joints, Pinocchio order
    dof_address: np.ndarray      # (nq,)
    body_ids: np.ndarray         # (nq,) the body each joint moves
    actuator_ids: np.ndarray     # (nq,)
    site_ids: dict[str, int]     # frame name -> site id

    def site(self, frame: str) -> int:
        if frame not in self.site_ids:
            raise RobotFileError(None, f"frame {frame}", f"no site of that name in the MuJoCo arm "
                                 f"(sites: {sorted(self.site_ids)})")
        return self.site_ids[frame]


def _frame_of_link(model: pin.Model, link: str) -> pin.Frame | None:
    if model.existFrame(link, pin.FrameType.BODY):
        return model.frames[model.getFrameId(link, pin.FrameType.BODY)]
    return None


def _set_placement(element: mujoco.MjsBody, placement: pin.SE3) -> None:
    element.pos = placement.translation.copy()
    element.quat = pin.Quaternion(placement.rotation).coeffs()[[3, 0, 1, 2]].copy()   # (w, x, y, z)


def compile_hidden_arm(nominal: RobotModel, truth: RobotModel, timestep_s: float = 1e-4) -> MujocoArm:
    """Compile ``nominal``'s URDF with MuJoCo and write ``truth``'s deviations into it (module docstring)."""
    spec = mujoco.MjSpec.from_string(mujoco_urdf(nominal))
    spec.option.timestep = float(timestep_s)
    spec.compiler.discardvisual = False      # the capsules below have no contacts: keep them
    tm, act = truth.model, truth.actuation
    joint_bodies = {}
    for j in range(1, tm.njoints):
        name = tm.names[j]
        joint = spec.joint(name)
        if joint is None:
            raise RobotFileError(nominal.urdf_path, f"joint {name}", "not found by MuJoCo's URDF compiler")
        body = joint.parent
        parent = body.parent
        frame = _frame_of_link(tm, parent.name)
        parent_joint = 0 if frame is None else frame.parentJoint
        if parent_joint != tm.parents[j]:
            raise RobotFileError(nominal.urdf_path, f"joint {name}", f"MuJoCo's parent link '{parent.name}' is not on "
                                 f"the model's parent joint {tm.names[tm.parents[j]]}")
        parent_placement = pin.SE3.Identity() if frame is None else frame.placement
        _set_placement(body, parent_placement.actInv(tm.jointPlacements[j]))
        joint.pos = np.zeros(3)
        inertia = tm.inertias[j]
        body.explicitinertial = True
        body.mass = float(inertia.mass)
        body.ipos = inertia.lever.copy()
        body.iquat = np.array([1.0, 0.0, 0.0, 0.0])   # fullinertia is in the inertial frame: the URDF's rpy is gone
        Ic = inertia.inertia
        body.fullinertia = np.array([Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2]])
        k = j - 1
        joint.armature = float(tm.armature[k])
        joint.damping = np.array([float(act.viscous_Nms_rad[k]), 0.0, 0.0])   # linear term only
        joint.frictionloss = float(act.coulomb_Nm[k])
        joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
        joint_bodies[j] = body
        effort = float(truth.limits.effort_Nm[k])
        spec.add_actuator(name=f"motor_{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT,
                          ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE, ctrlrange=[-effort, effort])
    moving = {b.name for b in joint_bodies.values()}
    for body in spec.bodies:
        if body.name not in moving and body.name != "world":
            body.explicitinertial = True
            body.mass, body.ipos, body.iquat, body.inertia = 0.0, np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3)
            body.fullinertia = np.full(6, np.nan)
    world = spec.worldbody
    sites: set[str] = set()
    for f in tm.frames:
        if f.parentJoint == 0 or f.name in sites:
            continue
        site = joint_bodies[f.parentJoint].add_site(name=f.name)
        _set_placement(site, f.placement)
        sites.add(f.name)
    for capsule in nominal.capsules:
        frame = nominal.model.frames[nominal.model.getFrameId(capsule.frame)]
        ends = [frame.placement.act(np.asarray(p, float)) for p in (capsule.p0, capsule.p1)]
        holder = world if frame.parentJoint == 0 else joint_bodies[frame.parentJoint]
        if np.linalg.norm(ends[1] - ends[0]) < 1e-9:     # a capsule of zero length: a sphere
            holder.add_geom(name=f"capsule_{capsule.name}", type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=ends[0],
                            size=[capsule.radius_m, 0, 0], contype=0, conaffinity=0, mass=0.0)
        else:
            holder.add_geom(name=f"capsule_{capsule.name}", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                            fromto=np.concatenate(ends), size=[capsule.radius_m, 0, 0], contype=0, conaffinity=0,
                            mass=0.0)
    model = spec.compile()
    names = tuple(tm.names[1:])
    jids = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names])
    return MujocoArm(model, names, model.jnt_qposadr[jids].copy(), model.jnt_dofadr[jids].copy(),
                     model.jnt_bodyid[jids].copy(),
                     np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"motor_{n}") for n in names]),
                     {model.site(i).name: i for i in range(model.nsite)})


# ------------------------------------------------------------------------------- truth readback
def link_inertias(arm: MujocoArm) -> list[pin.Inertia]:
    """Each joint's link inertia in its joint frame, read from the compiled ``mjModel`` (module docstring)."""
    m = arm.model
    out = []
    for k, b in enumerate(arm.body_ids):
        flat = np.empty(9)
        mujoco.mju_quat2Mat(flat, m.body_iquat[b])
        R = flat.reshape(3, 3)
        I_com = R @ np.diag(m.body_inertia[b]) @ R.T
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, arm.joint_names[k])
        out.append(pin.Inertia(float(m.body_mass[b]), m.body_ipos[b] - m.jnt_pos[jid], 0.5 * (I_com + I_com.T)))
    return out


def dynamic_parameters(arm: MujocoArm) -> np.ndarray:
    """``p_dyn`` (SymbolicRobot layout) of the compiled arm: 10 parameters per link, armature, damping
    (viscous) and frictionloss (Coulomb), offsets zero."""
    nq = len(arm.joint_names)
    layout = DynamicLayout(nq)
    p = np.zeros(layout.size)
    for k, inertia in enumerate(link_inertias(arm)):
        p[layout.link(k + 1)] = inertia.toDynamicParameters()
    m = arm.model
    p[layout.rotor] = m.dof_armature[arm.dof_address]
    p[layout.viscous] = m.dof_damping[arm.dof_address]
    p[layout.coulomb] = m.dof_frictionloss[arm.dof_address]
    return p


def joint_placements(arm: MujocoArm) -> list[pin.SE3]:
    """Each moving body's placement in its parent body (after fusing: the parent joint's frame)."""
    m = arm.model
    out = []
    for b in arm.body_ids:
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, m.body_quat[b])
        out.append(pin.SE3(R.reshape(3, 3), m.body_pos[b].copy()))
    return out
