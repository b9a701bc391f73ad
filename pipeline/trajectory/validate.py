"""Verification of planned trajectories: fine-grid torque check, execution in stage 3's servo
simulation on the real robot, and the plots (paper 004 Fig. 8 style, Pareto front)."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from pipeline.control.config import ControlConfig
from pipeline.control.simulate import simulate_joint_trajectory
from pipeline.robot.model import RobotModel
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.trajectories import JointTrajectory, TorqueCheck


def simulate_on_real(real: Any, robot: RobotModel, traj: JointTrajectory,  # Any: the simulated hidden robot
                     control_config: ControlConfig | None = None,
                     rng: np.random.Generator | None = None, average_window_s: float = 4e-3) -> dict:
    """Run ``traj`` through ``pipeline.control.simulate.simulate_joint_trajectory`` (cascade with
    full-friction feedforward from ``robot``) and report duration, max torque ratio and the TCP
    error of the (ideal-tracker) measured TCP against the planned TCP ``fk(q_d)``.

    Torque ratios are ``|tau| / tau_max`` with the FULL limits of ``robot`` (no reserve):
    ``max_torque_ratio`` of the raw command (per servo sample), ``max_feedforward_ratio`` of the
    feedforward alone, ``max_averaged_torque_ratio`` of the command averaged over
    ``average_window_s``, and the feedback share ``(tau_cmd - tau_ff) / tau_max`` per joint
    (standard deviation and maximum)."""
    cfg = control_config or ControlConfig(on_saturation="clip", benchmark_python_seconds=0.0)
    if getattr(cfg, "on_saturation", "clip") != "clip":
        cfg = ControlConfig(**{**cfg.__dict__, "on_saturation": "clip"})
    res = simulate_joint_trajectory(real, robot, traj.t_s, traj.q, traj.v, traj.a, cfg,
                                    feedforward="full_friction", rng=rng)
    # split the command into the feedforward (the plan's torques on the model) and the feedback:
    # the feedback is mostly zero-mean noise (encoder noise through the velocity loop), so the
    # command is also reported averaged over ``average_window_s`` (what a drive's current loop and
    # thermal limit see) next to its raw per-sample maximum
    limit = np.asarray(robot.limits.effort_Nm, float)
    feedback = (np.asarray(res.tau_cmd) - np.asarray(res.tau_ff)) / limit
    dt = float(res.t_s[1] - res.t_s[0]) if len(res.t_s) > 1 else 1.0
    width = min(max(1, int(round(average_window_s / dt))), len(res.t_s))
    kernel = np.ones(width) / width
    averaged = np.stack([np.convolve(np.asarray(res.tau_cmd)[:, j], kernel, mode="valid")
                         for j in range(limit.size)], axis=1) / limit
    out = {"duration_s": float(res.t_s[-1] - res.t_s[0]),
           "max_torque_ratio": float(np.max(res.max_torque_ratio)),
           "max_torque_ratio_per_joint": np.asarray(res.max_torque_ratio, float).tolist(),
           "max_feedforward_ratio": float(np.max(np.abs(res.tau_ff) / limit)),
           "max_averaged_torque_ratio": float(np.max(np.abs(averaged))),
           "max_averaged_torque_ratio_per_joint": np.abs(averaged).max(axis=0).tolist(),
           "average_window_s": width * dt,
           "feedback_std_ratio_per_joint": feedback.std(axis=0).tolist(),
           "feedback_max_ratio_per_joint": np.abs(feedback).max(axis=0).tolist(),
           "lag_error_max_rad": float(np.max(np.abs(res.lag_error_rad))),
           "realtime_factor": float(res.realtime_factor)}
    if res.tcp_position_m is not None:
        # against the planned TCP of the model (includes the residual kinematic error) ...
        desired = robot.positions(res.q_d, robot.frame_tcp)
        e = np.linalg.norm(res.tcp_position_m - desired, axis=1)
        out["tcp_error_max_m"] = float(e.max())
        out["tcp_error_rms_m"] = float(np.sqrt(np.mean(e**2)))
        # ... and against the tracker reading of the robot standing at q_d (dynamic tracking error)
        if hasattr(real.plant, "measure_tcp"):
            e = np.linalg.norm(res.tcp_position_m - real.plant.measure_tcp(res.q_d), axis=1)
            out["tcp_tracking_error_max_m"] = float(e.max())
            out["tcp_tracking_error_rms_m"] = float(np.sqrt(np.mean(e**2)))
    return out


def activity_figure(pm: PlanningModel, traj: JointTrajectory, check: TorqueCheck, title: str) -> Figure:
    """Normalised torques and speeds of every joint and their envelope (paper 004 Fig. 8):
    on a time-optimal trajectory at least one of them is at 1 at every instant."""
    fig = Figure(figsize=(8, 5), constrained_layout=True)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for j in range(pm.nq):
        ax1.plot(check.t_s, check.tau_Nm[:, j] / pm.effort_Nm[j], lw=0.9, label=f"axis {j + 1}")
        ax2.plot(traj.t_s, traj.v[:, j] / pm.velocity_rad_s[j], lw=0.9)
    env = np.maximum(check.torque_ratio.max(axis=1), check.velocity_ratio.max(axis=1))
    ax2.plot(check.t_s, env, "k--", lw=1.0, label="max over torque and speed ratios")
    for ax, lab in ((ax1, "tau / tau_max"), (ax2, "qdot / qdot_max")):
        ax.axhline(1.0, color="grey", lw=0.6)
        ax.axhline(-1.0, color="grey", lw=0.6)
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    ax1.legend(fontsize=7, ncol=6, loc="lower center")
    ax2.legend(fontsize=7, loc="lower center")
    ax2.set_xlabel("t [s]")
    ax1.set_title(title)
    return fig


def dominated_flags(points: list[tuple[float, float]], rtol: float = 1e-9) -> list[bool]:
    """For each ``(duration, energy)`` point: is another point at least as good in both and
    strictly better in one (beyond the relative tolerance ``rtol``)? Dominated points of a
    Pareto sweep are poorer local optima of the NLP."""
    def better(a: float, b: float) -> bool:       # a clearly below b
        return a < b - rtol * max(abs(a), abs(b))

    return [any(j != i and not better(t, tj) and not better(e, ej) and (better(tj, t) or better(ej, e))
                for j, (tj, ej) in enumerate(points))
            for i, (t, e) in enumerate(points)]


def pareto_figure(points: list[tuple[float, float, float]], ruckig: tuple[float, float] | None,
                  energy_label: str, dominated: list[bool] | None = None) -> Figure:
    """Duration against energy for the k2 sweep ``(k2, duration, energy)`` (k2 annotated), ruckig's
    point for reference. The front line joins the non-dominated points only; ``dominated`` points
    (default: computed with :func:`dominated_flags`) are drawn hollow, labelled as local optima."""
    fig = Figure(figsize=(6, 4), constrained_layout=True)
    ax = fig.subplots()
    if dominated is None:
        dominated = dominated_flags([(p[1], p[2]) for p in points])
    front = sorted((p for p, d in zip(points, dominated, strict=True) if not d), key=lambda p: p[1])
    if front:
        ax.plot([p[1] for p in front], [p[2] for p in front], "o-", color="tab:blue", label="PtP NLP (k1 = 1)")
    off = [p for p, d in zip(points, dominated, strict=True) if d]
    if off:
        ax.plot([p[1] for p in off], [p[2] for p in off], "o", mfc="none", color="tab:blue",
                label="dominated (local optimum)")
    for k2, t, e in points:
        ax.annotate(f"k2={k2:g}", (t, e), fontsize=7, textcoords="offset points", xytext=(4, 4))
    if ruckig is not None:
        ax.plot([ruckig[0]], [ruckig[1]], "s", color="tab:red", label="ruckig (torque-feasible limits)")
    ax.set_xlabel("duration [s]")
    ax.set_ylabel(energy_label)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def comparison_figure(pm: PlanningModel, items: list[tuple[str, JointTrajectory, TorqueCheck]],
                      title: str) -> Figure:
    """Max torque ratio over joints against time for several trajectories."""
    fig = Figure(figsize=(8, 3), constrained_layout=True)
    ax = fig.subplots()
    for name, _, chk in items:
        ax.plot(chk.t_s, chk.torque_ratio.max(axis=1), lw=0.9, label=f"{name} ({chk.t_s[-1]:.3f} s)")
    ax.axhline(1.0, color="grey", lw=0.6)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("max_i |tau_i| / tau_max,i")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig
