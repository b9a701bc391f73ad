"""Numeric dynamics for trajectory planning: limits, friction, path coefficients, torque checks.

Everything here is plain Pinocchio on numpy arrays (DESIGN.md "Measured facts": numeric
Pinocchio calls are cheap, batch them).  The rigid-body part comes from ``pin.rnea`` (which
includes the joint-side rotor inertia ``model.armature``), evaluated for many samples at once by
``pin.rneaInParallel`` on one thread (the loop runs in C++: about half the time of a Python loop of
``pin.rnea`` calls, same numbers), the friction part is

    tau_f = F_v * qdot + F_c * tanh(qdot / w)                       (DESIGN.md, "Symbolic bridge")

Path coefficients (Verscheure et al. 2009, used in paper 004 section 5.1): along a joint path
``q(s)`` with ``sdot``, ``sddot``

    tau(s) = m(s) sddot + c(s) sdot^2 + g(s) + F_v q'(s) sdot + F_c tanh(q'(s) sdot / w)
    m = M(q) q',   c = M(q) q'' + C(q, q') q',   g = g(q)

computed with the rnea tricks  g = rnea(q, 0, 0),  m = rnea(q, 0, q') - g,
c = rnea(q, q', q'') - g.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from pipeline.core.errors import ConfigError
from pipeline.robot.friction import smooth_sign
from pipeline.robot.model import RobotModel

#: joint path derivatives smaller than this are treated as "joint does not move" (Coulomb sign).
QPRIME_ZERO = 1e-9


@dataclass
class PlanningModel:
    """What the planners need from a robot: Pinocchio model, limits and friction (joint side)."""

    model: pin.Model
    lower_rad: np.ndarray
    upper_rad: np.ndarray
    velocity_rad_s: np.ndarray
    effort_Nm: np.ndarray
    viscous_Nms_rad: np.ndarray
    coulomb_Nm: np.ndarray
    coulomb_smoothing_rad_s: np.ndarray  # (nq,) rad/s
    acceleration_rad_s2: np.ndarray
    robot: RobotModel = None  # the RobotModel it was made from (IK, FK, symbolic bridge), if any
    _pool: pin.ModelPool | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @classmethod
    def from_robot(cls, robot: RobotModel, torque_reserve: float = 0.0) -> PlanningModel:
        """Build from a :class:`pipeline.robot.model.RobotModel` (docs/ARCHITECTURE.md).

        ``torque_reserve`` (fraction) is kept free for the feedback controller: the planners see
        ``effort_Nm = (1 - torque_reserve) * limit``. The friction is viscous + Coulomb: an identified
        Stribeck excess and load-dependent Coulomb friction (``actuation.coulomb_load_coefficient`` fl,
        which adds at most ``fl |tau|``, fl of order 1e-3..1e-2) are left out of the plan; the reserve
        covers them (the control stage's feedforward evaluates both).
        """
        if not 0.0 <= torque_reserve < 1.0:
            raise ConfigError(None, "trajectory.torque_reserve", f"must be in [0, 1), got {torque_reserve}")
        lim, act = robot.limits, robot.actuation
        return cls(
            model=robot.model,
            lower_rad=np.asarray(lim.lower_rad, float),
            upper_rad=np.asarray(lim.upper_rad, float),
            velocity_rad_s=np.asarray(lim.velocity_rad_s, float),
            effort_Nm=np.asarray(lim.effort_Nm, float) * (1.0 - torque_reserve),
            viscous_Nms_rad=np.asarray(act.viscous_Nms_rad, float),
            coulomb_Nm=np.asarray(act.coulomb_Nm, float),
            coulomb_smoothing_rad_s=np.asarray(act.coulomb_smoothing_rad_s, float).copy(),
            acceleration_rad_s2=np.asarray(lim.acceleration_rad_s2, float),
            robot=robot,
        )

    def friction(self, v: np.ndarray) -> np.ndarray:
        """Viscous plus smooth Coulomb friction, ``v`` of shape (..., nq)."""
        v = np.asarray(v, float)
        return self.viscous_Nms_rad * v + self.coulomb_Nm * smooth_sign(v, self.coulomb_smoothing_rad_s)

    def rigid_torques(self, Q: np.ndarray, V: np.ndarray, A: np.ndarray) -> np.ndarray:
        """Rigid-body (incl. rotor inertia) torques for rows of Q, V, A: (N, nq)."""
        Q, V, A = (np.atleast_2d(np.asarray(x, float)) for x in (Q, V, A))
        return rnea_rows(self, Q, V, A)

    def torques(self, Q: np.ndarray, V: np.ndarray, A: np.ndarray) -> np.ndarray:
        """Full model: rigid body + viscous + smooth Coulomb friction, (N, nq)."""
        return self.rigid_torques(Q, V, A) + self.friction(np.atleast_2d(V))

    def mass_diagonal(self, q: np.ndarray) -> np.ndarray:
        data = self.model.createData()
        return np.diag(pin.crba(self.model, data, np.asarray(q, float))).copy()


@dataclass
class PathCoefficients:
    """``tau = m sddot + c sdot^2 + g`` (+ friction in q' sdot) sampled at path parameters ``s``."""

    s: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    m: np.ndarray
    c: np.ndarray
    g: np.ndarray


#: below this many samples a Python loop of ``pin.rnea`` is cheaper than setting up the batch
_BATCH_MIN = 16


def rnea_rows(pm: PlanningModel, Q: np.ndarray, V: np.ndarray, A: np.ndarray) -> np.ndarray:
    """``pin.rnea`` for every row of Q, V, A (N, nq) -> (N, nq); one C++ loop for large N."""
    n = Q.shape[0]
    if n < _BATCH_MIN:
        data = pm.model.createData()
        return np.array([pin.rnea(pm.model, data, Q[k], V[k], A[k]) for k in range(n)]).reshape(n, pm.nq)
    if pm._pool is None:
        pm._pool = pin.ModelPool(pm.model, 1)
    tau = np.zeros((pm.nq, n))
    pin.rneaInParallel(1, pm._pool, np.ascontiguousarray(Q.T), np.ascontiguousarray(V.T),
                       np.ascontiguousarray(A.T), tau)
    return tau.T.copy()


def path_coefficients(pm: PlanningModel, s: np.ndarray, q: np.ndarray, dq: np.ndarray,
                      ddq: np.ndarray) -> PathCoefficients:
    """m(s), c(s), g(s) of the path by three rnea calls per sample (see module docstring)."""
    n = len(s)
    zero = np.zeros((n, pm.nq))
    Q, D1, D2 = (np.asarray(x, float).reshape(n, pm.nq) for x in (q, dq, ddq))
    tau = rnea_rows(pm, np.vstack([Q, Q, Q]), np.vstack([zero, zero, D1]), np.vstack([zero, D1, D2]))
    g = tau[:n]
    return PathCoefficients(np.asarray(s, float), q, dq, ddq, tau[n:2 * n] - g, tau[2 * n:] - g, g)


def torque_ratio(pm: PlanningModel, tau: np.ndarray) -> np.ndarray:
    """|tau| / tau_max, (N, nq)."""
    return np.abs(tau) / pm.effort_Nm


def max_violation(ratio: np.ndarray) -> float:
    """Relative violation max(0, max ratio - 1)."""
    return float(max(0.0, np.max(ratio) - 1.0))
