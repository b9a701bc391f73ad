"""Symbolic twin of the robot: CasADi ``SX`` kinematics and dynamics built from a Pinocchio model.

``pinocchio.casadi`` is not in the PyPI wheel, so forward kinematics and the recursive
Newton-Euler algorithm are rebuilt here from the model's own data (``jointPlacements``, joint
motion subspaces, ``inertias``, ``armature``, ``frames``, ``gravity``); see
``docs/DESIGN.md`` section "Symbolic bridge" and ``docs/ARCHITECTURE.md``.

The parameter layouts (kinematic errors ``p_kin``, dynamic parameters ``p_dyn``) and their
numeric counterparts on a ``pin.Model`` are in :mod:`pipeline.robot.parameters`.

Gear coupling (TX40 axes 5/6, ``q_motor = K q``): the joint-side rotor inertia of coupled axes is
``K^T diag(J_motor) K`` with off-diagonal terms. Pinocchio's ``armature`` and this bridge keep a
diagonal rotor inertia per joint (its diagonal); the coupling terms, if wanted, are the
identification stage's business (add a column ``d tau / d J`` built from ``K`` to the regressor).
Nothing here depends on ``K``.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pipeline.core import codegen
from pipeline.core.errors import PipelineError, RobotFileError
from pipeline.robot import spatial_sx as sx
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import (
    DEFAULT_COULOMB_SMOOTHING_RAD_S,
    DEFAULT_FLANGE_FRAME,
    DEFAULT_TOOL_FRAMES,
    DynamicLayout,
    KinematicLayout,
    SymbolicArg,
    _check_vector,
    _frame_id,
    _model_name,
    dynamic_parameter_names,
    joint_infos,
    kinematic_parameter_names,
    pinocchio_dynamic_parameters,
)

JIT_FLAGS = ("-O2",)


# --------------------------------------------------------------------------------------------
# Optional JIT: C code generation + gcc, cached on disk
# --------------------------------------------------------------------------------------------


def compile_function(function: ca.Function, cache_dir: Path | None = None) -> ca.Function:
    """``function`` compiled with gcc and cached (:func:`pipeline.core.codegen.compile_function`)."""
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
        robot: RobotModel | pin.Model,
        *,
        flange_frame: str | None = None,
        tool_frames: Sequence[str] | None = None,
        coulomb_smoothing_rad_s: float | npt.ArrayLike | None = None,
        viscous_Nms_rad: npt.ArrayLike | None = None,
        coulomb_Nm: npt.ArrayLike | None = None,
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
        viscous = (getattr(actuation, "viscous_Nms_rad", np.zeros(self.nq)) if viscous_Nms_rad is None
                   else viscous_Nms_rad)
        coulomb = getattr(actuation, "coulomb_Nm", np.zeros(self.nq)) if coulomb_Nm is None else coulomb_Nm
        width = np.broadcast_to(np.asarray(coulomb_smoothing_rad_s, float), (self.nq,)).copy()
        if not np.all(width > 0):
            raise PipelineError(
                None, "coulomb_smoothing_rad_s", f"must be positive, got {coulomb_smoothing_rad_s}"
            )
        self.flange_frame = flange_frame
        self.tool_frames = tuple(tool_frames)
        #: (nq,) the Coulomb smoothing width per joint (rad/s)
        self.coulomb_smoothing_rad_s = width
        self._viscous = _check_vector(viscous, self.nq, "viscous_Nms_rad")
        self._coulomb = _check_vector(coulomb, self.nq, "coulomb_Nm")
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
        self._cache: dict[Hashable, ca.Function] = {}

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the built functions (compiled ones cannot travel); rebuilt lazily."""
        state = self.__dict__.copy()
        state["_cache"] = {}
        return state

    @classmethod
    def from_robot(cls, robot: RobotModel | pin.Model, *, jit: bool = False,
                   **kwargs: Any) -> SymbolicRobot:  # Any: keyword arguments of __init__, forwarded
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

    def _function(self, key: Hashable, build: Callable[[], ca.Function]) -> ca.Function:
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
        self, q: SymbolicArg, v: SymbolicArg, a: SymbolicArg, p_dyn: SymbolicArg, gravity: bool = True,
        placements: Sequence[tuple[SymbolicArg, SymbolicArg]] | None = None,
    ) -> ca.SX:
        """``M(q) a + C(q, v) v [+ g(q)] + Ia a``: RNEA (Featherstone 2008, table 5.1) with the
        inertial parameters and rotor inertia of ``p_dyn`` (friction/offset not included).
        ``placements``: the joints' placements ``(R, p)`` in their parents (e.g. symbols, so that one
        expression serves every calibration of the arm); default the model's own."""
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
            placement = (info.rotation, info.translation) if placements is None else placements[i - 1]
            rot, pos = sx.compose(placement, (rot_j, pos_j))
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

    def friction_expression(self, v: SymbolicArg, p_dyn: SymbolicArg) -> SymbolicArg:
        """``fv v + fc tanh(v / width)`` (smooth Coulomb, width ``coulomb_smoothing_rad_s``)."""
        return p_dyn[self.dyn.viscous] * v + p_dyn[self.dyn.coulomb] * ca.tanh(
            v / ca.DM(self.coulomb_smoothing_rad_s)
        )

    def inverse_dynamics_expression(self, q: SymbolicArg, v: SymbolicArg, a: SymbolicArg, p_dyn: SymbolicArg,
                                    placements: Sequence[tuple[SymbolicArg, SymbolicArg]] | None = None,
                                    coulomb: bool = True) -> ca.SX:
        """Full joint torque: rigid body + rotor + friction + offset. ``placements``: as in
        :meth:`rigid_body_torque_expression`; ``coulomb=False``: viscous friction only (for a caller
        that adds the Coulomb term with its own smoothing width)."""
        friction = self.friction_expression(v, p_dyn) if coulomb else p_dyn[self.dyn.viscous] * v
        return (
            self.rigid_body_torque_expression(q, v, a, p_dyn, gravity=True, placements=placements)
            + friction
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
