"""Feedforward for elastic joints: command the motors so that the *links* follow the path.

Two-mass model per joint (joint side; :mod:`pipeline.sim.elastic_dynamics`): link torque
``tau_l = M_l(q) qdd + h_l(q, qd)`` (rigid-body dynamics of the link chain without rotor inertia)
is carried by the spring, ``tau_l = k (theta - q)``, so the motor must lead the link by the
deflection. Variants (paper ``004_abbe750b8bbcc3aa.txt`` §2.3 and §5; flatness of the elastic-joint
robot: De Luca, "Feedforward/feedback laws for the control of flexible robots", ICRA 2000, and
Spong, "Modeling and control of elastic joint robots", J. Dyn. Sys. Meas. Control 109, 1987)::

    elastic_static  theta_d = q_d + tau_l(q_d, v_d, a_d) / k        (static deflection compensation)
                    omega_d = d theta_d / dt,   tau_ff = rigid full_friction torque
    elastic_flat    theta_d as above (link position is the flat output),
                    omega_d = v_d + tau_l' / k,  alpha_d = a_d + tau_l'' / k
                    tau_ff  = J_m alpha_d + tau_l + friction(omega_d)   (two-mass inverse model)

``tau_l'`` and ``tau_l''`` involve the link jerk and snap (derivatives 3 and 4 of ``q_d``); they are
taken from the sampled ``tau_l`` by Savitzky-Golay differentiation (cubic, ``window_s`` long): a
jerk-limited reference has a piecewise constant jerk, so its snap is impulsive and the smoothed
derivative is what a finite-bandwidth motor can follow. The stiffness is the model's
(:func:`pipeline.robot.stiffness.nominal_joint_stiffness_Nm_rad`: robot.yaml or the rated-torque
rule); damping is neglected in the inverse (it only delays the deflection by ``d/k`` ~ 0.3 ms).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.signal import savgol_filter

from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad

ELASTIC_VARIANTS = ("elastic_static", "elastic_flat")


def link_torque(model, q_d: np.ndarray, v_d: np.ndarray, a_d: np.ndarray) -> np.ndarray:
    """``tau_l`` (N, nq): RNEA of the link chain without rotor inertia along the reference."""
    m = model.model.copy()
    m.armature = np.zeros(m.nv)
    data = m.createData()
    return np.array([pin.rnea(m, data, q, v, a) for q, v, a in zip(q_d, v_d, a_d, strict=True)])


def _derivative(x: np.ndarray, dt: float, order: int, window_s: float) -> np.ndarray:
    w = max(5, int(round(window_s / dt)) | 1)
    if len(x) <= w:
        return np.gradient(x, dt, axis=0) if order == 1 else np.gradient(np.gradient(x, dt, axis=0), dt, axis=0)
    return savgol_filter(x, w, 3, deriv=order, delta=dt, axis=0, mode="interp")


def elastic_feedforward(model, sample_time_s: float, q_d: np.ndarray, v_d: np.ndarray, a_d: np.ndarray,
                        variant: str, rigid_tau_ff: np.ndarray, stiffness_Nm_rad: np.ndarray | None = None,
                        window_s: float = 4e-3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Motor set points ``(theta_d, omega_d, tau_ff)`` (each (N, nq)) of an elastic variant.

    ``rigid_tau_ff``: the rigid ``full_friction`` torques along the same reference (``elastic_static``
    keeps them); ``stiffness_Nm_rad`` defaults to the model's (module docstring)."""
    k = nominal_joint_stiffness_Nm_rad(model) if stiffness_Nm_rad is None else np.asarray(stiffness_Nm_rad, float)
    tau_l = link_torque(model, q_d, v_d, a_d)
    theta = q_d + tau_l / k
    if variant == "elastic_static":
        return theta, v_d + _derivative(tau_l, sample_time_s, 1, window_s) / k, rigid_tau_ff
    d1 = _derivative(tau_l, sample_time_s, 1, window_s)
    d2 = _derivative(tau_l, sample_time_s, 2, window_s)
    omega = v_d + d1 / k
    alpha = a_d + d2 / k
    tau = np.asarray(model.model.armature) * alpha + tau_l + model.friction_torque(omega)
    tau = tau + model.load_friction_torque(tau, omega)   # load: the motor torque without that term
    return theta, omega, tau
