"""What sets the PtP settling time on the elastic hidden robot (stage 4, move and settle).

Run: ``.venv/bin/python benchmarks/bench_settling.py [robot] [seeds]`` (default ``rx130l 1,2,3``).

The PtP move of the run defaults is planned time-optimally on the NOMINAL model and smoothed
(:func:`pipeline.trajectory.settling.add_smooth_ptp`: a moving average one period of the lowest
elastic mode long); both plans run with a 1.5 s hold on the hidden robot of each seed (default
truth: elastic joints, Stribeck and load-dependent friction) under the servo, with the
``full_friction`` feedforward (:func:`pipeline.trajectory.settling.move_and_settle`). The feedforward
model is, per case,

* the nominal model (what a run without identification would use);
* the nominal model with the hidden robot's viscous and Coulomb numbers;
* the exact hidden robot (kinematics, inertias, rotor inertia, stiffness, friction with its Stribeck term);
* the nominal model again, on a hidden robot without Stribeck and load-dependent friction.

Printed per seed and case: the settling time (TCP within 50 µm and 0.1 mrad of its rest pose),
the 50 µm criterion alone, and whether the smooth plan settles first. The velocity loops'
integrators hold the feedforward's friction error when the motion ends; at standstill it drives a
slow (1-1.5 Hz) friction/integrator mode of the wrist axes that the plan does not excite and no plan
avoids. With the hidden robot's friction in the feedforward that tail vanishes and the smooth
plan, which does not ring on the gears, settles first on every seed.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from bench_elastic_gap import with_stiffness, with_truth_friction
from bench_help import exit_on_help

from pipeline.control.config import ControlConfig
from pipeline.robot import defaults
from pipeline.robot.model import RobotModel
from pipeline.run.stages import load_config
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.trajectory import settling
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.solve import plan_ptp, ptp_problem


def main(robot_name: str = "rx130l", seeds: str = "1,2,3") -> None:
    cfg = load_config(None, [f"robot={robot_name}"])
    tc = cfg.trajectory
    robot = RobotModel.load(robot_name)
    pm = PlanningModel.from_robot(robot, tc.torque_reserve)
    if tc.ptp_start_deg is not None and tc.ptp_goal_deg is not None:
        q0, q1 = np.radians(tc.ptp_start_deg), np.radians(tc.ptp_goal_deg)
    else:
        q0, q1 = defaults.ptp_move_rad(robot)
    t0 = time.perf_counter()
    plan = plan_ptp(pm, ptp_problem(pm, robot, tc), q0, q1, tc)
    settling.add_smooth_ptp(pm, robot, plan, tolerance=tc.violation_tolerance)
    plans = {"time-optimal": plan.trajectories["ptp"], "smooth": plan.trajectories["ptp_smooth"]}
    print(f"{robot_name}: PtP planned on the nominal model in {time.perf_counter() - t0:.1f} s; durations "
          + ", ".join(f"{k} {v.duration_s:.3f} s" for k, v in plans.items()))
    ccfg = ControlConfig(on_saturation="clip", benchmark_python_seconds=0.0)
    no_stribeck = TruthConfig(stribeck_excess_relative=0.0, coulomb_load_coefficient=0.0)
    print("| seed | feedforward model (hidden robot) | time-optimal settle / 50 µm [s] | smooth settle / 50 µm [s] "
          "| smooth first |")
    print("|---|---|---|---|---|")
    for seed in (int(s) for s in seeds.split(",")):
        real = RealRobot.create(robot, seed, TruthConfig())
        truth = real.truth
        exact = with_truth_friction(with_stiffness(truth, real.joint_stiffness_Nm_rad), truth, True, real)
        hidden_friction = with_truth_friction(robot, truth, False, real)
        cases = [("nominal", robot, real), ("nominal + hidden viscous/Coulomb", hidden_friction, real),
                 ("exact hidden robot", exact, real),
                 ("nominal (no Stribeck/load friction in the truth)", robot,
                  RealRobot.create(robot, seed, no_stribeck))]
        for label, model, plant in cases:
            res = {k: settling.move_and_settle(plant, model, tr, ccfg, np.random.default_rng(seed),
                                               settling.SETTLE_HOLD_S) for k, tr in plans.items()}
            o, s = res["time-optimal"], res["smooth"]
            print(f"| {seed} | {label} | {o.settling_time_s:.3f} / {o.position_settling_time_s:.3f} | "
                  f"{s.settling_time_s:.3f} / {s.position_settling_time_s:.3f} | "
                  f"{'yes' if s.settling_time_s < o.settling_time_s else 'no'} |", flush=True)


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(*sys.argv[1:3])
