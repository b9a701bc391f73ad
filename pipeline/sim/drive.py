"""The stand-in arm's own drives: factory tuning and set-point timing for motions played from outside.

A real arm that replays a logged or exported motion runs it under its drives' own tuning, not a
stage's. This is that drive (used by the MuJoCo arm's ``execute_joint_trajectory`` and by
``python -m pipeline arm play``), the cascade of paper 004 §2.3 with the control stage's default
numbers (``pipeline.control.config.ControlConfig``; the sim layer cannot import a stage):

- gains from the reflected inertia ``J = diag M(q_ref)`` of the model the drive was tuned on:
  ``Kv = J w_v``, ``Ki = Kv w_v / n``, ``Kp = w_p`` (the rule of ``pipeline.control.design``);
- velocity estimate low-pass ``alpha = 1 - exp(-2 pi f_c T_v)``;
- set points sent ahead by the known set-point delay (they arrive on time), the feedback set point
  aligned with the delayed measurement, per velocity sub-sample the velocity set point delayed like
  the estimate (``T_v / 2 + (1 - alpha) / alpha T_v``) and the feedforward torque at the middle of
  the hold (both interpolated linearly);
- a motion that starts at rest is preceded by ``settle_time_s`` of holding its first sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicHermiteSpline

from pipeline.core.errors import ConfigError
from pipeline.robot.model import RobotModel


@dataclass(frozen=True)
class DriveSettings:
    sample_time_s: float = 4e-4
    velocity_samples: int = 2
    measurement_delay_samples: int = 1
    position_bandwidth_hz: float = 5.0
    velocity_bandwidth_hz: float = 30.0
    pi_zero_ratio: float = 4.0
    velocity_filter_hz: float = 150.0
    settle_time_s: float = 0.3

    @property
    def velocity_sample_time_s(self) -> float:
        return self.sample_time_s / self.velocity_samples

    @property
    def alpha(self) -> float:
        return float(1.0 - np.exp(-2 * np.pi * self.velocity_filter_hz * self.velocity_sample_time_s))


def drive_gains(robot: RobotModel, q_ref: np.ndarray, settings: DriveSettings) -> dict[str, np.ndarray]:
    """``kp``, ``kv``, ``ki`` of the cascade tuned on ``robot`` at ``q_ref`` (module docstring)."""
    J = np.diag(pin.crba(robot.model, robot.model.createData(), np.asarray(q_ref, float))).copy()
    wv, wp = 2 * np.pi * settings.velocity_bandwidth_hz, 2 * np.pi * settings.position_bandwidth_hz
    kv = J * wv
    return {"kp": np.full_like(J, wp), "kv": kv, "ki": kv * wv / settings.pi_zero_ratio}


@dataclass
class DriveInputs:
    """What reaches the drives per position sample (rows), and where the motion starts in them."""

    t_s: np.ndarray          # (N,) the control grid, the settling hold first
    q_d: np.ndarray          # (N, nq) set point on the grid
    q_d_fb: np.ndarray       # (N, nq) set point aligned with the delayed measurement
    v_ff: np.ndarray         # (N, nv nq)
    tau_ff: np.ndarray       # (N, nv nq)
    v0: np.ndarray           # (nq,) velocity at the first row
    n_settle: int            # rows of the hold before the motion


def on_grid(t_s: np.ndarray, q: np.ndarray, v: np.ndarray, X: list[np.ndarray], dt: float
            ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """The motion on the uniform grid of ``dt`` from its first time: cubic Hermite for ``q`` (with ``v``),
    linear for every array of ``X`` (velocity, acceleration, torque...)."""
    t_s = np.asarray(t_s, float)
    if len(t_s) < 2 or np.any(np.diff(t_s) <= 0):
        raise ConfigError(None, "t_s", "motion times must increase strictly (>= 2 samples)")
    grid = t_s[0] + dt * np.arange(int(np.floor((t_s[-1] - t_s[0]) / dt + 1e-9)) + 1)
    qs = CubicHermiteSpline(t_s, q, v, axis=0)(grid)
    return grid, qs, [np.stack([np.interp(grid, t_s, x[:, j]) for j in range(x.shape[1])], axis=1) for x in X]


def drive_inputs(t_s: np.ndarray, q: np.ndarray, v: np.ndarray, tau_ff: np.ndarray,
                 settings: DriveSettings) -> DriveInputs:
    """The set points of a sampled motion (any sample times) as the drives receive them (module docstring)."""
    dt, nv = settings.sample_time_s, settings.velocity_samples
    grid, Q, (V, T) = on_grid(t_s, q, v, [v, tau_ff], dt)
    n_settle = 0 if np.abs(V[0]).max() > 1e-9 else int(round(settings.settle_time_s / dt))
    Q = np.vstack([np.repeat(Q[:1], n_settle, 0), Q])
    V = np.vstack([np.zeros((n_settle, V.shape[1])), V])
    T = np.vstack([np.repeat(T[:1], n_settle, 0), T])
    tt = dt * np.arange(len(Q))
    Tv, alpha = settings.velocity_sample_time_s, settings.alpha
    v_delay = Tv / 2 + (1 - alpha) / alpha * Tv

    def rows(t_new: np.ndarray, X: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t_new, tt, X[:, j]) for j in range(X.shape[1])], axis=1)

    v_ff = np.hstack([rows(tt + j * Tv - v_delay, V) for j in range(nv)])
    tau = np.hstack([rows(tt + (j + 0.5) * Tv, T) for j in range(nv)])
    idx_fb = np.clip(np.arange(len(Q)) - settings.measurement_delay_samples, 0, len(Q) - 1)
    t_grid = np.concatenate([grid[0] - dt * np.arange(n_settle, 0, -1), grid])
    return DriveInputs(t_grid, Q, Q[idx_fb], v_ff, tau, V[0].copy(), n_settle)
