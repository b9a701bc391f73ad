"""Speed and acceleration of the TCP along a joint trajectory (limits of the excitation).

Paper ``004_abbe750b8bbcc3aa.txt`` §4.3: the excitation of the RX130L reached "velocities up to
5 m/s and accelerations up to 12 m/s^2" at the end effector. With ``p(q)`` the TCP position,

    p_dot  = J(q) v                          (J = dp/dq, the translational Jacobian)
    p_ddot = J(q) a + (d(J v)/dq) v          (the classical, not the spatial, acceleration)

The numeric version uses Pinocchio (``getFrameVelocity`` / ``getFrameClassicalAcceleration``,
LOCAL_WORLD_ALIGNED); the symbolic one differentiates the symbolic bridge's FK with CasADi, so
the excitation NLP can bound ``|p_dot|^2`` and ``|p_ddot|^2`` per sample.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin

from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot


def tcp_speed_acceleration(robot: RobotModel, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray,
                           np.ndarray]:
    """``(|p_dot|, |p_ddot|)`` of the TCP at every sample (m/s, m/s^2), each (N,)."""
    model, data = robot.model, robot.new_data()
    fid = model.getFrameId(robot.frame_tcp)
    n = len(q)
    speed, acc = np.empty(n), np.empty(n)
    for k in range(n):
        pin.forwardKinematics(model, data, q[k], v[k], a[k])
        speed[k] = np.linalg.norm(pin.getFrameVelocity(model, data, fid, pin.LOCAL_WORLD_ALIGNED).linear)
        acc[k] = np.linalg.norm(pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).linear)
    return speed, acc


def tcp_motion_sx(robot: RobotModel, sym: SymbolicRobot, q: ca.SX, v: ca.SX, a: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``(|p_dot|^2, |p_ddot|^2)`` of the TCP as SX expressions of ``q, v, a`` (nominal kinematics)."""
    pos, _ = sym.fk(robot.frame_tcp)(q, ca.DM(sym.nominal_kinematic_parameters()))
    jac = ca.jacobian(pos, q)
    p_dot = ca.mtimes(jac, v)
    p_ddot = ca.mtimes(jac, a) + ca.mtimes(ca.jacobian(p_dot, q), v)
    return ca.sumsqr(p_dot), ca.sumsqr(p_ddot)
