"""Metrics and figures of the closed-loop runs (paper 004 §2.3.3, Fig. 2).

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

import control as ct
import numpy as np
import pinocchio as pin
from matplotlib.figure import Figure

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


VARIANT_STYLE = {"none": ("tab:red", "no feedforward"), "gravity": ("tab:orange", "gravity"),
                 "full": ("tab:green", "rigid body"), "full_friction": ("tab:blue", "rigid body + friction"),
                 "full_friction_nominal": ("tab:purple", "rigid body + friction (nominal model)"),
                 "elastic_static": ("tab:olive", "elastic: static deflection"),
                 "elastic_flat": ("tab:cyan", "elastic: two-mass inverse (flatness)")}


def lag_figure(t_s: np.ndarray, lag: dict[str, np.ndarray], axes: tuple[int, ...] = (0, 1, 2)) -> Figure:
    """Paper 004 Fig. 2(a): lag errors of axes 1-3 with and without feedforward."""
    fig = Figure(figsize=(8, 2.2 * len(axes)), constrained_layout=True)
    axs = fig.subplots(len(axes), 1, sharex=True)
    for ax, j in zip(np.atleast_1d(axs), axes, strict=True):
        for name, e in lag.items():
            color, label = VARIANT_STYLE.get(name, ("k", name))
            ax.plot(t_s, np.degrees(e[:, j]) * 1e3, color=color, lw=0.8, label=label)
        ax.set_ylabel(f"axis {j + 1} lag [mdeg]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axs)[0].legend(fontsize=7, ncol=2)
    np.atleast_1d(axs)[-1].set_xlabel("time [s]")
    fig.suptitle("Lag errors on the ISO 9283 path")
    return fig


def tcp_figure(s_m: np.ndarray, tcp_tracking: dict[str, np.ndarray], tcp_absolute: dict[str, np.ndarray]) -> Figure:
    """Paper 004 Fig. 2(b): TCP error along the path with and without feedforward.

    Top: tracking error (measured TCP against the real robot at the reference joints), bottom:
    absolute error against the desired Cartesian path (adds the kinematic model error).
    """
    fig = Figure(figsize=(8, 5.5), constrained_layout=True)
    axs = fig.subplots(2, 1, sharex=True)
    for ax, errs, title in ((axs[0], tcp_tracking, "TCP tracking error (vs. real robot at q_d)"),
                            (axs[1], tcp_absolute, "absolute TCP error (vs. desired path)")):
        for name, e in errs.items():
            color, label = VARIANT_STYLE.get(name, ("k", name))
            ax.plot(s_m, e * 1e3, color=color, lw=0.8, label=label)
        ax.set_ylabel("TCP error [mm]")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
        ax.set_title(title, fontsize=9)
    axs[0].legend(fontsize=7, ncol=2)
    axs[1].set_xlabel("path length [m]")
    return fig


def path_figure(desired_m: np.ndarray, actual: dict[str, np.ndarray], points: dict[str, np.ndarray],
                scale: float = 200.0) -> Figure:
    """Desired TCP path and the measured ones (deviations from it magnified ``scale`` times), 3-D."""
    fig = Figure(figsize=(6, 5.5), constrained_layout=True)
    ax = fig.add_subplot(111, projection="3d")
    ax.plot(*desired_m.T, color="k", lw=0.8, label="desired")
    for name, p in actual.items():
        color, label = VARIANT_STYLE.get(name, ("k", name))
        ax.plot(*(desired_m + scale * (p - desired_m)).T, color=color, lw=0.6, label=f"{label} (deviation x{scale:g})")
    for k, p in points.items():
        if k.startswith("P"):
            ax.scatter(*p, color="k", s=8)
            ax.text(*p, k, fontsize=7)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend(fontsize=7)
    return fig


def bode_figure(models: list[dict], joints: tuple[int, ...] = (0, 1, 2)) -> Figure:
    """Bode magnitude/phase of the velocity and position open loops (python-control frequency response)."""
    fig = Figure(figsize=(9, 5.5), constrained_layout=True)
    axs = fig.subplots(2, 2, sharex="col")
    for col, key in enumerate(("velocity_open", "position_open")):
        for j in joints:
            sys = models[j][key]
            w = np.logspace(0, np.log10(np.pi / sys.dt) - 0.01, 600)
            resp = ct.frequency_response(sys, w)
            mag, phase = np.abs(resp.complex).ravel(), np.unwrap(np.angle(resp.complex).ravel())
            axs[0, col].semilogx(w / 2 / np.pi, 20 * np.log10(mag), label=f"axis {j + 1}")
            axs[1, col].semilogx(w / 2 / np.pi, np.degrees(phase))
        axs[0, col].axhline(0, color="k", lw=0.5)
        axs[1, col].axhline(-180, color="k", lw=0.5)
        axs[0, col].set_title(key.replace("_", " ") + " loop")
        axs[1, col].set_xlabel("frequency [Hz]")
        for r in range(2):
            axs[r, col].grid(alpha=0.3, which="both")
    axs[0, 0].set_ylabel("magnitude [dB]")
    axs[1, 0].set_ylabel("phase [deg]")
    axs[0, 0].legend(fontsize=7)
    return fig
