"""Robot parameter layouts and their numeric counterparts on a Pinocchio model.

Kinematic error parameters ``p_kin`` (zero = nominal), layout (``nq`` one-dof joints):

- ``j{i}.dx dy dz rx ry rz`` for i = 1..nq: SE(3) offset right-multiplied onto the placement of
  joint i in its parent, ``M_i' = M_i exp6([dx, dy, dz, rx, ry, rz])`` (linear part first, like
  ``pin.exp6``);
- ``j{i}.dq``: joint zero offsets, the joint moves by ``q_i + dq_i``;
- ``base.dx .. base.rz``: left-multiplied onto everything attached to the universe,
  ``oMi = exp6(base) M_1' ...``;
- ``tool.dx .. tool.rz``: offset of the tool on the flange, applied to the tool frames
  (``tcp``, ``reflector``): ``oMf = oM_flange exp6(tool) (flange^-1 f)``; the flange frame itself
  and every other frame do not see it.

Errors enter as exact SE(3) exponentials, so the identification Jacobian
``d p / d p_kin`` at ``p_kin = 0`` is the exact linearisation used by calibration
(papers/002_2f409157c2a376aa.txt identification Jacobian; papers/003_16198f1660ab3739.txt POE
error model). ``apply_kinematic_errors`` writes the same errors into a ``pin.Model`` so that
``pin.forwardKinematics`` on it equals ``SymbolicRobot.fk`` with those errors.

Dynamic parameters ``p_dyn`` (length ``14 nq``):
``10 nq`` inertial parameters, per link ``[m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]``
(``pin.Inertia.toDynamicParameters`` order, inertia about the joint frame origin), then rotor
inertia (joint side, Pinocchio ``armature``), viscous, Coulomb and torque offset (``nq`` each):

    tau = RNEA(q, v, a; inertials) + Ia a + fv v + fc tanh(v / width) + tau0

which is linear in ``p_dyn``, so the regressor ``Y(q, v, a) = d tau / d p_dyn`` satisfies
``tau = Y p_dyn`` exactly (papers/004_abbe750b8bbcc3aa.txt, section 2.2; DESIGN.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pipeline.core.errors import PipelineError, RobotFileError
from pipeline.robot import spatial_sx as sx

KINEMATIC_COMPONENTS = ("dx", "dy", "dz", "rx", "ry", "rz")
INERTIAL_COMPONENTS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
DEFAULT_FLANGE_FRAME = "flange"
DEFAULT_TOOL_FRAMES = ("tcp", "reflector")
DEFAULT_COULOMB_SMOOTHING_RAD_S = 0.01
#: what the SX builders take for a joint or parameter vector: a CasADi symbol or numbers
SymbolicArg = ca.SX | np.ndarray


# --------------------------------------------------------------------------------------------
# Model introspection
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class JointInfo:
    """A one-dof joint of the model: kind, unit axis (in its own frame), parent, placement."""

    index: int  # Pinocchio joint index (1..njoints-1)
    parent: int
    idx_v: int
    kind: str  # "revolute" or "prismatic"
    axis: np.ndarray  # (3,) unit
    rotation: np.ndarray  # (3,3) of jointPlacements[index]
    translation: np.ndarray  # (3,1)

    @property
    def s_linear(self) -> np.ndarray:
        return self.axis if self.kind == "prismatic" else np.zeros(3)

    @property
    def s_angular(self) -> np.ndarray:
        return self.axis if self.kind == "revolute" else np.zeros(3)

    def motion(self, q: SymbolicArg) -> tuple[ca.SX, ca.SX]:
        """Joint transform ``exp6(S q)`` as ``(R, p)``."""
        if self.kind == "revolute":
            return sx.rotation_about_axis(self.axis, q), ca.SX.zeros(3, 1)
        return ca.SX.eye(3), ca.SX(self.axis.reshape(3, 1)) * q


def _model_name(model: pin.Model) -> str:
    return model.name or "pinocchio model"


def joint_infos(model: pin.Model) -> list[JointInfo]:
    """Describe every joint; only one-dof revolute/prismatic joints (any axis) are supported."""
    if model.nq != model.nv or model.nq != model.njoints - 1:
        raise RobotFileError(
            _model_name(model),
            "joints",
            f"the symbolic bridge needs one-dof joints only (nq={model.nq}, nv={model.nv}, "
            f"joints={model.njoints - 1})",
        )
    infos = []
    for i in range(1, model.njoints):
        joint = model.joints[i]
        if joint.nq != 1 or joint.nv != 1:
            raise RobotFileError(
                _model_name(model), f"joint {model.names[i]}", f"unsupported joint {joint.shortname()}"
            )
        data = joint.createData()
        joint.calc(data, np.zeros(1))
        s = np.array(data.S, dtype=float).reshape(6)
        lin, ang = s[:3], s[3:]
        if np.linalg.norm(lin) < 1e-12 and abs(np.linalg.norm(ang) - 1.0) < 1e-12:
            kind, axis = "revolute", ang
        elif np.linalg.norm(ang) < 1e-12 and abs(np.linalg.norm(lin) - 1.0) < 1e-12:
            kind, axis = "prismatic", lin
        else:
            raise RobotFileError(
                _model_name(model),
                f"joint {model.names[i]}",
                f"unsupported joint {joint.shortname()} (motion subspace {s.tolist()})",
            )
        rot, trans = sx.se3_numeric(model.jointPlacements[i])
        infos.append(
            JointInfo(
                index=i,
                parent=int(model.parents[i]),
                idx_v=int(joint.idx_v),
                kind=kind,
                axis=axis.copy(),
                rotation=rot,
                translation=trans,
            )
        )
    return infos


def kinematic_parameter_names(nq: int) -> list[str]:
    """Names of the kinematic error parameters (layout in the module docstring)."""
    names = [f"j{i}.{c}" for i in range(1, nq + 1) for c in KINEMATIC_COMPONENTS]
    names += [f"j{i}.dq" for i in range(1, nq + 1)]
    names += [f"base.{c}" for c in KINEMATIC_COMPONENTS]
    names += [f"tool.{c}" for c in KINEMATIC_COMPONENTS]
    return names


def dynamic_parameter_names(nq: int) -> list[str]:
    """Names of the dynamic parameters (layout in the module docstring)."""
    names = [f"link{i}.{c}" for i in range(1, nq + 1) for c in INERTIAL_COMPONENTS]
    for kind in ("rotor_inertia", "viscous", "coulomb", "offset"):
        names += [f"j{i}.{kind}" for i in range(1, nq + 1)]
    return names


@dataclass(frozen=True)
class KinematicLayout:
    """Slices of ``p_kin``; ``placement(i)`` is the 6-vector of joint i (1-based)."""

    nq: int

    @property
    def size(self) -> int:
        return 7 * self.nq + 12

    def placement(self, i: int) -> slice:
        return slice(6 * (i - 1), 6 * i)

    @property
    def joint_placements(self) -> slice:
        return slice(0, 6 * self.nq)

    @property
    def joint_offsets(self) -> slice:
        return slice(6 * self.nq, 7 * self.nq)

    @property
    def base(self) -> slice:
        return slice(7 * self.nq, 7 * self.nq + 6)

    @property
    def tool(self) -> slice:
        return slice(7 * self.nq + 6, 7 * self.nq + 12)


@dataclass(frozen=True)
class DynamicLayout:
    """Slices of ``p_dyn``; ``link(i)`` is the 10-vector of link i (1-based)."""

    nq: int

    @property
    def size(self) -> int:
        return 14 * self.nq

    def link(self, i: int) -> slice:
        return slice(10 * (i - 1), 10 * i)

    @property
    def inertial(self) -> slice:
        return slice(0, 10 * self.nq)

    @property
    def rotor(self) -> slice:
        return slice(10 * self.nq, 11 * self.nq)

    @property
    def viscous(self) -> slice:
        return slice(11 * self.nq, 12 * self.nq)

    @property
    def coulomb(self) -> slice:
        return slice(12 * self.nq, 13 * self.nq)

    @property
    def offset(self) -> slice:
        return slice(13 * self.nq, 14 * self.nq)


def _check_vector(x: npt.ArrayLike, size: int, field: str) -> np.ndarray:
    arr = np.asarray(x, dtype=float).reshape(-1)
    if arr.size != size:
        raise PipelineError(None, field, f"expected {size} values, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise PipelineError(None, field, "contains non-finite values")
    return arr


def _frame_id(model: pin.Model, name: str) -> int:
    if not model.existFrame(name):
        raise RobotFileError(_model_name(model), f"frame {name}", "no such frame in the model")
    return model.getFrameId(name)


# --------------------------------------------------------------------------------------------
# Numeric helpers: kinematic errors and dynamic parameters on a pin.Model
# --------------------------------------------------------------------------------------------


def apply_kinematic_errors(
    model: pin.Model,
    p_kin: npt.ArrayLike,
    flange_frame: str = DEFAULT_FLANGE_FRAME,
    tool_frames: Sequence[str] = DEFAULT_TOOL_FRAMES,
) -> pin.Model:
    """Return a copy of ``model`` whose joint placements and frames include the errors ``p_kin``.

    ``jointPlacements[i] <- [exp6(base) if parent is the universe] M_i exp6(d_i) exp6(S_i dq_i)``,
    frames on the universe are left-multiplied by ``exp6(base)``, and each tool frame ``f``
    becomes ``M_flange exp6(tool) M_flange^-1 M_f`` (``M_*`` placements in joint 6). Then
    ``pin.forwardKinematics`` + ``updateFramePlacements`` on the result equals
    ``SymbolicRobot.fk(frame)(q, p_kin)``. Inertias stay attached to their (displaced) joint
    frames, i.e. links move rigidly with the errors.
    """
    infos = joint_infos(model)
    layout = KinematicLayout(len(infos))
    p = _check_vector(p_kin, layout.size, "p_kin")
    out = model.copy()
    base = pin.exp6(p[layout.base])
    for info in infos:
        i = info.index
        s = np.concatenate([info.s_linear, info.s_angular])
        dq = p[layout.joint_offsets][info.idx_v]
        placement = model.jointPlacements[i] * pin.exp6(p[layout.placement(i)]) * pin.exp6(s * dq)
        if info.parent == 0:
            placement = base * placement
        out.jointPlacements[i] = placement
    for fid, frame in enumerate(model.frames):
        if frame.parentJoint == 0:
            out.frames[fid].placement = base * frame.placement
    if tool_frames:
        flange = model.frames[_frame_id(model, flange_frame)]
        tool = pin.exp6(p[layout.tool])
        for name in tool_frames:
            fid = _frame_id(model, name)
            frame = model.frames[fid]
            if frame.parentJoint != flange.parentJoint:
                raise RobotFileError(
                    _model_name(model),
                    f"frame {name}",
                    f"tool frame must hang on the joint of frame {flange_frame}",
                )
            out.frames[fid].placement = (
                flange.placement * tool * flange.placement.inverse() * frame.placement
            )
    return out


def pinocchio_dynamic_parameters(
    model: pin.Model,
    viscous_Nms_rad: npt.ArrayLike | None = None,
    coulomb_Nm: npt.ArrayLike | None = None,
    offset_Nm: npt.ArrayLike | None = None,
) -> np.ndarray:
    """``p_dyn`` (``14 nq``) of a model: its inertias and armature, friction/offset as given (0)."""
    infos = joint_infos(model)
    nq = len(infos)
    layout = DynamicLayout(nq)
    p = np.zeros(layout.size)
    for info in infos:
        p[layout.link(info.index)] = model.inertias[info.index].toDynamicParameters()
    p[layout.rotor] = np.asarray(model.armature, dtype=float)
    for values, sl, field in (
        (viscous_Nms_rad, layout.viscous, "viscous_Nms_rad"),
        (coulomb_Nm, layout.coulomb, "coulomb_Nm"),
        (offset_Nm, layout.offset, "offset_Nm"),
    ):
        if values is not None:
            p[sl] = _check_vector(values, nq, field)
    return p


def dynamic_parameter_problems(p_dyn: npt.ArrayLike, nq: int) -> list[str]:
    """Physical-consistency problems of ``p_dyn``: mass <= 0, pseudo-inertia not positive
    definite (Wensing et al. 2017 LMI), negative rotor inertia, viscous or Coulomb friction.
    An empty list means physically consistent."""
    layout = DynamicLayout(nq)
    p = _check_vector(p_dyn, layout.size, "p_dyn")
    names = dynamic_parameter_names(nq)
    problems = []
    for i in range(1, nq + 1):
        pi = p[layout.link(i)]
        m, h = pi[0], pi[1:4]
        inertia = np.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])
        if m <= 0:
            problems.append(f"link{i}.m: mass {m:.6g} kg is not positive")
            continue
        sigma = 0.5 * np.trace(inertia) * np.eye(3) - inertia
        pseudo = np.block([[sigma, h.reshape(3, 1)], [h.reshape(1, 3), np.array([[m]])]])
        if np.linalg.eigvalsh(pseudo).min() < -1e-12 * max(1.0, abs(m)):
            problems.append(f"link{i}: pseudo-inertia not positive semi-definite")
    for sl in (layout.rotor, layout.viscous, layout.coulomb):
        for k in np.flatnonzero(p[sl] < 0):
            problems.append(f"{names[sl.start + k]}: negative value {p[sl][k]:.6g}")
    return problems


def set_dynamic_parameters(model: pin.Model, p_dyn: npt.ArrayLike) -> pin.Model:
    """Copy of ``model`` with inertias (``pin.Inertia.FromDynamicParameters``) and armature from
    ``p_dyn``. Friction and torque offsets are not part of a ``pin.Model``: the caller keeps them.

    Raises :class:`PipelineError` if a link mass is not positive (not representable as a
    ``pin.Inertia``); other physical-consistency checks: :func:`dynamic_parameter_problems`.
    """
    infos = joint_infos(model)
    nq = len(infos)
    layout = DynamicLayout(nq)
    p = _check_vector(p_dyn, layout.size, "p_dyn")
    out = model.copy()
    for info in infos:
        pi = p[layout.link(info.index)]
        if pi[0] <= 0:
            raise PipelineError(
                None, f"p_dyn[link{info.index}.m]", f"mass {pi[0]:.6g} kg must be positive"
            )
        out.inertias[info.index] = pin.Inertia.FromDynamicParameters(pi)
    out.armature = p[layout.rotor].copy()
    return out
