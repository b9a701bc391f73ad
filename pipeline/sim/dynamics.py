"""CasADi SX forward dynamics (articulated-body algorithm) with the model numbers as inputs.

Featherstone's ABA (Rigid Body Dynamics Algorithms, 2008, ch. 7) written in Pinocchio's
conventions (spatial motion ``[v; w]``, local joint frames, ``model.armature`` added to the
joint-space articulated inertia ``D_i``), for serial chains of revolute joints::

    qdd = ABA(q, v, tau - friction(v)),   tau saturated at +-effort limit,
    friction(v) = viscous * v + coulomb * tanh(v / width)

The placements, inertias, rotor inertia, friction and torque limits are *inputs* (a parameter
vector ``p``), so one compiled function serves the nominal, identified and hidden models alike.
Paper ``004_abbe750b8bbcc3aa.txt`` §2.3: "the real robot is integrated between samples with ABA
plus rotor inertia and friction" (DESIGN.md, Control).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np
import pinocchio as pin

from pipeline.core.errors import RobotFileError
from pipeline.robot.model import RobotModel

PARAMS_PER_JOINT = 12 + 10 + 4  # placement (R row-major, p), inertia (10), armature, viscous, coulomb, effort


@dataclass(frozen=True)
class ChainStructure:
    """What the generated code depends on: number of joints, parents and joint axes."""

    nq: int
    parents: tuple[int, ...]
    axes: tuple[tuple[float, float, float], ...]

    def key(self) -> str:
        return hashlib.sha256(repr(self).encode()).hexdigest()[:16]

    @property
    def n_params(self) -> int:
        return self.nq * PARAMS_PER_JOINT + 3 + self.nq  # + gravity (3) + coulomb smoothing width per joint


_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}


def chain_structure(model: pin.Model) -> ChainStructure:
    """Structure of a Pinocchio model; raises RobotFileError for non-revolute joints."""
    axes = []
    for j in range(1, model.njoints):
        name = model.joints[j].shortname()
        if name in _AXES:
            axes.append(_AXES[name])
        elif name == "JointModelRevoluteUnaligned":
            a = model.joints[j].extract().axis
            axes.append((float(a[0]), float(a[1]), float(a[2])))
        else:
            raise RobotFileError(model.name or "model", f"joint {model.names[j]}",
                                 f"joint type {name} not supported by the control plant (revolute only)")
    if model.nq != model.njoints - 1 or model.nv != model.nq:
        raise RobotFileError(model.name or "model", "joints", "control plant needs nq == nv == joints")
    return ChainStructure(model.nq, tuple(int(p) for p in model.parents[1:]), tuple(axes))


def parameter_vector(robot: RobotModel) -> np.ndarray:
    """Pack a RobotModel's dynamics into the input vector of :func:`forward_dynamics_function`."""
    m: pin.Model = robot.model
    act = robot.actuation
    rows = []
    for j in range(1, m.njoints):
        M = m.jointPlacements[j]
        i = j - 1
        rows.append(np.concatenate([
            np.asarray(M.rotation).reshape(-1), np.asarray(M.translation),
            m.inertias[j].toDynamicParameters(),
            [m.armature[i], act.viscous_Nms_rad[i], act.coulomb_Nm[i], robot.limits.effort_Nm[i]],
        ]))
    return np.concatenate([*rows, np.asarray(m.gravity.linear),
                           np.broadcast_to(np.asarray(act.coulomb_smoothing_rad_s, float), (m.nv,))])


def _skew(x: ca.SX | ca.DM) -> ca.SX:
    return ca.vertcat(ca.horzcat(0, -x[2], x[1]), ca.horzcat(x[2], 0, -x[0]), ca.horzcat(-x[1], x[0], 0))


def _rot_axis(axis: tuple[float, float, float], q: ca.SX) -> ca.SX:
    c, s = ca.cos(q), ca.sin(q)
    if axis == (0.0, 0.0, 1.0):
        return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    if axis == (1.0, 0.0, 0.0):
        return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))
    if axis == (0.0, 1.0, 0.0):
        return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))
    a = ca.DM(axis)
    K = _skew(a)
    return ca.DM.eye(3) + s * K + (1 - c) * (K @ K)


def _inertia_matrix(pi: ca.SX) -> ca.SX:
    """Spatial inertia [lin; ang] about the frame origin from Pinocchio's 10 dynamic parameters."""
    m, h = pi[0], pi[1:4]
    ixx, ixy, iyy, ixz, iyz, izz = pi[4], pi[5], pi[6], pi[7], pi[8], pi[9]
    Io = ca.vertcat(ca.horzcat(ixx, ixy, ixz), ca.horzcat(ixy, iyy, iyz), ca.horzcat(ixz, iyz, izz))
    H = _skew(h)
    return ca.vertcat(ca.horzcat(m * ca.SX.eye(3), -H), ca.horzcat(H, Io))


def _unpack(p: ca.SX, s: ChainStructure) -> tuple[list[dict[str, ca.SX]], ca.SX, ca.SX]:
    n = PARAMS_PER_JOINT
    joints = []
    for i in range(s.nq):
        b = p[i * n:(i + 1) * n]
        joints.append(dict(R=ca.reshape(b[0:9], 3, 3).T, t=b[9:12], pi=b[12:22], armature=b[22],
                           viscous=b[23], coulomb=b[24], effort=b[25]))
    g = p[s.nq * n:s.nq * n + 3]
    width = p[s.nq * n + 3:s.nq * n + 3 + s.nq]
    return joints, g, width


def friction_sx(v: ca.SX, p: ca.SX, s: ChainStructure) -> ca.SX:
    joints, _, width = _unpack(p, s)
    return ca.vertcat(*[j["viscous"] * v[i] + j["coulomb"] * ca.tanh(v[i] / width[i]) for i, j in enumerate(joints)])


def effort_sx(p: ca.SX, s: ChainStructure) -> ca.SX:
    joints, _, _ = _unpack(p, s)
    return ca.vertcat(*[j["effort"] for j in joints])


def aba_sx(q: ca.SX, v: ca.SX, tau: ca.SX, p: ca.SX, s: ChainStructure) -> ca.SX:
    """Joint accelerations of the rigid chain with rotor inertia for joint torques ``tau``."""
    joints, g, _ = _unpack(p, s)
    n = s.nq
    R: list[ca.SX] = []
    t: list[ca.SX] = []
    S: list[ca.DM] = []
    vel: list[ca.SX] = []
    c: list[ca.SX] = []
    IA: list[ca.SX] = []
    pA: list[ca.SX] = []
    for i in range(n):  # pass 1: kinematics, bias forces
        jt = joints[i]
        Ri = jt["R"] @ _rot_axis(s.axes[i], q[i])   # child -> parent rotation
        ti = jt["t"]
        R.append(Ri)
        t.append(ti)
        ax = ca.DM(s.axes[i])
        S.append(ca.vertcat(ca.DM.zeros(3), ax))
        par = s.parents[i] - 1
        wj = ax * v[i]
        if par < 0:
            v_lin, v_ang = ca.SX.zeros(3), wj
            ci = ca.SX.zeros(6)
        else:
            pv, pw = vel[par][:3], vel[par][3:]
            w_c = Ri.T @ pw
            v_c = Ri.T @ (pv - ca.cross(ti, pw))
            v_lin, v_ang = v_c, w_c + wj
            # c = v x (S qd) = [v_lin x wj ; v_ang x wj]  (motion cross product with (0, wj))
            ci = ca.vertcat(ca.cross(v_lin, wj), ca.cross(v_ang, wj))
        vel.append(ca.vertcat(v_lin, v_ang))
        c.append(ci)
        Yi = _inertia_matrix(jt["pi"])
        IA.append(Yi)
        h = Yi @ vel[i]
        # v x* h = [w x f ; w x n + v x f]
        pA.append(ca.vertcat(ca.cross(v_ang, h[:3]), ca.cross(v_ang, h[3:]) + ca.cross(v_lin, h[:3])))
    U: list[ca.SX] = [ca.SX.zeros(6)] * n        # each set below before it is read
    D: list[ca.SX] = [ca.SX.zeros(1)] * n
    u: list[ca.SX] = [ca.SX.zeros(1)] * n
    for i in reversed(range(n)):  # pass 2: articulated inertias
        U[i] = IA[i] @ S[i]
        D[i] = ca.dot(S[i], U[i]) + joints[i]["armature"]
        u[i] = tau[i] - ca.dot(S[i], pA[i])
        par = s.parents[i] - 1
        if par >= 0:
            inv_d = 1.0 / D[i]
            Ud = U[i] * inv_d
            Ui, IAi = U[i], IA[i]

            def articulated(r: int, c_: int, Ud: ca.SX = Ud, Ui: ca.SX = Ui, IAi: ca.SX = IAi) -> ca.SX:
                return IAi[r, c_] - Ud[r] * Ui[c_]

            Ia = _sym(articulated)
            pa = pA[i] + Ia @ c[i] + Ud * u[i]
            IA[par] = IA[par] + _inertia_to_parent(Ia, R[i], t[i])
            pA[par] = pA[par] + _force_to_parent(R[i], t[i], pa)
    a_prev = {-1: ca.vertcat(-g, ca.DM.zeros(3))}
    qdd = []
    for i in range(n):  # pass 3: accelerations
        par = s.parents[i] - 1
        ap = a_prev[par]
        if par < 0:
            a_i = _apply_inverse(R[i], t[i], ap)
        else:
            a_i = _apply_inverse(R[i], t[i], ap) + c[i]
        qddi = (u[i] - ca.dot(U[i], a_i)) / D[i]
        qdd.append(qddi)
        a_prev[i] = a_i + S[i] * qddi
    return ca.vertcat(*qdd)


def _sym(entry: Callable[[int, int], ca.SX]) -> ca.SX:
    """6x6 symmetric SX matrix from ``entry(r, c)`` evaluated for r <= c only."""
    M = ca.SX(6, 6)
    for r in range(6):
        for c in range(r, 6):
            M[r, c] = entry(r, c)
            if c != r:
                M[c, r] = M[r, c]
    return M


def _rot_sym(R: ca.SX, A: ca.SX) -> ca.SX:
    """R A R^T for symmetric 3x3 A, upper triangle computed once."""
    RA = R @ A
    M = ca.SX(3, 3)
    for r in range(3):
        for c in range(r, 3):
            M[r, c] = ca.dot(RA[r, :].T, R[c, :].T)
            if c != r:
                M[c, r] = M[r, c]
    return M


def _inertia_to_parent(Ia: ca.SX, R: ca.SX, t: ca.SX) -> ca.SX:
    """X^T Ia X for the motion transform X parent -> child (rotation R child->parent, origin t).

    With Ia = [[A, B], [B^T, C]] ([lin; ang]), A' = R A R^T, B' = R B R^T, C' = R C R^T, T = [t]x:
    [[A', K], [K^T, C' - B'^T T + T K]] with K = B' - A' T.
    """
    A, B, C = Ia[:3, :3], Ia[:3, 3:], Ia[3:, 3:]
    Ap, Cp = _rot_sym(R, A), _rot_sym(R, C)
    Bp = R @ B @ R.T
    T = _skew(t)
    K = Bp - Ap @ T
    BR = Cp - Bp.T @ T + T @ K
    Mbr = ca.SX(3, 3)
    for r in range(3):
        for c in range(r, 3):
            Mbr[r, c] = BR[r, c]
            if c != r:
                Mbr[c, r] = BR[r, c]
    return ca.vertcat(ca.horzcat(Ap, K), ca.horzcat(K.T, Mbr))


def _force_to_parent(R: ca.SX, t: ca.SX, f: ca.SX) -> ca.SX:
    """Force [f; n] from child to parent coordinates: [R f; R n + t x R f]."""
    fl = R @ f[:3]
    return ca.vertcat(fl, R @ f[3:] + ca.cross(t, fl))


def _apply_inverse(R: ca.SX, t: ca.SX, m: ca.SX) -> ca.SX:
    v, w = m[:3], m[3:]
    return ca.vertcat(R.T @ (v - ca.cross(t, w)), R.T @ w)


def forward_dynamics_function(s: ChainStructure) -> ca.Function:
    """``fd(q, v, tau_cmd, p) -> qdd`` with saturation, friction and rotor inertia."""
    q, v, tau = ca.SX.sym("q", s.nq), ca.SX.sym("v", s.nq), ca.SX.sym("tau", s.nq)
    p = ca.SX.sym("p", s.n_params)
    eff = effort_sx(p, s)
    tau_sat = ca.fmin(ca.fmax(tau, -eff), eff)
    qdd = aba_sx(q, v, tau_sat - friction_sx(v, p, s), p, s)
    return ca.Function("fd", [q, v, tau, p], [qdd], ["q", "v", "tau", "p"], ["qdd"])
