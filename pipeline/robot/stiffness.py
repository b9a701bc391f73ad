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

#: gearbox twist at the joint's torque limit used when robot.yaml states no stiffness (rad)
DEFLECTION_AT_TORQUE_LIMIT_RAD = 2.0e-3


def nominal_joint_stiffness_Nm_rad(robot) -> np.ndarray:
    """``(nq,)`` stiffness: robot.yaml ``actuation.joint_stiffness_Nm_rad`` or the torque-limit rule."""
    given = getattr(robot.spec.actuation, "joint_stiffness_Nm_rad", None)
    if given is not None:
        return np.asarray(given, float).copy()
    return np.asarray(robot.limits.effort_Nm, float) / DEFLECTION_AT_TORQUE_LIMIT_RAD
