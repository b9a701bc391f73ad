"""Symbolic twin of the robot: CasADi ``SX`` kinematics and dynamics built from a Pinocchio model.

``pinocchio.casadi`` is not in the PyPI wheel, so forward kinematics and the recursive
Newton-Euler algorithm are rebuilt here from the model's own data (``jointPlacements``, joint
motion subspaces, ``inertias``, ``armature``, ``frames``, ``gravity``); see
``/work/shared/DESIGN.md`` section "Symbolic bridge" and ``docs/ARCHITECTURE.md``.

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

Gear coupling (TX40 axes 5/6, ``q_motor = K q``): the joint-side rotor inertia of coupled axes is
``K^T diag(J_motor) K`` with off-diagonal terms. Pinocchio's ``armature`` and this bridge keep a
diagonal rotor inertia per joint (its diagonal); the coupling terms, if wanted, are the
identification stage's business (add a column ``d tau / d J`` built from ``K`` to the regressor).
Nothing here depends on ``K``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from pipeline import codegen
from pipeline.errors import PipelineError, RobotFileError
from pipeline.robot import spatial_sx as sx

KINEMATIC_COMPONENTS = ("dx", "dy", "dz", "rx", "ry", "rz")
INERTIAL_COMPONENTS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
DEFAULT_FLANGE_FRAME = "flange"
DEFAULT_TOOL_FRAMES = ("tcp", "reflector")
DEFAULT_COULOMB_SMOOTHING_RAD_S = 0.01
JIT_FLAGS = ("-O2",)


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

    def motion(self, q: Any) -> tuple[ca.SX, ca.SX]:
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


def _check_vector(x: Any, size: int, field: str) -> np.ndarray:
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
    p_kin: Any,
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
    viscous_Nms_rad: Any = None,
    coulomb_Nm: Any = None,
    offset_Nm: Any = None,
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


def dynamic_parameter_problems(p_dyn: Any, nq: int) -> list[str]:
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


def set_dynamic_parameters(model: pin.Model, p_dyn: Any) -> pin.Model:
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


# --------------------------------------------------------------------------------------------
# Optional JIT: C code generation + gcc, cached on disk
# --------------------------------------------------------------------------------------------


def compile_function(function: ca.Function, cache_dir: Path | None = None) -> ca.Function:
    """``function`` compiled with gcc and cached (:func:`pipeline.codegen.compile_function`)."""
    return codegen.compile_function(function, subdir="casadi", flags=JIT_FLAGS, cache_dir=cache_dir)


# --------------------------------------------------------------------------------------------
# The symbolic robot
# --------------------------------------------------------------------------------------------


class SymbolicRobot:
    """CasADi ``SX`` forward kinematics with error parameters, inverse dynamics, regressor and
    mass matrix of a Pinocchio model.

    ``SymbolicRobot(robot)`` with a ``RobotModel`` (frames ``robot.frame_flange/tcp/reflector``,
    friction and ``coulomb_smoothing_rad_s`` from ``robot.actuation``), or
    ``SymbolicRobot(model, flange_frame=..., tool_frames=..., coulomb_smoothing_rad_s=...,
    viscous_Nms_rad=..., coulomb_Nm=...)`` with a bare ``pin.Model`` (friction defaults to 0).
    Keyword arguments override the values taken from a ``RobotModel``.

    All functions are built once (lazily) and cached. Called with SX/MX arguments they inline
    into an NLP; ``f.map(N)`` evaluates them on N columns. With ``jit=True`` the functions are
    compiled by gcc (cached on disk, see :func:`compile_function`); compiled functions take
    numeric or MX arguments only.
    """

    def __init__(
        self,
        robot: Any,
        *,
        flange_frame: str | None = None,
        tool_frames: Sequence[str] | None = None,
        coulomb_smoothing_rad_s: float | None = None,
        viscous_Nms_rad: Any = None,
        coulomb_Nm: Any = None,
        jit: bool = False,
        cache_dir: Path | str | None = None,
    ) -> None:
        if isinstance(robot, pin.Model):
            model = robot
            robot_model = None
        elif hasattr(robot, "model") and isinstance(robot.model, pin.Model):
            model = robot.model
            robot_model = robot
        else:
            raise TypeError("SymbolicRobot needs a RobotModel or a pinocchio.Model")
        self.robot = robot_model
        self.model: pin.Model = model
        self.joints = joint_infos(model)
        self.nq = len(self.joints)
        self.kin = KinematicLayout(self.nq)
        self.dyn = DynamicLayout(self.nq)

        actuation = getattr(robot_model, "actuation", None)
        if flange_frame is None:
            flange_frame = getattr(robot_model, "frame_flange", DEFAULT_FLANGE_FRAME)
        if tool_frames is None:
            if robot_model is not None:
                tool_frames = (
                    getattr(robot_model, "frame_tcp", "tcp"),
                    getattr(robot_model, "frame_reflector", "reflector"),
                )
            else:
                tool_frames = tuple(f for f in DEFAULT_TOOL_FRAMES if model.existFrame(f))
        if coulomb_smoothing_rad_s is None:
            coulomb_smoothing_rad_s = getattr(
                actuation, "coulomb_smoothing_rad_s", DEFAULT_COULOMB_SMOOTHING_RAD_S
            )
        if viscous_Nms_rad is None:
            viscous_Nms_rad = getattr(actuation, "viscous_Nms_rad", np.zeros(self.nq))
        if coulomb_Nm is None:
            coulomb_Nm = getattr(actuation, "coulomb_Nm", np.zeros(self.nq))
        if not coulomb_smoothing_rad_s > 0:
            raise PipelineError(
                None, "coulomb_smoothing_rad_s", f"must be positive, got {coulomb_smoothing_rad_s}"
            )
        self.flange_frame = flange_frame
        self.tool_frames = tuple(tool_frames)
        self.coulomb_smoothing_rad_s = float(coulomb_smoothing_rad_s)
        self._viscous = _check_vector(viscous_Nms_rad, self.nq, "viscous_Nms_rad")
        self._coulomb = _check_vector(coulomb_Nm, self.nq, "coulomb_Nm")
        self._flange_id = _frame_id(model, flange_frame) if self.tool_frames else None
        for name in self.tool_frames:
            fid = _frame_id(model, name)
            if model.frames[fid].parentJoint != model.frames[self._flange_id].parentJoint:
                raise RobotFileError(
                    _model_name(model),
                    f"frame {name}",
                    f"tool frame must hang on the joint of frame {flange_frame}",
                )
        self.jit = bool(jit)
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        self.gravity_linear = np.array(model.gravity.linear, dtype=float)
        self.gravity_angular = np.array(model.gravity.angular, dtype=float)
        self._cache: dict[Any, ca.Function] = {}

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the built functions (compiled ones cannot travel); rebuilt lazily."""
        state = self.__dict__.copy()
        state["_cache"] = {}
        return state

    @classmethod
    def from_robot(cls, robot: Any, *, jit: bool = False, **kwargs: Any) -> SymbolicRobot:
        """Same as ``SymbolicRobot(robot, jit=jit, **kwargs)``."""
        return cls(robot, jit=jit, **kwargs)

    # ----------------------------------------------------------------- names and parameters

    @property
    def kinematic_parameter_names(self) -> list[str]:
        return kinematic_parameter_names(self.nq)

    @property
    def dynamic_parameter_names(self) -> list[str]:
        return dynamic_parameter_names(self.nq)

    @property
    def n_kin(self) -> int:
        return self.kin.size

    @property
    def n_dyn(self) -> int:
        return self.dyn.size

    def nominal_kinematic_parameters(self) -> np.ndarray:
        """Zero errors."""
        return np.zeros(self.n_kin)

    def nominal_dynamic_parameters(self) -> np.ndarray:
        """``p_dyn`` of the model: inertias, armature, friction of the robot, zero offsets."""
        return pinocchio_dynamic_parameters(self.model, self._viscous, self._coulomb)

    # ----------------------------------------------------------------- function cache

    def _function(self, key: Any, build) -> ca.Function:
        if key not in self._cache:
            f = build()
            if self.jit:
                f = compile_function(f, self.cache_dir)
            self._cache[key] = f
        return self._cache[key]

    # ----------------------------------------------------------------- kinematics

    def _joint_pose_world(
        self, q: ca.SX, p_kin: ca.SX, joint: int, memo: dict[int, tuple[ca.SX, ca.SX]]
    ) -> tuple[ca.SX, ca.SX]:
        if joint in memo:
            return memo[joint]
        if joint == 0:
            pose = sx.exp6(p_kin[self.kin.base])
        else:
            info = self.joints[joint - 1]
            parent = self._joint_pose_world(q, p_kin, info.parent, memo)
            placement = sx.compose(
                (info.rotation, info.translation), sx.exp6(p_kin[self.kin.placement(joint)])
            )
            angle = q[info.idx_v] + p_kin[self.kin.joint_offsets][info.idx_v]
            local = sx.compose(placement, info.motion(angle))
            pose = sx.compose(parent, local)
        memo[joint] = pose
        return pose

    def fk_expression(self, frame: str, q: ca.SX, p_kin: ca.SX) -> tuple[ca.SX, ca.SX]:
        """World position (3,1) and rotation (3,3) of ``frame`` as SX expressions."""
        fid = _frame_id(self.model, frame)
        fr = self.model.frames[fid]
        pose = self._joint_pose_world(q, p_kin, int(fr.parentJoint), {})
        placement = sx.se3_numeric(fr.placement)
        if frame in self.tool_frames:
            flange = sx.se3_numeric(self.model.frames[self._flange_id].placement)
            flange_to_frame = sx.se3_numeric(
                self.model.frames[self._flange_id].placement.inverse() * fr.placement
            )
            pose = sx.compose(pose, flange)
            pose = sx.compose(pose, sx.exp6(p_kin[self.kin.tool]))
            pose = sx.compose(pose, flange_to_frame)
        else:
            pose = sx.compose(pose, placement)
        rot, pos = pose
        return pos, rot

    def fk(self, frame: str = "tcp") -> ca.Function:
        """``ca.Function("fk", [q (nq), p_kin (n_kin)], [p (3), R (3x3)])`` of ``frame``."""

        def build() -> ca.Function:
            q = ca.SX.sym("q", self.nq)
            p_kin = ca.SX.sym("p_kin", self.n_kin)
            pos, rot = self.fk_expression(frame, q, p_kin)
            return ca.Function("fk", [q, p_kin], [pos, rot], ["q", "p_kin"], ["p", "R"])

        return self._function(("fk", frame), build)

    def fk_position_jacobian(self, frame: str = "tcp") -> ca.Function:
        """``ca.Function("fk_jac", [q, p_kin], [J_kin (3 x n_kin), J_q (3 x nq)])``: the
        identification Jacobian ``d p / d p_kin`` and ``d p / d q`` of the frame position."""

        def build() -> ca.Function:
            q = ca.SX.sym("q", self.nq)
            p_kin = ca.SX.sym("p_kin", self.n_kin)
            pos, _ = self.fk_expression(frame, q, p_kin)
            return ca.Function(
                "fk_jac",
                [q, p_kin],
                [ca.jacobian(pos, p_kin), ca.jacobian(pos, q)],
                ["q", "p_kin"],
                ["J_kin", "J_q"],
            )

        return self._function(("fk_jac", frame), build)

    def fk_position_and_jacobian(self, frame: str = "tcp") -> ca.Function:
        """``ca.Function("fk_pos_jac", [q, p_kin], [p (3), J_kin (3 x n_kin), J_q (3 x nq)])``
        (one call for Gauss-Newton / Levenberg-Marquardt steps)."""

        def build() -> ca.Function:
            q = ca.SX.sym("q", self.nq)
            p_kin = ca.SX.sym("p_kin", self.n_kin)
            pos, _ = self.fk_expression(frame, q, p_kin)
            return ca.Function(
                "fk_pos_jac",
                [q, p_kin],
                [pos, ca.jacobian(pos, p_kin), ca.jacobian(pos, q)],
                ["q", "p_kin"],
                ["p", "J_kin", "J_q"],
            )

        return self._function(("fk_pos_jac", frame), build)

    # ----------------------------------------------------------------- dynamics

    def rigid_body_torque_expression(
        self, q: Any, v: Any, a: Any, p_dyn: Any, gravity: bool = True
    ) -> ca.SX:
        """``M(q) a + C(q, v) v [+ g(q)] + Ia a``: RNEA (Featherstone 2008, table 5.1) with the
        inertial parameters and rotor inertia of ``p_dyn`` (friction/offset not included)."""
        q, v, a, p_dyn = (ca.SX(x) if not isinstance(x, ca.SX) else x for x in (q, v, a, p_dyn))
        zero = ca.SX.zeros(3, 1)
        nj = self.nq + 1
        vel: list[tuple[ca.SX, ca.SX]] = [(zero, zero)] * nj
        acc: list[tuple[ca.SX, ca.SX]] = [(zero, zero)] * nj
        if gravity:
            acc[0] = (ca.SX(-self.gravity_linear.reshape(3, 1)),
                      ca.SX(-self.gravity_angular.reshape(3, 1)))
        forces: list[tuple[ca.SX, ca.SX]] = [(zero, zero)] * nj
        poses: list[tuple[ca.SX, ca.SX]] = [(ca.SX.eye(3), zero)] * nj
        for info in self.joints:
            i, k = info.index, info.idx_v
            rot_j, pos_j = info.motion(q[k])
            rot, pos = sx.compose((info.rotation, info.translation), (rot_j, pos_j))
            poses[i] = (rot, pos)
            s_lin = ca.SX(info.s_linear.reshape(3, 1))
            s_ang = ca.SX(info.s_angular.reshape(3, 1))
            vj_lin, vj_ang = s_lin * v[k], s_ang * v[k]
            vp_lin, vp_ang = sx.motion_act_inv(rot, pos, *vel[info.parent])
            vi = (vp_lin + vj_lin, vp_ang + vj_ang)
            ap_lin, ap_ang = sx.motion_act_inv(rot, pos, *acc[info.parent])
            c_lin, c_ang = sx.motion_cross(vi[0], vi[1], vj_lin, vj_ang)
            ai = (ap_lin + s_lin * a[k] + c_lin, ap_ang + s_ang * a[k] + c_ang)
            vel[i], acc[i] = vi, ai
            pi = p_dyn[self.dyn.link(i)]
            f_a = sx.inertia_apply(pi, *ai)
            h = sx.inertia_apply(pi, *vi)
            f_c = sx.force_cross(vi[0], vi[1], *h)
            forces[i] = (f_a[0] + f_c[0], f_a[1] + f_c[1])
        tau: list[Any] = [None] * self.nq
        rotor = p_dyn[self.dyn.rotor]
        for info in reversed(self.joints):
            i, k = info.index, info.idx_v
            f_lin, f_ang = forces[i]
            tau[k] = (
                ca.dot(ca.SX(info.s_linear), f_lin)
                + ca.dot(ca.SX(info.s_angular), f_ang)
                + rotor[k] * a[k]
            )
            if info.parent != 0:
                fp = sx.force_act(*poses[i], f_lin, f_ang)
                parent = forces[info.parent]
                forces[info.parent] = (parent[0] + fp[0], parent[1] + fp[1])
        return ca.vertcat(*tau)

    def friction_expression(self, v: Any, p_dyn: Any) -> ca.SX:
        """``fv v + fc tanh(v / width)`` (smooth Coulomb, width ``coulomb_smoothing_rad_s``)."""
        return p_dyn[self.dyn.viscous] * v + p_dyn[self.dyn.coulomb] * ca.tanh(
            v / self.coulomb_smoothing_rad_s
        )

    def inverse_dynamics_expression(self, q: Any, v: Any, a: Any, p_dyn: Any) -> ca.SX:
        """Full joint torque: rigid body + rotor + friction + offset."""
        return (
            self.rigid_body_torque_expression(q, v, a, p_dyn, gravity=True)
            + self.friction_expression(v, p_dyn)
            + p_dyn[self.dyn.offset]
        )

    def _symbols(self) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        return (
            ca.SX.sym("q", self.nq),
            ca.SX.sym("v", self.nq),
            ca.SX.sym("a", self.nq),
            ca.SX.sym("p_dyn", self.n_dyn),
        )

    @property
    def rnea(self) -> ca.Function:
        """``ca.Function("rnea", [q, v, a, p_dyn], [tau])``."""

        def build() -> ca.Function:
            q, v, a, p = self._symbols()
            tau = self.inverse_dynamics_expression(q, v, a, p)
            return ca.Function("rnea", [q, v, a, p], [tau], ["q", "v", "a", "p_dyn"], ["tau"])

        return self._function("rnea", build)

    @property
    def regressor(self) -> ca.Function:
        """``ca.Function("regressor", [q, v, a], [Y (nq x n_dyn)])`` with ``tau = Y p_dyn``."""

        def build() -> ca.Function:
            q, v, a, p = self._symbols()
            y = ca.jacobian(self.inverse_dynamics_expression(q, v, a, p), p)
            return ca.Function("regressor", [q, v, a], [y], ["q", "v", "a"], ["Y"])

        return self._function("regressor", build)

    @property
    def mass_matrix(self) -> ca.Function:
        """``ca.Function("M", [q, p_dyn], [M (nq x nq)])`` including rotor inertia."""

        def build() -> ca.Function:
            q, _, a, p = self._symbols()
            tau = self.rigid_body_torque_expression(q, ca.SX.zeros(self.nq), a, p, gravity=False)
            m = ca.jacobian(tau, a)
            m = 0.5 * (m + m.T)
            return ca.Function("M", [q, p], [m], ["q", "p_dyn"], ["M"])

        return self._function("M", build)

    @property
    def gravity(self) -> ca.Function:
        """``ca.Function("gravity", [q, p_dyn], [g (nq)])`` (``pin.computeGeneralizedGravity``)."""

        def build() -> ca.Function:
            q, _, _, p = self._symbols()
            z = ca.SX.zeros(self.nq)
            g = self.rigid_body_torque_expression(q, z, z, p, gravity=True)
            return ca.Function("gravity", [q, p], [g], ["q", "p_dyn"], ["g"])

        return self._function("gravity", build)

    @property
    def coriolis(self) -> ca.Function:
        """``ca.Function("coriolis", [q, v, p_dyn], [C(q, v) v])`` (no gravity, no friction)."""

        def build() -> ca.Function:
            q, v, _, p = self._symbols()
            c = self.rigid_body_torque_expression(q, v, ca.SX.zeros(self.nq), p, gravity=False)
            return ca.Function("coriolis", [q, v, p], [c], ["q", "v", "p_dyn"], ["c"])

        return self._function("coriolis", build)

    @property
    def nonlinear_effects(self) -> ca.Function:
        """``ca.Function("nle", [q, v, p_dyn], [C(q, v) v + g(q)])`` (``pin.nonLinearEffects``)."""

        def build() -> ca.Function:
            q, v, _, p = self._symbols()
            h = self.rigid_body_torque_expression(q, v, ca.SX.zeros(self.nq), p, gravity=True)
            return ca.Function("nle", [q, v, p], [h], ["q", "v", "p_dyn"], ["h"])

        return self._function("nle", build)

    @property
    def friction(self) -> ca.Function:
        """``ca.Function("friction", [v, p_dyn], [fv v + fc tanh(v / width)])`` (no offset)."""

        def build() -> ca.Function:
            _, v, _, p = self._symbols()
            f = self.friction_expression(v, p)
            return ca.Function("friction", [v, p], [f], ["v", "p_dyn"], ["tau_f"])

        return self._function("friction", build)
