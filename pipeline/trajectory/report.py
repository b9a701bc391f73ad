"""Summary, figures, arrays and report text of the trajectory stage (paper 004 §5, Fig. 8).

Every reported energy (summary, Pareto sweep, figure) is the fine-grid re-check with the weights of
``ptp_energy``; violations are fractions in summary.json and percentages in the report. Figures:
normalised torques and speeds of the CP and the PtP plan (Fig. 8), their torque ratios against the
baselines (toppra, ruckig), the Pareto front of the PtP sweep and, with the servo simulation, the
settling after the PtP move.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from pipeline.robot.model import RobotModel
from pipeline.robot.plotting import distinct_colors
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.measure import ServoVerification
from pipeline.trajectory.pareto import dominated_flags
from pipeline.trajectory.settling import settling_figure, settling_table, settling_verdict
from pipeline.trajectory.solve import CPPlan, PTPPlan
from pipeline.trajectory.trajectories import JointTrajectory, TorqueCheck

ENERGY_UNITS = {"torque": "N²·m²·s", "normalised": "s", "electrical": "J"}   # of int tau^T W tau dt


def percent(fraction: float) -> str:
    """A fraction (summary.json) as a percentage for the report: 0.002758 -> '0.276 %'."""
    return f"{100.0 * fraction:.3f} %"


def maybe(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.4g}"


def pareto_table(entries: list[dict], energy_label: str) -> str:
    """The Pareto sweep (summary ``ptp_pareto``) as a small markdown table."""
    lines = ["PtP Pareto sweep over k2 (k1 = 1; energies on the fine grid):", "",
             f"| k2 | duration [s] | {energy_label} | dominated |", "|---|---|---|---|"]
    for e in entries:
        if e.get("dominated"):
            dom = "yes (local optimum; cold re-solve: " + str(e.get("cold_restart") or "-") + ")"
        else:
            dom = "no" + (f" (cold re-solve {e['cold_restart']})" if e.get("cold_restart") else "")
        lines.append(f"| {e['k2']:g} | {e['duration_s']:.4f} | {e['energy']:.4g} | {dom} |")
    return "\n".join(lines)


def energy_label_of(cfg: TrajectoryConfig) -> str:
    """The energy measure and its unit, as tables and figures name it."""
    return f"energy ({cfg.ptp_energy}) [{ENERGY_UNITS.get(cfg.ptp_energy, '-')}]"


def plan_summary(cfg: TrajectoryConfig, robot: RobotModel, pm: PlanningModel, cp: CPPlan, ptp: PTPPlan,
                 path_length_m: float, identified: bool) -> dict[str, Any]:
    """The summary of the plans (before the servo simulation)."""
    smooth_ptp = ptp.trajectories["ptp_smooth"]
    summary = {**cp.summary(), **ptp.summary()}
    summary["ptp_time_scale"] = float(ptp.trajectories["ptp"].info.get("time_scale", 1.0))
    summary["ptp_smooth_duration_s"] = smooth_ptp.duration_s
    summary["ptp_smooth_fine_violation"] = ptp.checks["ptp_smooth"].violation
    summary["cp_segment"] = cfg.cp_segment
    summary["cp_path_length_m"] = path_length_m
    summary["dynamics_source"] = "identified" if identified else "nominal"
    summary["ptp_energy_measure"] = cfg.ptp_energy
    summary["torque_reserve"] = cfg.torque_reserve
    # one set of limits for every planner and baseline (CP, toppra, PtP, ruckig): the fine-grid
    # checks use these, the servo simulation the full limits
    summary["planning_torque_limits_Nm"] = pm.effort_Nm.tolist()
    summary["torque_limits_Nm"] = np.asarray(robot.limits.effort_Nm, float).tolist()
    return summary


def arrays(cp: CPPlan, ptp: PTPPlan) -> dict[str, np.ndarray]:
    """The plans (the viewer replays ``trajectory_*``), the CP speed profiles and ratios, ruckig's PtP."""
    tr_cp = cp.trajectories["cp"]
    tr_ptp = ptp.trajectories["ptp"]
    out = {
        "trajectory_cp_t": tr_cp.t_s, "trajectory_cp_q": tr_cp.q,
        "trajectory_ptp_t": tr_ptp.t_s, "trajectory_ptp_q": tr_ptp.q,
        "cp_s": cp.optimal.s, "cp_sdot": cp.optimal.sdot, "cp_toppra_sdot": cp.toppra.sdot,
        "cp_torque_ratio": cp.checks["cp"].torque_ratio, "cp_velocity_ratio": cp.checks["cp"].velocity_ratio,
        "ptp_ruckig_t": ptp.trajectories["ptp_ruckig"].t_s, "ptp_ruckig_q": ptp.trajectories["ptp_ruckig"].q,
    }
    if cp.smooth is not None:
        out["trajectory_cp_smooth_t"] = cp.trajectories["cp_smooth"].t_s
        out["trajectory_cp_smooth_q"] = cp.trajectories["cp_smooth"].q
    if "cp_executed" in cp.trajectories:     # a remedy of the time-optimal CP (executable.py) is what runs
        out["trajectory_cp_executed_t"] = cp.trajectories["cp_executed"].t_s
        out["trajectory_cp_executed_q"] = cp.trajectories["cp_executed"].q
    return out


def figures(pm: PlanningModel, cfg: TrajectoryConfig, cp: CPPlan, ptp: PTPPlan, summary: dict[str, Any],
            settle: dict) -> dict[str, Figure]:
    """The stage's figures (module docstring)."""
    tr_cp = cp.trajectories["cp"]
    tr_ptp = ptp.trajectories["ptp"]
    out = {
        "cp_normalised": activity_figure(pm, tr_cp, cp.checks["cp"],
                                         f"CP {cfg.cp_segment}: time-optimal with full friction "
                                         f"({cp.optimal.duration_s:.4f} s)"),
        "cp_vs_toppra": comparison_figure(pm, [(k, cp.trajectories[k], cp.checks[k]) for k in cp.trajectories],
                                          "CP: torque ratio with the full friction model"),
        "ptp_normalised": activity_figure(pm, tr_ptp, ptp.checks["ptp"],
                                          f"PtP: k1 = {cfg.ptp_k1:g}, k2 = {cfg.ptp_k2:g} "
                                          f"({ptp.result.duration_s:.4f} s)"),
        "ptp_vs_ruckig": comparison_figure(pm, [(k, ptp.trajectories[k], ptp.checks[k]) for k in ptp.trajectories],
                                           "PtP: torque ratio with the full friction model"),
        "ptp_pareto": pareto_figure([(e["k2"], e["duration_s"], e["energy"]) for e in summary["ptp_pareto"]],
                                    (ptp.ruckig.duration_s, ptp.checks["ptp_ruckig"].energy),
                                    f"energy ({cfg.ptp_energy}, fine grid) [{ENERGY_UNITS.get(cfg.ptp_energy, '-')}]",
                                    dominated=[e["dominated"] for e in summary["ptp_pareto"]]),
    }
    if settle:
        out["ptp_settling"] = settling_figure(list(settle.values()))
    return out


def data(cp: CPPlan, ptp: PTPPlan, servo: ServoVerification) -> dict[str, Any]:
    """data.json: the servo runs, settling runs, ruckig's details, solver statuses, the CP solvers' info."""
    sims, settle = servo.sims, servo.settle
    return {"simulation": {name: s.to_summary() for name, s in sims.items()},
            "settling": {k: r.summary() for k, r in settle.items()},
            "ruckig": {"jerk_ratio_1_s": ptp.ruckig.jerk_ratio_1_s, **ptp.ruckig.info,
                                           "evaluations": ptp.ruckig.evaluations},
            "solver_status": {"cp": cp.optimal.info.get("solver_status", "reachability (no IPOPT)"),
                              "cp_smooth": cp.smooth.info.get("solver_status") if cp.smooth else None,
                              "ptp": ptp.result.info.get("solver_status"),
                              "ptp_energy_at_ruckig_duration": ptp.at_ruckig_duration_status(),
                              "cp_equal": cp.equal.info.get("solver_status")},
            "cp_info": {"convex": cp.convex.info if cp.convex else None, "refined": cp.optimal.info,
                        "smooth": cp.smooth.info if cp.smooth else None, "toppra": cp.toppra.info}}


def report_markdown(cfg: TrajectoryConfig, summary: dict[str, Any], servo: ServoVerification) -> str:
    """report.md: the table of the plans and their servo runs, the executed CP, settling, Pareto sweep,
    and a warning when the servo asks for more than the torque limits."""
    sims, settle, cp_table = servo.sims, servo.settle, servo.cp_table
    label = energy_label_of(cfg)
    rows = [
        ("CP duration [s] (full friction)", summary["cp_duration_s"]),
        ("CP profile handed on (ours, or toppra's when shorter and within every limit on the fine grid) / "
         "our solver's duration [s]", f"{summary['cp_source']} / {summary['cp_ours_duration_s']:.6g}"),
        ("CP toppra duration [s] (rigid body + Coulomb)", summary["cp_toppra_duration_s"]),
        ("CP toppra made to keep every limit on the fine grid (the peer judged): duration [s], intervals, "
         "uniform slow-down", "within them as planned" if summary["cp_toppra_within_limits"] else
         "none keeps them" if summary["cp_toppra_feasible_duration_s"] is None else
         f"{summary['cp_toppra_feasible_duration_s']:.6g} s, {summary['cp_toppra_feasible_n_grid']}, "
         f"×{summary['cp_toppra_feasible_time_scale']:.6g}"),
        ("CP ours with toppra's constraints / toppra", summary["cp_equal_vs_toppra_ratio"]),
        ("CP fine-grid torque violation [% over the planning limit], ours / toppra (full friction; "
         "summary.json: fractions)",
         f"{percent(summary['cp_fine_violation'])} / {percent(summary['cp_toppra_fine_violation_full_friction'])}"),
        ("CP constraint activity: lowest at the grid points (1 = a limit active everywhere, Fig. 8) / share of "
         "the fine time grid >= 98 %", f"{summary['cp_grid_min_activity']:.4f} / {summary['cp_active_fraction']:.3f}"),
        ("CP smooth duration [s] (time cost)",
         f"{summary.get('cp_smooth_duration_s', float('nan')):.4f} "
         f"({summary.get('cp_smooth_time_cost', 0) * 100:.1f} %)"),
        ("PtP duration [s] / ruckig [s] (executed plan slowed into the fine-grid limits by this factor)",
         f"{summary['ptp_duration_s']:.4f} / {summary['ptp_ruckig_duration_s']:.4f} "
         f"(x{summary['ptp_time_scale']:.5f})"),
        ("PtP fine-grid torque violation [% over the planning limit] (summary.json: a fraction)",
         percent(summary["ptp_fine_violation"])),
        ("PtP smooth (moving average over the lowest elastic mode) duration [s] / fine-grid torque violation",
         f"{summary['ptp_smooth_duration_s']:.4f} / {percent(summary['ptp_smooth_fine_violation'])}"),
        (f"PtP {label} on the fine grid: ours / minimum at ruckig's duration / ruckig's",
         f"{summary['ptp_energy']:.4g} / {maybe(summary['ptp_energy_at_ruckig_duration'])} / "
         f"{summary['ptp_ruckig_energy']:.4g}"),
        ("PtP energy at ruckig's duration / ruckig's",
         summary["ptp_energy_at_ruckig_duration_ratio"] if summary["ptp_energy_at_ruckig_duration"] is not None
         else summary["ptp_energy_at_ruckig_duration_note"]),
        ("PtP solve time [s] (after compile)", summary["ptp_solve_time_s"]),
    ]
    if summary.get("ptp_elastic_plant") and "ptp_sim_max_averaged_torque_ratio" in summary:
        rows.append(("PtP on the elastic arm: the time-optimal (rigid-model) plan needs this multiple of the "
                     "torque limits in the servo (4 ms mean); not vouched for, the smooth plan is",
                     summary["ptp_sim_max_averaged_torque_ratio"]))
    for name, s in sims.items():
        if s.diverged:
            rows.append((f"{name}: servo simulation", f"diverged at t = {s.diverged_at_s:.4f} s (non-finite state)"))
            continue
        rows.append((f"{name}: simulated max torque ratio (raw / {1e3 * s.average_window_s:.0f} ms mean / "
                     "feedforward; feedback std), TCP error max [mm]",
                     f"{s.max_torque_ratio:.4f} / {s.max_averaged_torque_ratio:.4f} / "
                     f"{s.max_feedforward_ratio:.4f}; {float(np.max(s.feedback_std_ratio_per_joint)):.4f}, "
                     f"{1e3 * (s.tcp_error_max_m if s.tcp_error_max_m is not None else float('nan')):.3f}"))
    limits = ", ".join(f"{x:.0f}" for x in summary["planning_torque_limits_Nm"])
    report = (f"Dynamics: {summary['dynamics_source']} model; every planner and baseline (CP, toppra, PtP, "
              f"ruckig) plans with the same limits, (1 - torque_reserve) = {1 - cfg.torque_reserve:g} x the "
              f"torque limits ({limits} N·m); the servo simulation is measured against the full limits. "
              f"Energies are the fine-grid re-check ({cfg.fine_dt_s * 1e3:g} ms samples, full friction model).\n\n")
    report += "| quantity | value |\n|---|---|\n" + "\n".join(
        f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in rows)
    if cp_table:
        report += "\n\n" + cp_table
    if settle:
        report += "\n\n" + settling_table(list(settle.values())) + "\n\n" + settling_verdict(summary)
    if summary["ptp_pareto"]:
        report += "\n\n" + pareto_table(summary["ptp_pareto"], label)
    over = {name: s for name, s in sims.items() if s.max_torque_ratio > 1.0 and not s.diverged}
    if over:
        listed = ", ".join(
            f"{name} {s.max_torque_ratio:.3f} (feedforward {s.max_feedforward_ratio:.3f}, "
            f"{1e3 * s.average_window_s:.0f} ms mean {s.max_averaged_torque_ratio:.3f}, feedback std "
            f"{float(np.max(s.feedback_std_ratio_per_joint)):.3f})" for name, s in over.items())
        report += (f"\n\n**Warning: not executable within the torque limits.** In the closed-loop simulation of the "
                   f"real robot the drives ask for more than the torque limit ({listed} x the limit). "
                   "The excess over the feedforward (the plan's torques on the model) is feedback torque: where "
                   "the averaged command stays near the feedforward it is zero-mean noise of the velocity loop "
                   "(encoder noise through the velocity estimate), a lasting excess is model error. Raise "
                   f"`trajectory.torque_reserve` (now {cfg.torque_reserve:g}) above the feedback peaks, or lower "
                   "the velocity-loop noise (control stage), or improve the identified model.")
    return report


def activity_figure(pm: PlanningModel, traj: JointTrajectory, check: TorqueCheck, title: str) -> Figure:
    """Normalised torques and speeds of every joint and their envelope (paper 004 Fig. 8):
    on a time-optimal trajectory at least one of them is at 1 at every instant."""
    fig = Figure(figsize=(8, 5), constrained_layout=True)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for j, color in enumerate(distinct_colors(pm.nq)):     # one colour per joint, the same in both panels
        ax1.plot(check.t_s, check.tau_Nm[:, j] / pm.effort_Nm[j], lw=0.9, color=color, label=f"axis {j + 1}")
        ax2.plot(traj.t_s, traj.v[:, j] / pm.velocity_rad_s[j], lw=0.9, color=color)
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
    for (name, _, chk), color in zip(items, distinct_colors(len(items)), strict=True):
        ax.plot(chk.t_s, chk.torque_ratio.max(axis=1), lw=0.9, color=color, label=f"{name} ({chk.t_s[-1]:.3f} s)")
    ax.axhline(1.0, color="grey", lw=0.6)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("max_i |tau_i| / tau_max,i")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig
