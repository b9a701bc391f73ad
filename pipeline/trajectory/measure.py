"""What the trajectory stage measures: its plans executed in stage 3's 400 µs servo simulation of
the real robot (paper 004 §5, DESIGN.md "Trajectories").

Every plan (CP, its smooth variant, the PtP plans and ruckig's baseline) runs with the same encoder
noise (one seed drawn from the stage's generator) through
:func:`~pipeline.trajectory.validate.simulate_on_real`; the smooth PtP is slowed until its 4 ms
mean command keeps ``max_sim_averaged_torque_ratio`` (:func:`executable_smooth_ptp`); the PtP plans
also run with a hold after the move (settling times, :mod:`pipeline.trajectory.settling`); on
elastic joints the executed CP is verified too (:mod:`pipeline.trajectory.executable`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.control.config import ControlConfig
from pipeline.stage_api import StageContext
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.executable import executable_cp, executed_check
from pipeline.trajectory.settling import SettleResult, settle_study, time_scaled
from pipeline.trajectory.solve import CPPlan, PTPPlan
from pipeline.trajectory.trajectories import JointTrajectory, check_trajectory
from pipeline.trajectory.validate import ServoRun, simulate_on_real

#: rounds of slowing the smooth PtP until the servo simulation keeps the torque limits
SERVO_SCALING_ROUNDS = 4


@dataclass
class ServoVerification:
    """The plans' servo runs by name (:func:`simulate_on_real`'s records), the settling runs, the
    summary entries they give (in the order the summary lists them) and the executed CP's table."""

    sims: dict[str, ServoRun] = field(default_factory=dict)
    settle: dict[str, SettleResult] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    cp_table: str = ""


def control_config(ctx: StageContext) -> ControlConfig:
    """The run's control section (defaults without one), clipping at saturation, no loop benchmark."""
    base = getattr(ctx.run, "sections", {}).get("control") if hasattr(ctx.run, "sections") else None
    cfg = base if isinstance(base, ControlConfig) else ControlConfig()
    return ControlConfig(**{**cfg.__dict__, "on_saturation": "clip", "benchmark_python_seconds": 0.0})


def elastic_of(ctx: StageContext) -> bool:
    """Whether the hidden robot's joints are elastic (the executed CP is then verified in its servo)."""
    return ctx.real is not None and bool(ctx.real.transmission.elastic)


def executable_smooth_ptp(ctx: StageContext, pm: PlanningModel, ptp: PTPPlan, ccfg: ControlConfig, seed: int,
                          cfg: TrajectoryConfig) -> tuple[JointTrajectory, ServoRun]:
    """The smooth PtP verified in the servo simulation on the real (elastic) arm: while its 4 ms mean
    command exceeds ``max_sim_averaged_torque_ratio`` (the servo's feedback on the ringing joints comes
    on top of the planned torques), slow it down by ``sqrt(excess)`` (inertial torques scale with the
    square of the speed) and run it again; the last run is returned with its simulation. A run that
    diverged is not slowed further: its ratio measures nothing (the stage's gates name it)."""
    smooth = ptp.trajectories["ptp_smooth"]
    base, factor = smooth, 1.0
    sim = simulate_on_real(ctx.real, ctx.robot, smooth, ccfg, np.random.default_rng(seed))
    for _ in range(SERVO_SCALING_ROUNDS):
        ratio = sim.max_averaged_torque_ratio / cfg.max_sim_averaged_torque_ratio
        if ratio <= 1.0 or sim.diverged:
            break
        factor *= max(1.01, float(np.sqrt(ratio)) * 1.01)
        smooth = time_scaled(base, factor, "ptp_smooth")
        smooth.info["servo_time_scale"] = factor
        sim = simulate_on_real(ctx.real, ctx.robot, smooth, ccfg, np.random.default_rng(seed))
    if smooth is not base:
        ptp.trajectories["ptp_smooth"] = smooth
        ptp.checks["ptp_smooth"] = check_trajectory(pm, smooth, energy_weights=ptp.weights)
    return smooth, sim


def sim_summary(name: str, sim: ServoRun) -> dict[str, Any]:
    """The summary entries of one plan's servo run (``<name>_sim_diverged_at_s`` only for a run that diverged)."""
    diverged = {} if not sim.diverged else {f"{name}_sim_diverged_at_s": sim.diverged_at_s}
    return {**diverged, f"{name}_sim_max_torque_ratio": sim.max_torque_ratio,
            f"{name}_sim_tcp_error_max_m": sim.tcp_error_max_m,
            f"{name}_sim_tcp_tracking_error_max_m": sim.tcp_tracking_error_max_m,
            f"{name}_sim_duration_s": sim.duration_s,
            f"{name}_sim_max_feedforward_ratio": sim.max_feedforward_ratio,
            f"{name}_sim_max_averaged_torque_ratio": sim.max_averaged_torque_ratio,
            f"{name}_sim_feedback_std_ratio": float(np.max(sim.feedback_std_ratio_per_joint))}


def verify_in_servo(ctx: StageContext, pm: PlanningModel, cp: CPPlan, ptp: PTPPlan) -> ServoVerification:
    """Every plan in the servo simulation (module docstring); updates ``ptp``'s smooth plan when the
    servo slowed it and ``cp.checks["cp_executed"]`` on elastic joints."""
    cfg: TrajectoryConfig = ctx.config
    out = ServoVerification()
    ccfg = control_config(ctx)
    seed = int(ctx.rng.integers(2**32))
    items = {"cp": cp.trajectories["cp"], "ptp": ptp.trajectories["ptp"]}
    if "cp_smooth" in cp.trajectories:
        items["cp_smooth"] = cp.trajectories["cp_smooth"]
    items["ptp_ruckig"] = ptp.trajectories["ptp_ruckig"]     # the baseline, under the same servo
    if "ptp_energy_at_ruckig_duration" in ptp.trajectories:
        items["ptp_energy_at_ruckig_duration"] = ptp.trajectories["ptp_energy_at_ruckig_duration"]
    smooth_ptp, out.sims["ptp_smooth"] = executable_smooth_ptp(ctx, pm, ptp, ccfg, seed, cfg)
    out.summary["ptp_smooth_servo_time_scale"] = float(smooth_ptp.info.get("servo_time_scale", 1.0))
    out.summary["ptp_smooth_time_scale"] = float(smooth_ptp.info.get("time_scale", 1.0))
    out.summary["ptp_smooth_duration_s"] = smooth_ptp.duration_s
    out.summary["ptp_smooth_fine_violation"] = ptp.checks["ptp_smooth"].violation
    out.settle, settle_summary = settle_study(ctx.real, ctx.robot, ptp.trajectories, ccfg, ctx.rng)
    out.summary.update(settle_summary)
    items["ptp_smooth"] = smooth_ptp
    for name, tr in ctx.progress.track(list(items.items()), "trajectory: servo simulation"):
        if name not in out.sims:
            out.sims[name] = simulate_on_real(ctx.real, ctx.robot, tr, ccfg, np.random.default_rng(seed))
        out.summary.update(sim_summary(name, out.sims[name]))
    if elastic_of(ctx) and ctx.real is not None:       # elastic joints: a hidden robot is there
        ex = executable_cp(ctx.real, ctx.robot, pm, cp, ccfg, seed, cfg, out.sims["cp"])
        out.sims["cp_executed"] = ex.sim
        cp.checks["cp_executed"] = executed_check(pm, ex)
        if ex.name != "time_optimal":          # a remedy: the plan the arm runs is stored (and exported)
            cp.trajectories["cp_executed"] = ex.trajectory
        out.summary.update(ex.summary(cp.optimal.duration_s))
        out.summary["cp_executed_sim_max_averaged_torque_ratio"] = ex.sim.max_averaged_torque_ratio
        out.summary["cp_executed_sim_max_torque_ratio"] = ex.sim.max_torque_ratio
        out.summary["cp_executed_sim_tcp_error_max_m"] = ex.sim.tcp_error_max_m
        out.summary["cp_executed_fine_violation"] = cp.checks["cp_executed"].violation
        out.cp_table = ex.table(cp.optimal.duration_s, cfg.max_sim_averaged_torque_ratio)
    return out
