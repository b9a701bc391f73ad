"""Nominal torsional joint stiffness of a serial arm (joint side, N m/rad).

``robot.yaml`` ``actuation.joint_stiffness_Nm_rad`` when the data sheet (or an identification)
gives it; otherwise a rule from the robot's own data: the joint's torque limit twists its
gearbox by :data:`DEFLECTION_AT_TORQUE_LIMIT_RAD`,

    k_i = tau_max_i / theta_ref,    theta_ref = 2 mrad.

Order of magnitude: elastostatic identifications of six-revolute industrial arms report joint
stiffnesses of 10^5 to a few 10^6 N m/rad for 10-200 kg payload arms, i.e. deflections of the
order of a milliradian at rated torque (Dumas, Caro, Garnier, Furet, "Joint stiffness
identification of six-revolute industrial serial robots", Robotics and Computer-Integrated
Manufacturing 27(4), 2011; Abele, Weigold, Rothenbücher, "Modeling and identification of an
industrial robot for machining applications", CIRP Annals 56(1), 2007). Paper
``000_bd0c20fcd494d4a1.txt`` (Outlook) names these elasticities as the next error source of a
KPI-based calibration design.
"""

from __future__ import annotations

import numpy as np

from pipeline.robot.model import RobotModel

#: gearbox twist at the joint's torque limit used when robot.yaml states no stiffness (rad)
DEFLECTION_AT_TORQUE_LIMIT_RAD = 2.0e-3


def nominal_joint_stiffness_Nm_rad(robot: RobotModel) -> np.ndarray:
    """``(nq,)`` stiffness: robot.yaml ``actuation.joint_stiffness_Nm_rad`` or the torque-limit rule."""
    given = getattr(robot.spec.actuation, "joint_stiffness_Nm_rad", None)
    if given is not None:
        return np.asarray(given, float).copy()
    return np.asarray(robot.limits.effort_Nm, float) / DEFLECTION_AT_TORQUE_LIMIT_RAD


def stiffness_for_gravity_model(stiffness_Nm_rad: np.ndarray, identified: np.ndarray, torques_fit_Nm: np.ndarray,
                                torques_new_Nm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint stiffness of an elastostatic calibration re-expressed for a better gravity model.

    The calibration models the deflection of joint ``i`` in reading ``r`` as ``c_i g_ri`` with the
    static torques ``g`` of its gravity model (``torques_fit_Nm``, (R, nq)); the joints really deflect
    by ``c'_i g'_ri`` (``torques_new_Nm``: the same readings' torques from, e.g., identified inertias).
    The least-squares compliance is the projection ``c_i = c'_i sum_r g_ri g'_ri / sum_r g_ri^2``, so

        k'_i = k_i * s_i,    s_i = sum_r g_ri g'_ri / sum_r g_ri^2

    for every ``identified`` joint (others, nominal values, are returned unchanged with ``s_i = 1``).
    A gravity-model error of x % in a joint's torque biases its stiffness by about x % (paper
    ``000_bd0c20fcd494d4a1.txt`` Outlook; Dumas et al. 2011 identify with known loads for this
    reason). First order in the compliance: the geometric parameters fitted jointly are assumed not
    to absorb the difference ``g' - g`` (a second calibration pass with ``calibration.gravity_model``
    re-fits everything). Returns ``(k', s)``; ``s`` is 1 where ``sum g g' <= 0`` (no usable load).
    """
    k = np.asarray(stiffness_Nm_rad, float).copy()
    g, g_new = np.atleast_2d(np.asarray(torques_fit_Nm, float)), np.atleast_2d(np.asarray(torques_new_Nm, float))
    num, den = np.sum(g * g_new, axis=0), np.sum(g * g, axis=0)
    use = np.asarray(identified, bool) & (den > 0) & (num > 0)
    s = np.ones_like(k)
    s[use] = num[use] / den[use]
    return k * s, s
