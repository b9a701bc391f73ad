"""Time-sampled joint trajectories and their fine-grid torque check."""

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
