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

The steps of :func:`run`: plan the CP and the PtP motion (:mod:`.solve`; side by side, the CP plan in a
forked child, :func:`pipeline.core.forks.in_background`), verify the plans in the
servo simulation (:mod:`.measure`), gate them (:mod:`.validate`), report (:mod:`.report`: every
reported energy is the fine-grid re-check with the weights of ``ptp_energy``).
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.core.errors import ConfigError
from pipeline.core.forks import in_background
from pipeline.robot.defaults import ptp_move_rad
from pipeline.robot.model import RobotModel
from pipeline.stage_api import StageContext, StageResult
from pipeline.trajectory import report
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.measure import ServoVerification, verify_in_servo
from pipeline.trajectory.settling import add_smooth_ptp, slowed_into_limits
from pipeline.trajectory.solve import CPPlan, PTPPlan, cp_joint_path, plan_cp, plan_ptp, ptp_problem
from pipeline.trajectory.trajectories import FINE_GRID_ROUNDOFF
from pipeline.trajectory.validate import quality_gates

NAME = "trajectory"
#: the stage's section (pipeline.stage_api.StageModule)
Config = TrajectoryConfig
#: the identified dynamics (and the calibrated kinematics before it); the control stage's results are not read
DEPENDS: tuple[str, ...] = ("model", "identification")
#: the plans run in the servo simulation designed from the run's ``control`` section (gains, delays,
#: rates: :func:`pipeline.trajectory.measure.control_config`), never from the control stage's results
CONFIG_READS: tuple[str, ...] = ("control",)
#: provenance (pipeline.run.stage_plan): what is simulated (this stage reads no recorded file)
RECORDED_INPUT = ""
SIMULATES = "servo loop on the hidden robot"
__all__ = ["NAME", "DEPENDS", "CONFIG_READS", "RECORDED_INPUT", "SIMULATES", "Config", "check", "warm_up", "run"]


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


def warm_up(config: TrajectoryConfig, robot: RobotModel) -> None:
    """Compile the PtP NLP while the upstream stages run (:mod:`pipeline.run.warm_up`): its code depends on
    the arm's structure and this section only (the identified and calibrated parameters are inputs),
    so the nominal robot's build is the library :func:`plan_ptp_step` loads."""
    if config.ptp_jit:
        ptp_problem(PlanningModel.from_robot(robot, config.torque_reserve), robot, config)


def run(ctx: StageContext[TrajectoryConfig]) -> StageResult:
    cfg: TrajectoryConfig = ctx.config
    pm = PlanningModel.from_robot(ctx.robot, cfg.torque_reserve)
    ptp_timings: dict[str, float] = {}
    # the CP plan in a forked child beside the PtP plans: independent problems, the same numbers
    with in_background(lambda: plan_cp_step(ctx.robot, pm, cfg)) as cp_result:
        ptp = plan_ptp_step(ctx.robot, pm, cfg, ptp_timings)
        cp, path_length_m, cp_s = cp_result()
    timings = {"cp_s": cp_s, **ptp_timings}
    summary = report.plan_summary(cfg, ctx.robot, pm, cp, ptp, path_length_m,
                                  ctx.upstream.get("identification") is not None)
    servo = ServoVerification()
    if cfg.simulate and ctx.real is not None:
        t0 = time.perf_counter()
        servo = verify_in_servo(ctx, pm, cp, ptp)
        summary.update(servo.summary)
        timings["simulation_s"] = time.perf_counter() - t0
    summary["timings_s"] = timings
    if cp.smooth is not None:
        summary["cp_smooth_solver_status"] = cp.smooth.info.get("solver_status")
    elastic_plant = bool(ctx.real.transmission.elastic) if servo.sims else False
    summary["ptp_elastic_plant"] = elastic_plant
    gates = quality_gates(cfg, cp, ptp, servo.sims, bool(getattr(ctx.run, "accept_poor", False)), elastic_plant)
    return gates.finish(StageResult(summary=summary, arrays=report.arrays(cp, ptp), data=report.data(cp, ptp, servo),
                                    figures=report.figures(pm, cfg, cp, ptp, summary, servo.settle),
                                    report_md=report.report_markdown(cfg, summary, servo)))


def plan_cp_step(robot: RobotModel, pm: PlanningModel, cfg: TrajectoryConfig) -> tuple[CPPlan, float, float]:
    """The CP plan on its piece of the ISO path, the piece's length (m) and the wall time taken (s)."""
    t0 = time.perf_counter()
    path, piece = cp_joint_path(robot, cfg)
    cp = plan_cp(pm, path, cfg)
    return cp, float(piece.length_m), time.perf_counter() - t0


def plan_ptp_step(robot: RobotModel, pm: PlanningModel, cfg: TrajectoryConfig, timings: dict[str, float]) -> PTPPlan:
    """The PtP plans (time/energy optimum, baselines, Pareto sweep), the executed plan slowed into the
    fine-grid limits and its smooth variant for the elastic joints (:mod:`.settling`), timed."""
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
    add_smooth_ptp(pm, robot, ptp, tolerance=cfg.violation_tolerance,   # for the elastic joints
                   acceleration_limits=cfg.acceleration_limits)           # (settling.py)
    timings["ptp_s"] = time.perf_counter() - t0
    return ptp
