"""The hidden robot's transmissions: joint elasticity, its damping and non-linear friction.

Per joint ``i`` (joint side, rotor reflected through the gear):

* **Elasticity** (paper ``004_abbe750b8bbcc3aa.txt`` title, §2.3 and §5: "gear elasticities"): a
  spring of stiffness ``k_i`` and a damper ``d_i = 2 zeta sqrt(k_i J_red,i)`` between the rotor
  (inertia ``J_m,i`` = the model's armature) and the link; ``J_red = J_m J_l / (J_m + J_l)`` with
  ``J_l = M_ii(0)`` of the link chain without rotor inertia. ``k = inf`` is the rigid joint.
* **Friction on the motor side** (Stribeck curve with smooth sign, Armstrong-Hélouvry, Dupont and
  Canudas de Wit, Automatica 30(7), 1994, eq. for the "Stribeck friction" model)::

      f(w, tau_load) = viscous w + (F_c + (F_s - F_c) exp(-(w / w_s)^2)) tanh(w / width)
      F_c = coulomb (1 + mu |tau_load|/tau_max),   F_s = F_c (1 + x)

  ``x`` (``stribeck_excess_relative``) is the static excess over Coulomb, ``w_s`` the Stribeck
  velocity, ``mu`` (``coulomb_load_coefficient``) the growth of Coulomb friction with the
  transmitted torque measured on robot joints by Bittencourt and Gunnarsson ("Static friction in a
  robot joint - modeling and identification of load and temperature effects", J. Dyn. Sys. Meas.
  Control 134(5), 2012). Every value is 0 -> the viscous + Coulomb model of the nominal robot.

Stiffness: :func:`pipeline.robot.stiffness.nominal_joint_stiffness_Nm_rad` (robot.yaml or a cited rule).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.robot.friction import smooth_sign
from pipeline.robot.model import RobotModel

#: fixed salt of the transmission's random stream (independent of the truth's main stream)
_TRANSMISSION_SALT = 0x7472616E



@dataclass
class Transmission:
    """Per-joint transmission numbers of a robot (arrays (nq,)); see the module docstring."""

    stiffness_Nm_rad: np.ndarray          # inf: rigid joint
    damping_Nms_rad: np.ndarray
    motor_inertia_kgm2: np.ndarray        # joint side (the model's armature)
    viscous_Nms_rad: np.ndarray
    coulomb_Nm: np.ndarray
    static_excess_Nm: np.ndarray          # F_s - F_c at zero load
    stribeck_velocity_rad_s: np.ndarray
    coulomb_load_coefficient: np.ndarray  # mu: F_c grows by mu * coulomb * |tau_load| / tau_max
    effort_Nm: np.ndarray
    smoothing_rad_s: np.ndarray           # (nq,) Coulomb smoothing width

    @property
    def elastic(self) -> bool:
        return bool(np.all(np.isfinite(self.stiffness_Nm_rad)))

    @property
    def nonlinear_friction(self) -> bool:
        return bool(np.any(self.static_excess_Nm > 0) or np.any(self.coulomb_load_coefficient > 0))

    def friction_torque(self, w: np.ndarray, load_Nm: np.ndarray | float = 0.0) -> np.ndarray:
        """Friction torque at motor speed ``w`` (joint side) under transmitted torque ``load_Nm``."""
        sgn = smooth_sign(w, self.smoothing_rad_s)
        grow = 1.0 + self.coulomb_load_coefficient * np.abs(load_Nm) / self.effort_Nm
        static = self.static_excess_Nm * grow * np.exp(-(w / self.stribeck_velocity_rad_s) ** 2)
        return self.viscous_Nms_rad * w + (self.coulomb_Nm * grow + static) * sgn

    def loop_vector(self) -> np.ndarray:
        """Numbers the compiled loop takes: per joint (J_m, k, d, F_s - F_c, w_s, mu), joint-major."""
        k = np.where(np.isfinite(self.stiffness_Nm_rad), self.stiffness_Nm_rad, 0.0)
        return np.column_stack([self.motor_inertia_kgm2, k, self.damping_Nms_rad, self.static_excess_Nm,
                                self.stribeck_velocity_rad_s, self.coulomb_load_coefficient]).ravel()


def link_inertia_kgm2(robot: RobotModel, q: np.ndarray | None = None) -> np.ndarray:
    """Diagonal of the link chain's joint-space inertia (rotor inertia excluded) at ``q`` (default 0)."""
    model = robot.model.copy()
    model.armature = np.zeros(model.nv)
    q = np.zeros(model.nq) if q is None else np.asarray(q, float)
    return np.diag(pin.crba(model, model.createData(), q)).copy()


def create_transmission(truth: RobotModel, seed: int, stiffness_Nm_rad: np.ndarray, damping_ratio: float,
                        stribeck_excess_relative: float, stribeck_velocity_rad_s: float,
                        coulomb_load_coefficient: float, relative_sigma: float) -> Transmission:
    """The hidden robot's transmission: Stribeck numbers spread log-normally by ``relative_sigma`` per
    joint from a stream of its own (same seed -> same numbers; the truth's main stream is untouched)."""
    rng = np.random.default_rng([int(seed), _TRANSMISSION_SALT])
    nq = truth.nq
    act = truth.actuation
    spread = np.exp(relative_sigma * rng.standard_normal((3, nq)))
    k = np.asarray(stiffness_Nm_rad, float)
    jm = np.asarray(truth.model.armature, float).copy()
    jl = link_inertia_kgm2(truth)
    j_red = jm * jl / (jm + jl)
    d = np.where(np.isfinite(k), 2.0 * damping_ratio * np.sqrt(np.where(np.isfinite(k), k, 0.0) * j_red), 0.0)
    return Transmission(
        stiffness_Nm_rad=k, damping_Nms_rad=d, motor_inertia_kgm2=jm,
        viscous_Nms_rad=np.asarray(act.viscous_Nms_rad, float).copy(),
        coulomb_Nm=np.asarray(act.coulomb_Nm, float).copy(),
        static_excess_Nm=stribeck_excess_relative * spread[0] * act.coulomb_Nm,
        stribeck_velocity_rad_s=stribeck_velocity_rad_s * spread[1] if stribeck_velocity_rad_s > 0 else np.ones(nq),
        coulomb_load_coefficient=coulomb_load_coefficient * spread[2],
        effort_Nm=np.asarray(truth.limits.effort_Nm, float).copy(),
        smoothing_rad_s=np.asarray(act.coulomb_smoothing_rad_s, float).copy())
