"""Trajectories on the elastic plant: smooth PtP variant, residual vibration, move-and-settle trade-off.

Paper ``004_abbe750b8bbcc3aa.txt`` §5 (and §2.3, "gear elasticities"): a time-optimal motion drives
at least one torque or speed limit at every instant, so its acceleration and torque change abruptly
(piecewise-constant jerk with the largest jerk the grid allows); on elastic gears these steps
excite the joints' resonances and the TCP rings after the goal is reached. A smooth variant trades
a little motion time for less vibration. Here:

* **lowest elastic mode** :func:`lowest_mode_hz`: with the motor held by the position loop, the link
  chain vibrates against the gear springs, ``K x = omega^2 M_l(q) x`` (``M_l`` the link chain's joint
  inertia without rotor inertia, ``K = diag(k)`` the model's nominal joint stiffness,
  :func:`pipeline.sim.transmission.nominal_joint_stiffness_Nm_rad`); the lowest ``omega`` at the
  goal is the slowest ringing;
* **smooth PtP** :func:`smooth_trajectory`: the time-optimal plan filtered by a moving average of
  length ``T_f`` (q, qdot and qddot alike: the filter commutes with differentiation, starts and
  ends at rest at the same points). The jerk becomes bounded by ``(max qddot - min qddot) / T_f`` and the
  acceleration spectrum is multiplied by ``sinc(f T_f)``, which is zero at ``f = 1/T_f``: with
  ``T_f`` the period of the lowest mode, that mode is not excited (the jerk-limited profile with
  the jerk time equal to the oscillation period, Biagiotti & Melchiorri, "Trajectory Planning for
  Automatic Machines and Robots", Springer 2008, §5.4 / FIR input shaping). It costs ``T_f`` of
  motion time; the torques stay close to the plan's (a moving average of its accelerations);
* **settling time** :func:`move_and_settle`: the plan runs in the closed-loop servo simulation of
  the real (elastic) robot with a hold after the move; the link-side TCP pose (ideal 6-D tracker)
  must stay within 50 µm and 0.1 mrad of the pose the robot comes to rest at
  (:func:`pipeline.control.validate.settling_time`). The rest pose is the mean of the last
  ``rest_window_s`` of the hold; its distance from the planned goal (static gear deflection left
  by the feedforward variant) is reported separately.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from matplotlib.figure import Figure
from scipy.linalg import eigh

from pipeline.control.config import ControlConfig
from pipeline.control.simulate import resample, simulate_joint_trajectory
from pipeline.control.validate import (
    SETTLING_POSITION_TOLERANCE_M,
    SETTLING_ROTATION_TOLERANCE_RAD,
    settling_time,
)
from pipeline.robot.model import RobotModel
from pipeline.robot.plotting import distinct_colors
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.solve import PTPPlan
from pipeline.trajectory.trajectories import JointTrajectory, check_trajectory, slowed_into_limits
from pipeline.trajectory.trajectories import time_scaled as time_scaled  # re-exported beside slowed_into_limits


def lowest_mode_hz(robot: RobotModel, q: np.ndarray, stiffness_Nm_rad: np.ndarray | None = None) -> float:
    """Lowest eigenfrequency [Hz] of ``K x = omega^2 M_l(q) x`` (motors held, module docstring)."""
    k = nominal_joint_stiffness_Nm_rad(robot) if stiffness_Nm_rad is None else np.asarray(stiffness_Nm_rad, float)
    model = robot.model.copy()
    model.armature = np.zeros(model.nv)
    M = pin.crba(model, model.createData(), np.asarray(q, float))
    M = 0.5 * (M + M.T)
    w2 = eigh(np.diag(k), M, eigvals_only=True)
    return float(np.sqrt(max(w2.min(), 0.0)) / (2 * np.pi))


def _box(x: np.ndarray, width: int, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Causal moving average over ``width`` samples of ``x`` (N, n) padded with the rest values:
    output length ``N + width - 1``."""
    pad = np.vstack([np.repeat(before[None], width - 1, 0), x, np.repeat(after[None], width - 1, 0)])
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), pad]), axis=0)
    return (c[width:] - c[:-width]) / width


def smooth_trajectory(traj: JointTrajectory, filter_time_s: float, name: str | None = None) -> JointTrajectory:
    """``traj`` (uniformly sampled, at rest at both ends) through a moving average of ``filter_time_s``
    (module docstring): same start and goal, ``filter_time_s`` longer (rounded to the sample time),
    jerk <= (max a - min a) / filter_time_s per joint."""
    t0 = np.asarray(traj.t_s, float)
    dt = float(np.median(np.diff(t0)))
    # onto a uniform grid that ends exactly at the goal (the plan's last interval may be shorter)
    n = int(np.ceil((t0[-1] - t0[0]) / dt - 1e-9))
    dt = (t0[-1] - t0[0]) / n
    t, Q, V, A = resample(t0, traj.q, traj.v, traj.a, dt)
    if len(t) == n:                     # rounding left the goal sample out
        t, Q, V, A = (np.vstack([x, x0[-1:]]) if x.ndim == 2 else np.append(x, t0[-1])
                      for x, x0 in ((t, t0), (Q, traj.q), (V, traj.v), (A, traj.a)))
    width = max(1, int(round(filter_time_s / dt)))
    zero = np.zeros(traj.q.shape[1])
    q = _box(Q, width, traj.q[0], traj.q[-1])
    v = _box(V, width, zero, zero)
    a = _box(A, width, zero, zero)
    # the padded average starts at the rest value and reaches the goal exactly width - 1 samples late
    q, v, a = q[: len(t) + width - 1], v[: len(t) + width - 1], a[: len(t) + width - 1]
    t_new = t[0] + dt * np.arange(len(q))
    info = {**traj.info, "time_scale": 1.0, "smoothed_from": traj.name, "filter_time_s": width * dt,
            "max_jerk_rad_s3": (np.abs(np.diff(a, axis=0)) / dt).max(axis=0).tolist()}
    return JointTrajectory(name or f"{traj.name}_smooth", t_new, q, v, a, info)


@dataclass
class SettleResult:
    """One plan run on the real robot with a hold after the move (times in s, distances in m/rad)."""

    name: str
    duration_s: float                 # planned motion time
    settling_time_s: float            # after the end of the plan (inf: not settled within the hold)
    t_s: np.ndarray                   # simulation times (motion + hold)
    position_error_m: np.ndarray      # |p_tcp(t) - p_rest| (link side)
    rotation_error_rad: np.ndarray    # |log3(R_rest^T R_tcp(t))|
    tcp_error_max_m: float            # max |p_tcp - fk(q_d)| during the motion (link side, planned TCP)
    static_offset_m: float            # |p_rest - fk(q_goal)| (deflection left by the feedforward)
    max_torque_ratio: float
    position_settling_time_s: float = float("nan")   # the 50 µm criterion alone (without the rotation)

    @property
    def move_and_settle_s(self) -> float:
        return self.duration_s + self.settling_time_s

    def summary(self) -> dict:
        return {"duration_s": self.duration_s, "settling_time_s": self.settling_time_s,
                "move_and_settle_s": self.move_and_settle_s, "tcp_error_max_m": self.tcp_error_max_m,
                "static_offset_m": self.static_offset_m, "max_torque_ratio": self.max_torque_ratio,
                "position_settling_time_s": self.position_settling_time_s,
                "residual_vibration_max_m": float(self.position_error_m[self.t_s > self.duration_s].max())}


def move_and_settle(real, robot: RobotModel, traj: JointTrajectory, control_config: ControlConfig | None = None,
                    rng: np.random.Generator | None = None, hold_s: float = 0.5, rest_window_s: float = 0.05,
                    feedforward: str = "full_friction", tcp_frame: str = "tcp") -> SettleResult:
    """Run ``traj`` on ``real`` with ``hold_s`` of hold after it; settling time of the link-side TCP
    (module docstring; tolerances of :mod:`pipeline.control.validate`)."""
    cfg = control_config or ControlConfig(on_saturation="clip", benchmark_python_seconds=0.0)
    res = simulate_joint_trajectory(real, robot, traj.t_s, traj.q, traj.v, traj.a, cfg, feedforward=feedforward,
                                    rng=rng, tcp_frame=tcp_frame, hold_end_s=hold_s)
    t = res.t_s - res.t_s[0]
    q_link = res.q_link if res.q_link is not None else res.q
    pos, rot = real.plant.measure_tcp_pose(q_link, frame=tcp_frame)
    rest = t >= t[-1] - rest_window_s
    p_rest = pos[rest].mean(axis=0)
    R_rest = pin.exp3(np.mean([pin.log3(rot[-1].T @ R) for R in rot[rest]], axis=0))
    R_rest = rot[-1] @ R_rest
    duration = traj.duration_s
    ts = settling_time(t, pos, p_rest, duration, rot, R_rest)
    ts_pos = settling_time(t, pos, p_rest, duration)
    e_pos = np.linalg.norm(pos - p_rest, axis=1)
    e_rot = np.array([math.sqrt(w.dot(w)) for w in map(pin.log3, np.matmul(R_rest.T, rot))])  # |log3| (norm)
    moving = t <= duration + 1e-9
    desired = robot.positions(res.q_d, frame=tcp_frame)
    e_path = np.linalg.norm(pos - desired, axis=1)
    return SettleResult(traj.name, duration, ts, t, e_pos, e_rot, float(e_path[moving].max()),
                        float(np.linalg.norm(p_rest - desired[-1])), float(np.max(res.max_torque_ratio)), ts_pos)


def settling_table(results: list[SettleResult]) -> str:
    """Markdown table: duration, settling time, move-and-settle total, residual vibration."""
    lines = [f"PtP move and settle on the real robot's elastic joints (TCP within "
             f"{SETTLING_POSITION_TOLERANCE_M * 1e6:.0f} µm and {SETTLING_ROTATION_TOLERANCE_RAD * 1e3:g} mrad "
             "of its rest pose, link side):", "",
             "| plan | duration [s] | settling time [s] | move + settle [s] | settling, 50 µm alone [s] | "
             "residual vibration max [µm] | TCP path error max [mm] |", "|---|---|---|---|---|---|---|"]
    for r in results:
        s = r.summary()
        lines.append(f"| {r.name} | {r.duration_s:.4f} | {r.settling_time_s:.4f} | {r.move_and_settle_s:.4f} | "
                     f"{r.position_settling_time_s:.4f} | {1e6 * s['residual_vibration_max_m']:.1f} | "
                     f"{1e3 * r.tcp_error_max_m:.3f} |")
    return "\n".join(lines)


def settling_figure(results: list[SettleResult]) -> Figure:
    """Top: TCP distance and rotation from the rest pose against time (log scale, tolerance lines, end of
    each plan dotted, its settling instant dashed); bottom: motion time and settling time of each plan,
    the trade-off to choose from."""
    fig = Figure(figsize=(8, 8), constrained_layout=True)
    ax1, ax3, ax2 = fig.subplots(3, 1, gridspec_kw={"height_ratios": [3, 2, 2]})
    for r, c in zip(results, distinct_colors(len(results)), strict=True):   # one colour per plan
        ax1.semilogy(r.t_s, np.maximum(r.position_error_m, 1e-7) * 1e6, color=c, lw=0.8,
                     label=f"{r.name}: {r.duration_s:.3f} s + settle {r.settling_time_s:.3f} s")
        ax3.semilogy(r.t_s, np.maximum(r.rotation_error_rad, 1e-7) * 1e3, color=c, lw=0.8, label=r.name)
        for ax in (ax1, ax3):
            ax.axvline(r.duration_s, color=c, ls=":", lw=0.8)
            if np.isfinite(r.settling_time_s):
                ax.axvline(r.duration_s + r.settling_time_s, color=c, ls="--", lw=0.8)
        ax2.barh(r.name, r.duration_s, color=c, alpha=0.5)
        ax2.barh(r.name, r.settling_time_s if np.isfinite(r.settling_time_s) else 0.0, left=r.duration_s,
                 color=c, hatch="//", alpha=0.9)
    ax1.axhline(SETTLING_POSITION_TOLERANCE_M * 1e6, color="k", lw=0.8,
                label=f"tolerance {SETTLING_POSITION_TOLERANCE_M * 1e6:.0f} µm")
    ax3.axhline(SETTLING_ROTATION_TOLERANCE_RAD * 1e3, color="k", lw=0.8,
                label=f"tolerance {SETTLING_ROTATION_TOLERANCE_RAD * 1e3:g} mrad")
    ax1.set_ylabel("TCP distance from rest pose [µm]")
    ax1.set_title("PtP on the elastic robot: residual vibration (dotted: end of plan, dashed: settled)")
    ax3.set_ylabel("TCP rotation from rest pose [mrad]")
    for ax in (ax1, ax3):
        ax.set_xlabel("time from the start of the move [s]")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    ax2.set_xlabel("time [s] (plain: motion, hatched: settling)")
    ax2.set_ylabel("plan")
    ax2.set_title("move-and-settle time")
    ax2.grid(alpha=0.3, axis="x")
    return fig


def add_smooth_ptp(pm: PlanningModel, robot: RobotModel, plan: PTPPlan, filter_periods: float = 1.0,
                   tolerance: float | None = None, acceleration_limits: bool = True) -> JointTrajectory:
    """Add the smooth variant of ``plan.trajectories["ptp"]`` (moving average over ``filter_periods``
    periods of the lowest elastic mode at the goal) to ``plan.trajectories`` and its fine-grid check
    (full friction model, the plan's energy weights) to ``plan.checks``, both under ``"ptp_smooth"``.

    The average of a plan on its torque limits can exceed them a little (the torque of the averaged
    motion is not the average torque); with a ``tolerance`` the smooth plan is then slowed down
    (:func:`slowed_into_limits`) until its fine-grid check is within the limits."""
    tr = plan.trajectories["ptp"]
    smooth = smooth_trajectory(tr, filter_periods / lowest_mode_hz(robot, tr.q[-1]), "ptp_smooth")
    if tolerance is None:
        check = check_trajectory(pm, smooth, energy_weights=plan.weights)
    else:
        smooth, check = slowed_into_limits(pm, smooth, tolerance, acceleration_limits, plan.weights)
    plan.trajectories["ptp_smooth"] = smooth
    plan.checks["ptp_smooth"] = check
    return smooth


#: hold after the move for the settling time [s] (the slow tail of the servo on the elastic joints)
SETTLE_HOLD_S = 1.5


def settle_study(real, robot: RobotModel, trajectories: dict[str, JointTrajectory],
                 control_config: ControlConfig | None,
                 rng: np.random.Generator, hold_s: float = SETTLE_HOLD_S, filter_periods: float = 1.0,
                 elastic_feedforward: str | None = "elastic_flat") -> tuple[dict[str, SettleResult], dict]:
    """The PtP trade-off: the time-optimal plan ``trajectories["ptp"]``, its smooth variant (moving
    average over ``filter_periods`` periods of the model's lowest elastic mode at the goal) and the
    jerk-limited ruckig baseline when given, each run with ``hold_s`` of hold (same noise seed), with
    the rigid ``full_friction`` feedforward and, on an elastic plant, again with ``elastic_feedforward``
    (:mod:`pipeline.control.elastic_feedforward`; results named ``"<plan> (<variant>)"``).
    Returns the results and the summary entries (``ptp_settle_*``, ``<name>_settling_time_s``,
    ``<name>_elastic_ff_*``, ...)."""
    tr = trajectories["ptp"]
    f1 = lowest_mode_hz(robot, tr.q[-1])
    smooth = trajectories.get("ptp_smooth") or smooth_trajectory(tr, filter_periods / f1, "ptp_smooth")
    plans = {"ptp": tr, "ptp_smooth": smooth}
    if "ptp_ruckig" in trajectories:
        plans["ptp_ruckig"] = trajectories["ptp_ruckig"]
    seed = int(rng.integers(2**32))
    results = {name: move_and_settle(real, robot, x, control_config, np.random.default_rng(seed), hold_s)
               for name, x in plans.items()}
    summary: dict = {"ptp_lowest_mode_hz": f1, "ptp_smooth_filter_time_s": plans["ptp_smooth"].info["filter_time_s"],
                     "ptp_settle_hold_s": hold_s}
    for name, r in results.items():
        for key, value in r.summary().items():
            plain = key in ("settling_time_s", "move_and_settle_s")
            summary[f"{name}_{key}" if plain else f"{name}_settle_{key}"] = value
    opt, smooth = results["ptp"], results["ptp_smooth"]
    summary["ptp_smooth_time_cost"] = smooth.duration_s / opt.duration_s - 1.0
    summary["ptp_smooth_settles_faster"] = bool(smooth.settling_time_s < opt.settling_time_s)
    if elastic_feedforward is not None and real.plant.elastic:
        for name, x in plans.items():
            r = move_and_settle(real, robot, x, control_config, np.random.default_rng(seed), hold_s,
                                feedforward=elastic_feedforward)
            r.name = f"{name} ({elastic_feedforward})"
            results[r.name] = r
            for key, value in r.summary().items():
                summary[f"{name}_elastic_ff_{key}"] = value
        summary["ptp_settle_elastic_feedforward"] = elastic_feedforward
        summary["ptp_smooth_settles_faster_elastic_ff"] = bool(
            summary["ptp_smooth_elastic_ff_settling_time_s"] < summary["ptp_elastic_ff_settling_time_s"])
    return results, summary


def settling_verdict(summary: dict) -> str:
    """One paragraph for the report: the time cost of the smooth plan against its settling gain."""
    opt, sm = summary["ptp_settling_time_s"], summary["ptp_smooth_settling_time_s"]
    text = (f"Smooth PtP: the time-optimal plan through a {1e3 * summary['ptp_smooth_filter_time_s']:.1f} ms moving "
            f"average (one period of the model's lowest elastic mode, {summary['ptp_lowest_mode_hz']:.1f} Hz, at the "
            f"goal) costs {100 * summary['ptp_smooth_time_cost']:.1f} % motion time; it settles in {sm:.3f} s "
            f"against {opt:.3f} s, move + settle {summary['ptp_smooth_move_and_settle_s']:.3f} s against "
            f"{summary['ptp_move_and_settle_s']:.3f} s for the time-optimal plan.")
    if not summary["ptp_smooth_settles_faster"]:
        text += (" **The smooth plan does not settle faster on this move**: compare the residual vibration column "
                 "(the ringing it avoids) with the settling time. The last 0.1 mrad are then set by a slow "
                 "(about 1 Hz) friction/integrator mode of the wrist axes: the velocity loops' integrators hold the "
                 "feedforward's friction error when the motion ends, largest after the smooth plan's slow approach "
                 "through the Stribeck range, and at standstill it drives that mode. It is the model's error, not "
                 "the plan's: with the hidden robot's model in the feedforward the smooth plan settles first on "
                 "every measured seed (`benchmarks/bench_settling.py`).")
    elif summary["ptp_smooth_move_and_settle_s"] < summary["ptp_move_and_settle_s"]:
        text += " Choose the smooth plan when the robot must stand still at the goal."
    else:
        text += " The settling gain does not pay for the longer motion here: choose by the application."
    if "ptp_elastic_ff_settling_time_s" in summary:
        e_opt, e_sm = summary["ptp_elastic_ff_settling_time_s"], summary["ptp_smooth_elastic_ff_settling_time_s"]
        text += (f" With the elastic-joint feedforward ({summary['ptp_settle_elastic_feedforward']}) the time-optimal "
                 f"plan rings {1e6 * summary['ptp_elastic_ff_residual_vibration_max_m']:.0f} µm at most after the move "
                 f"(rigid feedforward: {1e6 * summary['ptp_settle_residual_vibration_max_m']:.0f} µm) and settles in "
                 f"{e_opt:.3f} s, the smooth plan in {e_sm:.3f} s (move + settle "
                 f"{summary['ptp_elastic_ff_move_and_settle_s']:.3f} s against "
                 f"{summary['ptp_smooth_elastic_ff_move_and_settle_s']:.3f} s).")
    late = [n for n in ("ptp", "ptp_smooth", "ptp_ruckig")
            if not summary.get(f"{n}_settling_time_s", 0.0) < 0.8 * summary["ptp_settle_hold_s"]]
    if late:
        text += (f" Settling of {', '.join(late)} within 20 % of the end of the {summary['ptp_settle_hold_s']:g} s "
                 "hold (or not at all): the rest pose is uncertain there.")
    return text
