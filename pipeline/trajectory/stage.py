"""Stage ``trajectory``: time-optimal CP and time/energy-optimal PtP motion (paper 004 §5).

Paper ``004_abbe750b8bbcc3aa.txt`` §5 and DESIGN.md "Trajectories":

1. CP: a smooth piece of the EN ISO 9283 path -> joint path by IK -> convex minimum-time problem
   (Verscheure, b = sdot^2, SOC objective, torques at grid points and midpoints) -> refinement with
   viscous + smooth Coulomb friction -> smooth (continuous jerk) variant; toppra on the same grid
   as baseline;
2. PtP: ``min k1 T + k2 int tau^T W tau dt`` with the full dynamics of the best model (identified
   after stage 2), compiled once; ruckig with the most aggressive torque-feasible kinematic limits
   as baseline; the minimum-energy motion at ruckig's duration; a Pareto sweep over k2
   (continuation from the main solution; a dominated point is re-solved once from a cold start, a
   still dominated one is flagged and drawn hollow);
3. every trajectory re-checked on a fine time grid with the full friction model and executed in
   stage 3's 400 µs servo simulation of the real robot (elastic joints by default; TCP path error
   of the links), the PtP plans also with a hold after the move: settling time of the time-optimal
   plan, of its smooth variant and of ruckig's jerk-limited one (:mod:`pipeline.trajectory.settling`).

Every reported energy (summary, Pareto sweep, figure) is the fine-grid re-check with the weights of
``ptp_energy``; violations are fractions in summary.json and percentages in the report.
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.control.config import ControlConfig
from pipeline.errors import ConfigError
from pipeline.quality import QualityGates
from pipeline.robot.defaults import ptp_move_rad
from pipeline.robot.model import RobotModel
from pipeline.solver_status import SUCCESS_STATUSES
from pipeline.stage_api import StageContext, StageResult
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.executable import executable_cp, executed_check
from pipeline.trajectory.settling import (
    add_smooth_ptp,
    settle_study,
    settling_figure,
    settling_table,
    settling_verdict,
    slowed_into_limits,
    time_scaled,
)
from pipeline.trajectory.solve import (
    FINE_GRID_ROUNDOFF,
    CPPlan,
    PTPPlan,
    cp_joint_path,
    plan_cp,
    plan_ptp,
    ptp_problem,
)
from pipeline.trajectory.trajectories import JointTrajectory, check_trajectory
from pipeline.trajectory.validate import (
    activity_figure,
    comparison_figure,
    pareto_figure,
    simulate_on_real,
)

NAME = "trajectory"
DEPENDS: tuple[str, ...] = ("model", "identification", "control")  # plans are run in the servo simulation
#: provenance (pipeline.stage_plan): what is simulated (this stage reads no recorded file)
SIMULATES = "servo loop on the hidden robot"
Config = TrajectoryConfig


def check(config: TrajectoryConfig, robot: RobotModel) -> None:
    """Validate the section against the robot before anything runs (ConfigError naming the field)."""
    def bad(field: str, problem: str) -> ConfigError:
        return ConfigError(None, f"trajectory.{field}", problem)

    config.validate(None)          # the robot-independent checks, also for configs built in Python
    nq = robot.nq
    for field in ("ptp_start_deg", "ptp_goal_deg", "cp_ik_seed_deg", "motor_resistance_ohm", "torque_constant_Nm_A"):
        if getattr(config, field) is not None and len(getattr(config, field)) != nq:
            raise bad(field, f"expected {nq} numbers for robot {robot.name}, got {len(getattr(config, field))}: "
                      f"{list(getattr(config, field))!r}")
    lo, hi = np.degrees(robot.limits.lower_rad), np.degrees(robot.limits.upper_rad)
    for field in ("ptp_start_deg", "ptp_goal_deg"):
        if getattr(config, field) is None:
            continue
        q = np.asarray(getattr(config, field), float)
        out = np.flatnonzero((q < lo) | (q > hi))
        if out.size:
            j = int(out[0])
            raise bad(field, f"joint {j + 1} = {q[j]:.1f} deg outside [{lo[j]:.1f}, {hi[j]:.1f}] deg")


ENERGY_UNITS = {"torque": "N²·m²·s", "normalised": "s", "electrical": "J"}   # of int tau^T W tau dt


def _pct(fraction: float) -> str:
    """A fraction (summary.json) as a percentage for the report: 0.002758 -> '0.276 %'."""
    return f"{100.0 * fraction:.3f} %"


def _maybe(value: float | None) -> str:
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


def _control_config(ctx: StageContext):
    base = getattr(ctx.run, "sections", {}).get("control") if hasattr(ctx.run, "sections") else None
    cfg = base if isinstance(base, ControlConfig) else ControlConfig()
    return ControlConfig(**{**cfg.__dict__, "on_saturation": "clip", "benchmark_python_seconds": 0.0})


def quality_gates(cfg: TrajectoryConfig, cp: CPPlan, ptp: PTPPlan, sims: dict[str, dict],
                  accept_poor: bool = False, elastic_plant: bool = False) -> QualityGates:
    """The stage's gates: every plan within its limits on the fine grid (torque excess, speed and,
    with ``acceleration_limits``, acceleration ratios <= 1 + ``violation_tolerance``), every IPOPT
    solve of a stored plan ``Solve_Succeeded`` (or acceptable), and in the servo simulation the
    command averaged over 4 ms within ``max_sim_averaged_torque_ratio`` x the full torque limits.
    On an elastic plant the time-optimal (rigid-model) PtP is reported, not vouched for: its torque
    steps ring the joints (paper 004 §5: hence jerk-limited plans); the smooth PtP is the one gated."""
    gates = QualityGates(NAME, accept_poor=accept_poor)
    tol = cfg.violation_tolerance
    plans = {**cp.checks, **ptp.checks}
    for name in ("cp", "cp_smooth", "ptp", "ptp_energy_at_ruckig_duration", "ptp_smooth"):
        if name not in plans:
            continue
        chk = plans[name]
        gates.check(f"{name}_fine_violation", chk.violation, "<=", tol, "torque excess on the fine grid")
        gates.check(f"{name}_fine_max_velocity_ratio", chk.max_velocity_ratio, "<=", 1.0 + tol)
        if cfg.acceleration_limits:
            gates.check(f"{name}_fine_max_acceleration_ratio", chk.max_acceleration_ratio, "<=", 1.0 + tol)
    statuses = {"ptp_solver_status": ptp.result.info.get("solver_status"),
                "ptp_energy_at_ruckig_duration_solver_status": ptp.at_ruckig_duration_status()}
    if ptp.at_ruckig_duration is None:          # a comparison that does not exist is not a failed solve
        statuses.pop("ptp_energy_at_ruckig_duration_solver_status")
    if cp.optimal.info.get("method") == "nlp":          # the reachability solver has no IPOPT status
        statuses["cp_solver_status"] = cp.optimal.info.get("solver_status")
    if cp.smooth is not None:
        statuses["cp_smooth_solver_status"] = cp.smooth.info.get("solver_status")
    for name, status in statuses.items():
        gates.require(name, status in SUCCESS_STATUSES, f"IPOPT returned {status}")
    torque_limited_cp = elastic_plant and not cfg.acceleration_limits and "cp_executed" in sims
    if torque_limited_cp:
        chk = cp.checks["cp_executed"]
        gates.check("cp_executed_fine_violation", chk.violation, "<=", tol, "torque excess on the fine grid")
        gates.check("cp_executed_fine_max_velocity_ratio", chk.max_velocity_ratio, "<=", 1.0 + tol)
    for name, s in sims.items():
        if name in ("ptp_ruckig", "ptp_energy_at_ruckig_duration"):
            continue                 # the baseline is reported, not vouched for
        if torque_limited_cp and name in ("cp", "cp_smooth"):
            continue                 # reported (summary cp_sim_*); the executed CP is the one vouched for
        if elastic_plant and name == "ptp" and "ptp_smooth" in sims:
            continue                 # reported (summary ptp_sim_*); the smooth plan is the executable one
        gates.check(f"{name}_sim_max_averaged_torque_ratio", s["max_averaged_torque_ratio"], "<=",
                    cfg.max_sim_averaged_torque_ratio, "servo simulation, 4 ms mean over the full limits")
    return gates


#: rounds of slowing the smooth PtP until the servo simulation keeps the torque limits
SERVO_SCALING_ROUNDS = 4


def _executable_smooth_ptp(ctx: StageContext, pm: PlanningModel, ptp: PTPPlan, ccfg, seed: int,
                           cfg: TrajectoryConfig) -> tuple[JointTrajectory, dict]:
    """The smooth PtP verified in the servo simulation on the real (elastic) arm: while its 4 ms mean
    command exceeds ``max_sim_averaged_torque_ratio`` (the servo's feedback on the ringing joints comes
    on top of the planned torques), slow it down by ``sqrt(excess)`` (inertial torques scale with the
    square of the speed) and run it again; the last run is returned with its simulation."""
    smooth = ptp.trajectories["ptp_smooth"]
    base, factor = smooth, 1.0
    sim = simulate_on_real(ctx.real, ctx.robot, smooth, ccfg, np.random.default_rng(seed))
    for _ in range(SERVO_SCALING_ROUNDS):
        ratio = sim["max_averaged_torque_ratio"] / cfg.max_sim_averaged_torque_ratio
        if ratio <= 1.0:
            break
        factor *= max(1.01, float(np.sqrt(ratio)) * 1.01)
        smooth = time_scaled(base, factor, "ptp_smooth")
        smooth.info["servo_time_scale"] = factor
        sim = simulate_on_real(ctx.real, ctx.robot, smooth, ccfg, np.random.default_rng(seed))
    if smooth is not base:
        ptp.trajectories["ptp_smooth"] = smooth
        ptp.checks["ptp_smooth"] = check_trajectory(pm, smooth, energy_weights=ptp.weights)
    return smooth, sim


def elastic_of(ctx: StageContext) -> bool:
    """Whether the hidden robot's joints are elastic (the executed CP is then verified in its servo)."""
    return ctx.real is not None and bool(ctx.real.transmission.elastic)


def run(ctx: StageContext) -> StageResult:
    cfg: TrajectoryConfig = ctx.config
    robot = ctx.robot
    pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    path, piece = cp_joint_path(robot, cfg)
    cp = plan_cp(pm, path, cfg)
    timings["cp_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    problem = ptp_problem(pm, robot, cfg)
    timings["ptp_build_and_compile_s"] = time.perf_counter() - t0
    q0, q1 = (ptp_move_rad(robot) if cfg.ptp_start_deg is None       # None: derived from the robot
              else (np.radians(cfg.ptp_start_deg), np.radians(cfg.ptp_goal_deg)))
    t0 = time.perf_counter()
    ptp = plan_ptp(pm, problem, q0, q1, cfg)
    # the NLP keeps the limits at its nodes; between them the interpolated plan may pass a speed or
    # acceleration limit by a fraction of a per cent: the plan handed on is slowed into them
    ptp.trajectories["ptp"], ptp.checks["ptp"] = slowed_into_limits(
        pm, ptp.trajectories["ptp"], FINE_GRID_ROUNDOFF, cfg.acceleration_limits, ptp.weights)
    smooth_ptp = add_smooth_ptp(pm, robot, ptp, tolerance=cfg.violation_tolerance,   # for the elastic joints
                                acceleration_limits=cfg.acceleration_limits)           # (settling.py)
    timings["ptp_s"] = time.perf_counter() - t0

    summary = {**cp.summary(), **ptp.summary()}
    summary["ptp_time_scale"] = float(ptp.trajectories["ptp"].info.get("time_scale", 1.0))
    summary["ptp_smooth_duration_s"] = smooth_ptp.duration_s
    summary["ptp_smooth_fine_violation"] = ptp.checks["ptp_smooth"].violation
    summary["cp_segment"] = cfg.cp_segment
    summary["cp_path_length_m"] = float(piece.length_m)
    summary["dynamics_source"] = "identified" if ctx.upstream.get("identification") is not None else "nominal"
    summary["ptp_energy_measure"] = cfg.ptp_energy
    summary["torque_reserve"] = cfg.torque_reserve
    # one set of limits for every planner and baseline (CP, toppra, PtP, ruckig): the fine-grid
    # checks use these, the servo simulation the full limits
    summary["planning_torque_limits_Nm"] = pm.effort_Nm.tolist()
    summary["torque_limits_Nm"] = np.asarray(robot.limits.effort_Nm, float).tolist()
    sims: dict[str, dict] = {}
    settle: dict = {}
    cp_table = ""
    if cfg.simulate and ctx.real is not None:
        t0 = time.perf_counter()
        ccfg = _control_config(ctx)
        seed = int(ctx.rng.integers(2**32))
        items = {"cp": cp.trajectories["cp"], "ptp": ptp.trajectories["ptp"]}
        if "cp_smooth" in cp.trajectories:
            items["cp_smooth"] = cp.trajectories["cp_smooth"]
        items["ptp_ruckig"] = ptp.trajectories["ptp_ruckig"]     # the baseline, under the same servo
        if "ptp_energy_at_ruckig_duration" in ptp.trajectories:
            items["ptp_energy_at_ruckig_duration"] = ptp.trajectories["ptp_energy_at_ruckig_duration"]
        smooth_ptp, sims["ptp_smooth"] = _executable_smooth_ptp(ctx, pm, ptp, ccfg, seed, cfg)
        summary["ptp_smooth_servo_time_scale"] = float(smooth_ptp.info.get("servo_time_scale", 1.0))
        summary["ptp_smooth_time_scale"] = float(smooth_ptp.info.get("time_scale", 1.0))
        summary["ptp_smooth_duration_s"] = smooth_ptp.duration_s
        summary["ptp_smooth_fine_violation"] = ptp.checks["ptp_smooth"].violation
        settle, settle_summary = settle_study(ctx.real, robot, ptp.trajectories, ccfg, ctx.rng)
        summary.update(settle_summary)
        items["ptp_smooth"] = smooth_ptp
        for name, tr in ctx.progress.track(list(items.items()), "trajectory: servo simulation"):
            if name not in sims:
                sims[name] = simulate_on_real(ctx.real, robot, tr, ccfg, np.random.default_rng(seed))
            summary[f"{name}_sim_max_torque_ratio"] = sims[name]["max_torque_ratio"]
            summary[f"{name}_sim_tcp_error_max_m"] = sims[name].get("tcp_error_max_m")
            summary[f"{name}_sim_tcp_tracking_error_max_m"] = sims[name].get("tcp_tracking_error_max_m")
            summary[f"{name}_sim_duration_s"] = sims[name]["duration_s"]
            summary[f"{name}_sim_max_feedforward_ratio"] = sims[name]["max_feedforward_ratio"]
            summary[f"{name}_sim_max_averaged_torque_ratio"] = sims[name]["max_averaged_torque_ratio"]
            summary[f"{name}_sim_feedback_std_ratio"] = float(max(sims[name]["feedback_std_ratio_per_joint"]))
        if elastic_of(ctx):
            ex = executable_cp(ctx.real, robot, pm, cp, ccfg, seed, cfg, sims["cp"])
            sims["cp_executed"] = ex.sim
            cp.checks["cp_executed"] = executed_check(pm, ex)
            summary.update(ex.summary(cp.optimal.duration_s))
            summary["cp_executed_sim_max_averaged_torque_ratio"] = ex.sim["max_averaged_torque_ratio"]
            summary["cp_executed_sim_max_torque_ratio"] = ex.sim["max_torque_ratio"]
            summary["cp_executed_sim_tcp_error_max_m"] = ex.sim.get("tcp_error_max_m")
            summary["cp_executed_fine_violation"] = cp.checks["cp_executed"].violation
            cp_table = ex.table(cp.optimal.duration_s, cfg.max_sim_averaged_torque_ratio)
        timings["simulation_s"] = time.perf_counter() - t0
    summary["timings_s"] = timings
    if cp.smooth is not None:
        summary["cp_smooth_solver_status"] = cp.smooth.info.get("solver_status")
    elastic_plant = bool(ctx.real.transmission.elastic) if sims else False
    summary["ptp_elastic_plant"] = elastic_plant
    gates = quality_gates(cfg, cp, ptp, sims, bool(getattr(ctx.run, "accept_poor", False)), elastic_plant)

    tr_cp = cp.trajectories["cp"]
    tr_ptp = ptp.trajectories["ptp"]
    arrays = {
        "trajectory_cp_t": tr_cp.t_s, "trajectory_cp_q": tr_cp.q,
        "trajectory_ptp_t": tr_ptp.t_s, "trajectory_ptp_q": tr_ptp.q,
        "cp_s": cp.optimal.s, "cp_sdot": cp.optimal.sdot, "cp_toppra_sdot": cp.toppra.sdot,
        "cp_torque_ratio": cp.checks["cp"].torque_ratio, "cp_velocity_ratio": cp.checks["cp"].velocity_ratio,
        "ptp_ruckig_t": ptp.trajectories["ptp_ruckig"].t_s, "ptp_ruckig_q": ptp.trajectories["ptp_ruckig"].q,
    }
    if cp.smooth is not None:
        arrays["trajectory_cp_smooth_t"] = cp.trajectories["cp_smooth"].t_s
        arrays["trajectory_cp_smooth_q"] = cp.trajectories["cp_smooth"].q
    energy_label = f"energy ({cfg.ptp_energy}) [{ENERGY_UNITS.get(cfg.ptp_energy, '-')}]"
    figures = {
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
        figures["ptp_settling"] = settling_figure(list(settle.values()))
    data = {"simulation": sims, "settling": {k: r.summary() for k, r in settle.items()},
            "ruckig": {"jerk_ratio_1_s": ptp.ruckig.jerk_ratio_1_s, **ptp.ruckig.info,
                                           "evaluations": ptp.ruckig.evaluations},
            "solver_status": {"cp": cp.optimal.info.get("solver_status", "reachability (no IPOPT)"),
                              "cp_smooth": cp.smooth.info.get("solver_status") if cp.smooth else None,
                              "ptp": ptp.result.info.get("solver_status"),
                              "ptp_energy_at_ruckig_duration": ptp.at_ruckig_duration_status(),
                              "cp_equal": cp.equal.info.get("solver_status")},
            "cp_info": {"convex": cp.convex.info if cp.convex else None, "refined": cp.optimal.info,
                        "smooth": cp.smooth.info if cp.smooth else None, "toppra": cp.toppra.info}}
    rows = [
        ("CP duration [s] (full friction)", summary["cp_duration_s"]),
        ("CP toppra duration [s] (rigid body + Coulomb)", summary["cp_toppra_duration_s"]),
        ("CP ours with toppra's constraints / toppra", summary["cp_equal_vs_toppra_ratio"]),
        ("CP fine-grid torque violation [% over the planning limit], ours / toppra (full friction; "
         "summary.json: fractions)",
         f"{_pct(summary['cp_fine_violation'])} / {_pct(summary['cp_toppra_fine_violation_full_friction'])}"),
        ("CP constraint activity: lowest at the grid points (1 = a limit active everywhere, Fig. 8) / share of "
         "the fine time grid >= 98 %", f"{summary['cp_grid_min_activity']:.4f} / {summary['cp_active_fraction']:.3f}"),
        ("CP smooth duration [s] (time cost)",
         f"{summary.get('cp_smooth_duration_s', float('nan')):.4f} "
         f"({summary.get('cp_smooth_time_cost', 0) * 100:.1f} %)"),
        ("PtP duration [s] / ruckig [s] (executed plan slowed into the fine-grid limits by this factor)",
         f"{summary['ptp_duration_s']:.4f} / {summary['ptp_ruckig_duration_s']:.4f} "
         f"(x{summary['ptp_time_scale']:.5f})"),
        ("PtP fine-grid torque violation [% over the planning limit] (summary.json: a fraction)",
         _pct(summary["ptp_fine_violation"])),
        ("PtP smooth (moving average over the lowest elastic mode) duration [s] / fine-grid torque violation",
         f"{summary['ptp_smooth_duration_s']:.4f} / {_pct(summary['ptp_smooth_fine_violation'])}"),
        (f"PtP {energy_label} on the fine grid: ours / minimum at ruckig's duration / ruckig's",
         f"{summary['ptp_energy']:.4g} / {_maybe(summary['ptp_energy_at_ruckig_duration'])} / "
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
        rows.append((f"{name}: simulated max torque ratio (raw / {1e3 * s['average_window_s']:.0f} ms mean / "
                     "feedforward; feedback std), TCP error max [mm]",
                     f"{s['max_torque_ratio']:.4f} / {s['max_averaged_torque_ratio']:.4f} / "
                     f"{s['max_feedforward_ratio']:.4f}; {max(s['feedback_std_ratio_per_joint']):.4f}, "
                     f"{1e3 * s.get('tcp_error_max_m', float('nan')):.3f}"))
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
        report += "\n\n" + pareto_table(summary["ptp_pareto"], energy_label)
    over = {name: s for name, s in sims.items() if s["max_torque_ratio"] > 1.0}
    if over:
        listed = ", ".join(
            f"{name} {s['max_torque_ratio']:.3f} (feedforward {s['max_feedforward_ratio']:.3f}, "
            f"{1e3 * s['average_window_s']:.0f} ms mean {s['max_averaged_torque_ratio']:.3f}, feedback std "
            f"{max(s['feedback_std_ratio_per_joint']):.3f})" for name, s in over.items())
        report += (f"\n\n**Warning: not executable within the torque limits.** In the closed-loop simulation of the "
                   f"real robot the drives ask for more than the torque limit ({listed} x the limit). "
                   "The excess over the feedforward (the plan's torques on the model) is feedback torque: where "
                   "the averaged command stays near the feedforward it is zero-mean noise of the velocity loop "
                   "(encoder noise through the velocity estimate), a lasting excess is model error. Raise "
                   f"`trajectory.torque_reserve` (now {cfg.torque_reserve:g}) above the feedback peaks, or lower "
                   "the velocity-loop noise (control stage), or improve the identified model.")
    return gates.finish(StageResult(summary=summary, arrays=arrays, data=data, figures=figures, report_md=report))
