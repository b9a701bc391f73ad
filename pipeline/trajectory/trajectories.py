"""Time-sampled joint trajectories, their fine-grid torque check and the time scaling into the limits."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.trajectory.dynamics import PlanningModel, max_violation, torque_ratio


@dataclass
class JointTrajectory:
    """Joint positions, velocities, accelerations sampled at times ``t_s`` (rows)."""

    name: str
    t_s: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])


@dataclass
class TorqueCheck:
    """Full-model torques on a fine grid: ``ratio = |tau| / tau_max``, velocity ratio likewise."""

    t_s: np.ndarray
    tau_Nm: np.ndarray
    torque_ratio: np.ndarray
    velocity_ratio: np.ndarray
    max_torque_ratio: float
    violation: float
    max_velocity_ratio: float
    energy: float  # int sum(w_i tau_i^2) dt with the given weights (trapezoid)
    max_acceleration_ratio: float = 0.0   # max |a| / robot.limits.acceleration_rad_s2

    def summary(self) -> dict:
        return {"max_torque_ratio": self.max_torque_ratio, "violation": self.violation,
                "max_velocity_ratio": self.max_velocity_ratio, "energy": self.energy,
                "max_acceleration_ratio": self.max_acceleration_ratio}


def check_trajectory(pm: PlanningModel, traj: JointTrajectory, friction: bool = True,
                     energy_weights: np.ndarray | None = None) -> TorqueCheck:
    """Recompute torques of a sampled trajectory with the full model (or rigid body only)."""
    tau = pm.torques(traj.q, traj.v, traj.a) if friction else pm.rigid_torques(traj.q, traj.v, traj.a)
    ratio = torque_ratio(pm, tau)
    vratio = np.abs(traj.v) / pm.velocity_rad_s
    w = np.ones(pm.nq) if energy_weights is None else np.asarray(energy_weights, float)
    energy = float(np.trapezoid((tau**2) @ w, traj.t_s))
    aratio = float((np.abs(traj.a) / pm.acceleration_rad_s2).max())
    return TorqueCheck(traj.t_s, tau, ratio, vratio, float(ratio.max()), max_violation(ratio),
                       float(vratio.max()), energy, aratio)


def time_scaled(traj: JointTrajectory, factor: float, name: str | None = None) -> JointTrajectory:
    """The same path ``factor`` times slower: ``t' = factor t``, ``v' = v / factor``, ``a' = a / factor^2``
    (``info["time_scale"]``: the product of all scalings)."""
    info = {**traj.info, "time_scale": float(traj.info.get("time_scale", 1.0)) * float(factor)}
    return JointTrajectory(name or traj.name, traj.t_s[0] + factor * (traj.t_s - traj.t_s[0]), traj.q.copy(),
                           traj.v / factor, traj.a / factor**2, info)


#: fine-grid limit ratios above 1 by less than this are round-off; a plan handed on in place of our
#: solvers' (the PtP slowed into its limits, ruckig's or toppra's profile) keeps its limits to this
#: accuracy, while the gates accept ``violation_tolerance``, the slack of our solvers' grids
FINE_GRID_ROUNDOFF = 1e-4


def within_limits(check: TorqueCheck, tolerance: float, acceleration_limits: bool) -> bool:
    return bool(check.violation <= tolerance and check.max_velocity_ratio <= 1.0 + tolerance
                and (not acceleration_limits or check.max_acceleration_ratio <= 1.0 + tolerance))


def slowed_into_limits(pm: PlanningModel, traj: JointTrajectory, tolerance: float, acceleration_limits: bool = True,
                       energy_weights: np.ndarray | None = None) -> tuple[JointTrajectory, TorqueCheck]:
    """``traj`` and its fine-grid check when within the limits (ratios <= 1 + ``tolerance``), else the
    same path slowed down (:func:`time_scaled`; bisection on the factor to ~1e-5) until it is. A plan
    that 4x slower still breaks a limit (a static torque: slowing does not help) is returned at that
    speed, for the stage's gate to report."""
    check = check_trajectory(pm, traj, energy_weights=energy_weights)
    if within_limits(check, tolerance, acceleration_limits):
        return traj, check
    lo, hi = 1.0, 1.05
    while not within_limits(check_trajectory(pm, time_scaled(traj, hi)), tolerance, acceleration_limits):
        lo, hi = hi, 1.0 + 2.0 * (hi - 1.0)
        if hi > 4.0:
            break                     # left to the stage's gate
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        ok = within_limits(check_trajectory(pm, time_scaled(traj, mid)), tolerance, acceleration_limits)
        lo, hi = (lo, mid) if ok else (mid, hi)
    slowed = time_scaled(traj, hi, traj.name)
    return slowed, check_trajectory(pm, slowed, energy_weights=energy_weights)
