"""Metrics of the closed-loop runs (paper 004 §2.3.3, Fig. 2).

* Lag error per joint: ``e_i(t) = q_d,i(t) - q_i(t)`` (encoder), max |e| and RMS.
* TCP path error: ``|p_meas(t) - p_d(t)|`` with ``p_meas`` the TCP position of the real robot
  (ideal laser tracker registered to the base) and ``p_d`` the desired TCP of the Cartesian
  path (absolute: includes the kinematic model error); the same after a best-fit rigid
  registration of the measured path onto the desired one (how a tracker measurement of a path is
  compared, paper 004 §2.3.3; removes the robot's placement, which a tracker calibration cannot
  separate from the tracker pose, and a constant TCP offset); and the tracking part
  ``|p_meas(t) - p(q_d(t))|`` against the real robot standing at the reference joints.
* Settling time after a move (residual vibration of elastic joints, paper 004 §5): the time after
  the end of the plan from which the TCP stays within 50 µm of the goal position and 0.1 mrad of
  the goal orientation (:func:`settling_time`).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

SETTLING_POSITION_TOLERANCE_M = 50e-6
SETTLING_ROTATION_TOLERANCE_RAD = 0.1e-3


def settling_time(t_s: np.ndarray, position_m: np.ndarray, goal_position_m: np.ndarray, t_end_s: float,
                  rotation: np.ndarray | None = None, goal_rotation: np.ndarray | None = None,
                  position_tolerance_m: float = SETTLING_POSITION_TOLERANCE_M,
                  rotation_tolerance_rad: float = SETTLING_ROTATION_TOLERANCE_RAD) -> float:
    """Seconds after ``t_end_s`` (end of the plan) from which every later sample is within tolerance.

    ``position_m`` (N, 3) measured TCP, ``rotation`` (N, 3, 3) its orientation (optional; error
    ``|log3(R_goal^T R)|``). Returns 0 if already settled at ``t_end_s`` and ``inf`` if the record ends
    outside the tolerance (hold longer: ``simulate_joint_trajectory(..., hold_end_s=...)``)."""
    t_s = np.asarray(t_s, float)
    ok = np.linalg.norm(np.asarray(position_m) - np.asarray(goal_position_m), axis=1) <= position_tolerance_m
    if rotation is not None:
        goal = np.asarray(goal_rotation, float)
        ang = np.array([np.linalg.norm(pin.log3(goal.T @ R)) for R in np.asarray(rotation)])
        ok &= ang <= rotation_tolerance_rad
    if not ok[-1]:
        return float("inf")
    bad = np.nonzero(~ok)[0]
    t_settle = t_s[bad[-1] + 1] if len(bad) else t_s[0]
    return float(max(0.0, t_settle - t_end_s))


def error_stats(err: np.ndarray) -> dict[str, float]:
    e = np.abs(np.asarray(err, float))
    return {"max": float(e.max()), "rms": float(np.sqrt(np.mean(e**2)))}


def run_metrics(lag_error_rad: np.ndarray, tcp_meas_m: np.ndarray, tcp_desired_m: np.ndarray,
                tcp_at_reference_m: np.ndarray | None) -> dict:
    lag = np.abs(lag_error_rad)
    out = {
        "lag_error_max_rad": lag.max(axis=0).tolist(),
        "lag_error_rms_rad": np.sqrt(np.mean(lag**2, axis=0)).tolist(),
    }
    e_abs = np.linalg.norm(tcp_meas_m - tcp_desired_m, axis=1)
    out["tcp_error_max_m"], out["tcp_error_rms_m"] = error_stats(e_abs).values()
    e_reg = registered_error(tcp_meas_m, tcp_desired_m)
    out["tcp_error_registered_max_m"], out["tcp_error_registered_rms_m"] = error_stats(e_reg).values()
    if tcp_at_reference_m is not None:
        e_trk = np.linalg.norm(tcp_meas_m - tcp_at_reference_m, axis=1)
        out["tcp_tracking_error_max_m"], out["tcp_tracking_error_rms_m"] = error_stats(e_trk).values()
    return out


def registered_error(measured_m: np.ndarray, desired_m: np.ndarray) -> np.ndarray:
    """|R p_meas + t - p_des| after the best-fit rigid registration (Kabsch) of the measured path onto
    the desired one: the path accuracy free of the robot's placement in the world, which a tracker
    calibration cannot separate from the tracker pose."""
    a, b = measured_m.mean(axis=0), desired_m.mean(axis=0)
    U, _, Vt = np.linalg.svd((measured_m - a).T @ (desired_m - b))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return np.linalg.norm((measured_m - a) @ R.T + b - desired_m, axis=1)
