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
from pipeline.sim import dynamics, loop
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
    whole = []
    for _ in range(3):
        c0, t0 = time.process_time(), time.perf_counter()
        res = simulate_joint_trajectory(real, robot, ref.t_s, ref.q_d, ref.v_d, ref.a_d, cfg, "full_friction",
                                        np.random.default_rng(0))
        results.append(res)
        whole.append((time.perf_counter() - t0, time.process_time() - c0))
    best = max(results, key=lambda r: r.realtime_factor)
    best_cpu = max(results, key=lambda r: r.realtime_factor_cpu)
    sim_s = len(ref.t_s) * cfg.sample_time_s + cfg.settle_time_s
    print(f"compiled loop: {sim_s:.2f} s simulated in {best.wall_time_s:.3f} s wall "
          f"-> real-time factor {best.realtime_factor:.1f} (CPU-time based {best_cpu.realtime_factor_cpu:.1f}; "
          f"best of 3)")
    wall_s, cpu_s = min(w for w, _ in whole), min(c for _, c in whole)
    print(f"whole control simulation (resample, feedforward, loop): {sim_s / wall_s:.1f} x real time wall, "
          f"{sim_s / cpu_s:.1f} x CPU (best of 3)")
    k = min(len(ref.t_s), int(python_seconds / cfg.sample_time_s))
    py_cfg = ControlConfig(on_saturation="clip", engine="python", settle_time_s=0.0)
    res_py = simulate_joint_trajectory(real, robot, ref.t_s[:k], ref.q_d[:k], ref.v_d[:k], ref.a_d[:k], py_cfg,
                                       "full_friction", np.random.default_rng(0))
    print(f"plain Python loop (pin.aba per substep): {k * cfg.sample_time_s:.2f} s simulated in "
          f"{res_py.wall_time_s:.3f} s -> real-time factor {res_py.realtime_factor:.2f} "
          f"(CPU {res_py.realtime_factor_cpu:.2f})")
    print(f"speed-up compiled / Python loop: {best.realtime_factor / res_py.realtime_factor:.1f}x wall, "
          f"{best.realtime_factor_cpu / res_py.realtime_factor_cpu:.1f}x CPU")


def _synthetic_chain(n: int, rng: np.random.Generator) -> tuple[dynamics.ChainStructure, np.ndarray]:
    """A serial chain of ``n`` revolute joints (axes z, y, y, x, y, x, z, ...), 0.2-0.5 m links, 2-20 kg."""
    cycle = ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))
    axes = tuple(cycle[i % len(cycle)] for i in range(n))
    rows = []
    for _ in range(n):
        m = rng.uniform(2.0, 20.0)
        c = rng.uniform(-0.1, 0.1, 3)
        inertia = pin.Inertia(m, c, np.diag(rng.uniform(0.01, 0.5, 3)))
        rows.append(np.concatenate([np.eye(3).ravel(), [0.0, 0.0, rng.uniform(0.2, 0.5)],
                                    inertia.toDynamicParameters(), [0.5, 5.0, 5.0, 500.0]]))
    p = np.concatenate([*rows, [0.0, 0.0, -9.81], [0.01]])
    return dynamics.ChainStructure(n, tuple(range(n)), axes), p


def scaling(joints: tuple[int, ...] = (2, 3, 4, 6, 7, 8), samples: int = 2500) -> None:
    """Compiled loop time per simulated second against the number of joints, fitted ``t ~ n^p``."""
    rng = np.random.default_rng(0)
    times = []
    for n in joints:
        chain, p = _synthetic_chain(n, rng)
        ls = loop.LoopStructure(chain, 2, 2, 1, 250)
        roll = loop.compiled_rollout(ls)
        P = loop.loop_parameters(p, np.full(n, 30.0), np.full(n, 500.0), np.full(n, 5e3), 0.4, 1e-7, 4e-4)
        q0 = np.zeros(n)
        U = np.zeros((ls.n_input, ls.chunk_samples))
        U[n * 3:n * 5] = 10.0
        x0 = np.concatenate([q0, np.zeros(n), np.zeros(n), q0, np.zeros(n), q0])
        best = np.inf
        for _ in range(3):
            c0 = time.thread_time()
            for _ in range(samples // ls.chunk_samples):
                roll(x0, U, P)
            best = min(best, time.thread_time() - c0)
        times.append(best / (samples * 4e-4))
        print(f"  {n} joints: {times[-1] * 1e3:.2f} ms CPU per simulated second "
              f"(real-time factor {1 / times[-1]:.0f})")
    slope = np.polyfit(np.log(joints), np.log(times), 1)[0]
    print(f"control loop time ~ n_joints^{slope:.2f} (least squares on log-log, {len(joints)} chains)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "rx130l", float(sys.argv[2]) if len(sys.argv) > 2 else 1.0)
    print("--- scaling with the number of joints (rigid plant, 2 substeps per 200 us)")
    scaling()
