"""Speed of the closed-loop simulation on the EN ISO 9283 path (stage 3).

Run: ``.venv/bin/python benchmarks/bench_control.py [robot] [python_seconds]``.
Prints the real-time factor of the compiled loop (simulated duration / wall time, and / CPU
time of the loop thread, which excludes other processes on a shared box), the same for the plain
Python loop (``pin.aba`` at every substep) on the first ``python_seconds`` of the path, and the
speed-up between them, all measured in this run, for the default hidden robot (elastic joints,
Stribeck friction: the two-mass plant with motor-side encoders) and for the rigid one
(``TruthConfig.ideal()``). The torque limits are not enforced here (``on_saturation = clip``): only
the speed is measured.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import pinocchio as pin

from pipeline.config import load_config
from pipeline.control.config import ControlConfig
from pipeline.control.simulate import simulate_joint_trajectory
from pipeline.robot.defaults import ik_seeds_or_derived_rad, iso_or_derived
from pipeline.robot.iso9283 import iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import cartesian_reference
from pipeline.sim.truth import RealRobot, TruthConfig


def main(robot_name: str = "rx130l", python_seconds: float = 1.0) -> None:
    robot = RobotModel.load(robot_name)
    cfg = load_config(values={"robot": robot_name, "control.on_saturation": "clip"}).control   # + run_defaults
    iso = iso_or_derived(robot, cfg.iso)             # None fields derived from the robot
    path = iso9283_path(robot, iso.edge_m, iso.centre_m, iso.plane, pin.utils.rotate("x", np.pi))
    q0 = start_configuration(robot, path.poses([0.0])[0], ik_seeds_or_derived_rad(robot, cfg.ik_seeds_deg))
    t0 = time.perf_counter()
    ref = cartesian_reference(robot, path, cfg.sample_time_s, iso.speed_m_s, iso.acceleration_m_s2, iso.jerk_m_s3, q0)
    t_ref = time.perf_counter() - t0
    print(f"ISO 9283 path: {path.length_m:.3f} m, {ref.t_s[-1]:.2f} s, {len(ref.t_s)} samples of "
          f"{cfg.sample_time_s * 1e6:.0f} us; reference (ruckig + IK every sample) {t_ref:.2f} s")
    for label, truth_config in (("elastic joints + Stribeck friction", TruthConfig()),
                                ("rigid joints, viscous + Coulomb", TruthConfig.ideal())):
        real = RealRobot.create(robot, 1, truth_config)
        print(f"--- hidden robot: {label} (elastic plant: {real.plant.elastic}, "
              f"{real.plant.substeps_for(cfg.sample_time_s / 2)} substeps per 200 us)")
        _measure(real, robot, ref, cfg, python_seconds)


def _measure(real, robot, ref, cfg, python_seconds: float) -> None:
    t0 = time.perf_counter()
    k_warm = min(len(ref.t_s), 50)
    simulate_joint_trajectory(real, robot, ref.t_s[:k_warm], ref.q_d[:k_warm], ref.v_d[:k_warm], ref.a_d[:k_warm],
                              cfg, "full_friction", np.random.default_rng(0))
    print(f"compiled rollout ready in {time.perf_counter() - t0:.2f} s (gcc on first use, then cached on disk)")
    results = []
    for _ in range(3):
        res = simulate_joint_trajectory(real, robot, ref.t_s, ref.q_d, ref.v_d, ref.a_d, cfg, "full_friction",
                                        np.random.default_rng(0))
        results.append(res)
    best = max(results, key=lambda r: r.realtime_factor)
    sim_s = len(ref.t_s) * cfg.sample_time_s + cfg.settle_time_s
    print(f"compiled loop: {sim_s:.2f} s simulated in {best.wall_time_s:.3f} s wall -> real-time factor "
          f"{best.realtime_factor:.1f} (CPU-time based {best.realtime_factor_cpu:.1f}; best of 3)")
    k = min(len(ref.t_s), int(python_seconds / cfg.sample_time_s))
    py_cfg = ControlConfig(on_saturation="clip", engine="python", settle_time_s=0.0)
    res_py = simulate_joint_trajectory(real, robot, ref.t_s[:k], ref.q_d[:k], ref.v_d[:k], ref.a_d[:k], py_cfg,
                                       "full_friction", np.random.default_rng(0))
    print(f"plain Python loop (pin.aba per substep): {k * cfg.sample_time_s:.2f} s simulated in "
          f"{res_py.wall_time_s:.3f} s -> real-time factor {res_py.realtime_factor:.2f} "
          f"(CPU {res_py.realtime_factor_cpu:.2f})")
    print(f"speed-up compiled / Python loop: {best.realtime_factor / res_py.realtime_factor:.1f}x wall, "
          f"{best.realtime_factor_cpu / res_py.realtime_factor_cpu:.1f}x CPU")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "rx130l", float(sys.argv[2]) if len(sys.argv) > 2 else 1.0)
