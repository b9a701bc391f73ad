"""Real-time factor of the MuJoCo arm's servo loop against the project's compiled loop (same arm, same path).

Run: ``.venv/bin/python benchmarks/bench_engines.py [robot] [seconds]``.
Both engines run the same closed loop (:func:`pipeline.control.simulate.simulate_joint_trajectory`,
feedforward ``full_friction``, the 400 µs cascade) on the first ``seconds`` of the robot's EN ISO 9283
path on the rigid hidden robot of seed 1 (``TruthConfig.ideal()``: the own plant's compiled rigid loop;
``engine: mujoco``: the same deviations in MuJoCo, stepped from Python with the same servo law).
Printed, all measured in this run: the real-time factor (simulated time / CPU time of the loop
thread, best of 3) of each engine and their ratio; then the scaling of the MuJoCo loop's CPU time
with the simulated duration and with the number of axes (the UR3's 6 against the Panda's 7 axes, when
example-robot-data is installed; their ISO paths at a quarter of the speed and acceleration, within
their joint speeds), exponents fitted on log-log.
"""

from __future__ import annotations

import os
import sys

import numpy as np
import pinocchio as pin
from bench_help import exit_on_help

from pipeline.control.config import ControlConfig
from pipeline.control.simulate import simulate_joint_trajectory
from pipeline.robot.defaults import ik_seeds_or_derived_rad, iso_or_derived
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.iso9283 import iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import Reference, cartesian_reference
from pipeline.run.stages import load_config
from pipeline.sim.mujoco_robot import create_hidden_robot
from pipeline.sim.truth import RealRobot, TruthConfig


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} {five:.2f} {fifteen:.2f} on {os.cpu_count()} cores"


def mujoco_truth() -> TruthConfig:
    """The rigid hidden robot's deviations, in MuJoCo."""
    truth = TruthConfig.ideal()
    truth.engine = "mujoco"
    return truth


def iso_reference(robot: RobotModel, cfg: ControlConfig, slower: float = 1.0) -> Reference:
    """The robot's ISO 9283 path with ruckig timing, speed and acceleration divided by ``slower``."""
    iso = iso_or_derived(robot, cfg.iso)
    path = iso9283_path(robot, iso.edge_m, iso.centre_m, iso.plane, pin.utils.rotate("x", np.pi))
    q0 = start_configuration(robot, path.poses([0.0])[0], ik_seeds_or_derived_rad(robot, cfg.ik_seeds_deg))
    return cartesian_reference(robot, path, cfg.sample_time_s, iso.speed_m_s / slower, iso.acceleration_m_s2 / slower,
                               iso.jerk_m_s3 / slower, q0)


def cpu_rtf(real: RealRobot, robot: RobotModel, ref: Reference, cfg: ControlConfig, n: int, repeats: int = 3) -> float:
    """Simulated time / loop-thread CPU time of the first ``n`` samples, best of ``repeats``."""
    best = 0.0
    for _ in range(repeats):
        res = simulate_joint_trajectory(real, robot, ref.t_s[:n], ref.q_d[:n], ref.v_d[:n], ref.a_d[:n], cfg,
                                        rng=np.random.default_rng(0))
        best = max(best, res.realtime_factor_cpu)
    return best


def main(robot_name: str = "rx130l", seconds: float = 2.0) -> None:
    robot = RobotModel.load(robot_name)
    cfg = load_config(values={"robot": robot_name, "control.on_saturation": "clip",
                              "control.settle_time_s": 0.0}).control
    ref = iso_reference(robot, cfg)
    n = min(len(ref.t_s), int(round(seconds / cfg.sample_time_s)))
    own = RealRobot.create(robot, 1, TruthConfig.ideal())
    mj = create_hidden_robot(robot, 1, mujoco_truth())
    simulate_joint_trajectory(own, robot, ref.t_s[:50], ref.q_d[:50], ref.v_d[:50], ref.a_d[:50], cfg)  # compile
    rtf_own, rtf_mj = cpu_rtf(own, robot, ref, cfg, n), cpu_rtf(mj, robot, ref, cfg, n)
    print(f"{robot_name}: {n * cfg.sample_time_s:.2f} s of the ISO 9283 path at {cfg.sample_time_s * 1e6:.0f} us; "
          f"{_load()}")
    print(f"  real-time factor (CPU): compiled own loop {rtf_own:8.1f}   MuJoCo loop {rtf_mj:6.2f}   "
          f"ratio own/MuJoCo {rtf_own / rtf_mj:6.1f}")
    durations = [d for d in (0.25 * seconds, 0.5 * seconds, seconds) if d / cfg.sample_time_s >= 20]
    cpu = []
    for d in durations:
        k = int(round(d / cfg.sample_time_s))
        cpu.append(k * cfg.sample_time_s / cpu_rtf(mj, robot, ref, cfg, k, repeats=2))
    slope = float(np.polyfit(np.log(durations), np.log(cpu), 1)[0])
    print("  MuJoCo loop CPU time vs simulated duration: "
          + ", ".join(f"{d:.2f} s -> {c:.2f} s" for d, c in zip(durations, cpu, strict=True))
          + f" (exponent {slope:.2f})")
    arms = [(name, example_arm_urdf(name)) for name in ("ur3", "panda")]
    if all(path is not None for _, path in arms):
        per_sample = []
        for name, path in arms:
            arm = RobotModel.load(path)
            acfg = load_config(values={"robot": str(path), "control.on_saturation": "clip",
                                       "control.settle_time_s": 0.0}).control
            aref = iso_reference(arm, acfg, slower=4.0)   # the small arms' joint speeds
            k = min(len(aref.t_s), n // 2)
            real = create_hidden_robot(arm, 1, mujoco_truth())
            per_sample.append(1e6 / cpu_rtf(real, arm, aref, acfg, k, repeats=2) * acfg.sample_time_s)
            print(f"  {name} ({arm.nq} axes): MuJoCo loop {per_sample[-1]:.0f} us CPU per 400 us sample")
        axes = np.log([6.0, 7.0])
        print(f"  CPU per sample vs axes exponent {float(np.diff(np.log(per_sample))[0] / np.diff(axes)[0]):.2f}")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(*(sys.argv[1:2] or ["rx130l"]), *(float(a) for a in sys.argv[2:3]))
