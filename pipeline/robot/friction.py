"""Joint friction of a robot model (joint side): viscous, smooth Coulomb and, when identified, the
Stribeck excess of static over Coulomb friction.

    tau_f = f_v v + f_c tanh(v / w) + f_s exp(-(v / v_s)^2) tanh(v / w)

(Armstrong-Hélouvry, Dupont & Canudas de Wit 1994, "A survey of models, analysis tools and
compensation methods for the control of machines with friction", Automatica 30(7), the
steady-state "Stribeck" curve; ``w`` the Coulomb smoothing width of DESIGN.md). ``f_s`` and
``v_s`` are ``actuation.static_friction_excess_Nm`` and ``actuation.stribeck_velocity_rad_s``
(written by the identification with ``friction_model: stribeck``); without them the model is
viscous + Coulomb. The hidden robot's own friction is :class:`pipeline.sim.transmission.Transmission`.

Load-dependent Coulomb friction (identified when the held-out data prefer it,
``actuation.coulomb_load_coefficient`` ``fl``; Bittencourt & Gunnarsson 2012, J. Dyn. Sys. Meas.
Control 134(5)): Coulomb friction grows with the torque the transmission carries,

    tau = tau_0 + fl |tau_0| tanh(v / w),   tau_0 = rigid-body torque + tau_f

with the load torque ``tau_0`` the model's torque without this term (explicit: the same load the
identification used, :mod:`pipeline.identification.friction`). Given the applied torque ``tau`` the
load is exact: ``tau_0 = tau / (1 + c sign(tau))``, ``c = fl tanh(v / w)`` (:func:`load_free_from_applied`,
``|c| < 1``).
"""

from __future__ import annotations

import numpy as np

from pipeline.robot.spec import ActuationSpec


def smooth_sign(v: np.ndarray, width_rad_s: float | np.ndarray) -> np.ndarray:
    """``tanh(v / w)``, the Coulomb friction's smoothed sign, elementwise; ``w`` one width or one per
    joint (the last axis of ``v``); ``sign(v)`` where ``w = 0``."""
    v = np.asarray(v, float)
    w = np.broadcast_to(np.asarray(width_rad_s, float), v.shape[-1:])
    safe = np.where(w > 0, w, 1.0)
    return np.where(w > 0, np.tanh(v / safe), np.sign(v))


def stribeck_excess_torque(v: np.ndarray, fs: np.ndarray, vs: np.ndarray, width_rad_s: float | np.ndarray
                          ) -> np.ndarray:
    """``fs exp(-(v / vs)^2) tanh(v / width)`` (``sign`` for ``width = 0``; one width or one per
    joint), per joint (last axis)."""
    v = np.asarray(v, float)
    s = smooth_sign(v, width_rad_s)
    return np.asarray(fs, float) * np.exp(-((v / np.asarray(vs, float)) ** 2)) * s


#: steepest fall of ``exp(-(v / v_s)^2)`` with ``v``, times ``v_s``: ``sqrt(2 / e)`` at ``v = v_s / sqrt(2)``
STRIBECK_SLOPE_FACTOR = float(np.sqrt(2.0 / np.e))


def stribeck_slope_Nms_rad(fs: np.ndarray, vs: np.ndarray) -> np.ndarray:
    """Steepest negative slope of the Stribeck excess ``fs exp(-(v / vs)^2)`` over ``v`` (N m s/rad):
    ``sqrt(2 / e) fs / vs``. Friction falling with speed is a negative damping (stick-slip,
    Armstrong-Hélouvry, Dupont and Canudas de Wit 1994, module docstring)."""
    return STRIBECK_SLOPE_FACTOR * np.asarray(fs, float) / np.asarray(vs, float)


def has_stribeck(act: ActuationSpec) -> bool:
    """The actuation carries an identified Stribeck term (both numbers given)."""
    return act.static_friction_excess_Nm is not None and act.stribeck_velocity_rad_s is not None


def load_friction_torque(act: ActuationSpec, load_Nm: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``fl |tau_0| tanh(v / w)`` at load torques ``load_Nm`` (the model's torque without this term)
    and joint velocities ``v`` (..., nq) (module doc); zero without an identified coefficient."""
    v = np.asarray(v, float)
    if act.coulomb_load_coefficient is None:
        return np.zeros(np.broadcast_shapes(np.shape(load_Nm), v.shape))
    return act.coulomb_load_coefficient * np.abs(load_Nm) * smooth_sign(v, act.coulomb_smoothing_rad_s)


def load_free_from_applied(act: ActuationSpec, tau_Nm: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The load torque ``tau_0`` behind an applied torque ``tau = tau_0 + fl |tau_0| tanh(v / w)``:
    ``tau / (1 + c sign(tau))`` with ``c = fl tanh(v / w)`` (module doc); ``tau`` without a coefficient."""
    tau = np.asarray(tau_Nm, float)
    if act.coulomb_load_coefficient is None:
        return tau
    c = act.coulomb_load_coefficient * smooth_sign(v, act.coulomb_smoothing_rad_s)
    return tau / (1.0 + c * np.sign(tau))


def joint_friction_torque(act: ActuationSpec, v: np.ndarray) -> np.ndarray:
    """Friction torque at joint velocities ``v`` (..., nq) of the model's actuation (module doc), without
    the load-dependent term (:func:`load_friction_torque`, which needs the load torque)."""
    v = np.asarray(v, float)
    tau = act.viscous_Nms_rad * v + act.coulomb_Nm * smooth_sign(v, act.coulomb_smoothing_rad_s)
    if act.static_friction_excess_Nm is not None and act.stribeck_velocity_rad_s is not None:  # has_stribeck
        tau = tau + stribeck_excess_torque(v, act.static_friction_excess_Nm, act.stribeck_velocity_rad_s,
                                           act.coulomb_smoothing_rad_s)
    return tau
