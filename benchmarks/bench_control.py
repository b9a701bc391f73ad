"""Speed of the closed-loop simulation on the EN ISO 9283 path (stage 3).

Run: ``.venv/bin/python benchmarks/bench_control.py [robot] [python_seconds]``.
For the default hidden robot (elastic joints, Stribeck friction: the two-mass plant with
motor-side encoders) and for the rigid one (``TruthConfig.ideal()``) it prints, all measured in
this run (simulated; the load average of the shared machine beside each figure):

* the real-time factor of the compiled loop, simulated duration / wall time and / CPU time of the
  loop thread (the CPU figure excludes other processes on a shared box), best of 3;
* the same loop called the plain way (``DM`` in and out of every chunk, the path before the
  buffer interface), back to back, and whether its outputs are identical;
* the whole control simulation (resampling, feedforward, loop, tracker positions);
* the plain Python loop (``pin.aba`` at every substep) on the first ``python_seconds`` of the path.

Then the scaling of the compiled elastic loop: CPU time against the simulated duration and against
the number of joints (synthetic chains, 6 against 7 axes), with the exponents fitted by least
squares on log-log. The torque limits are not enforced here (``on_saturation = clip``): only the
speed is measured.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pinocchio as pin
from bench_help import exit_on_help

from pipeline.control.config import ControlConfig
from pipeline.control.simulate import ClosedLoopResult, simulate_joint_trajectory
from pipeline.robot.defaults import ik_seeds_or_derived_rad, iso_or_derived
from pipeline.robot.iso9283 import iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import cartesian_reference
from pipeline.run.stages import load_config
from pipeline.sim import dynamics, loop
from pipeline.sim.truth import RealRobot, TruthConfig


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} {five:.2f} {fifteen:.2f} on {os.cpu_count()} cores"


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
          f"{cfg.sample_time_s * 1e6:.0f} us; reference (ruckig + IK every sample, not part of the loop) "
          f"{t_ref:.2f} s; {_load()}")
    summary = []
    for label, truth_config in (("elastic", TruthConfig()), ("rigid", TruthConfig.ideal())):
        real = RealRobot.create(robot, 1, truth_config)
        print(f"--- hidden robot {label} (simulated): elastic plant {real.plant.elastic}, Stribeck friction "
              f"{real.plant.elastic or real.plant.stribeck}, "
              f"{real.plant.substeps_for(cfg.sample_time_s / 2)} substeps per 200 us")
        summary.append((label, *_measure(real, robot, ref, cfg, python_seconds)))
    print("--- real-time factor of the compiled servo loop per plant (simulated duration / loop time, best of 3)")
    for label, wall, cpu, load in summary:
        print(f"  {label:8s} {wall:6.1f} x wall  {cpu:6.1f} x CPU   ({load})")
    duration_scaling(robot, ref, cfg)


@contextmanager
def _dm_path() -> Iterator[None]:
    """``loop.rollout`` replaced by plain calls of the compiled function (``DM`` in and out)."""
    buffered = loop.rollout

    def plain(ls, x0, U, P):  # noqa: ANN001, ANN202 - the signature of loop.rollout
        roll = loop.compiled_rollout(ls)
        c, N = ls.chunk_samples, len(U)
        n_chunks = -(-N // c)
        Upad = np.vstack([U, np.repeat(U[-1:], n_chunks * c - N, axis=0)])
        Upad[N:, (1 + 2 * ls.velocity_samples_per_position_sample) * ls.nq:] = 0.0
        Ys, x = [], x0
        for i in range(n_chunks):
            X, Yc = roll(x, Upad[i * c:(i + 1) * c].T, P)
            x = np.asarray(X)[:, -1]
            Ys.append(np.asarray(Yc).T)
        return x, np.vstack(Ys)[:N]

    loop.rollout = plain
    try:
        yield
    finally:
        loop.rollout = buffered


def _best_of_3(real, robot, ref, cfg) -> tuple[ClosedLoopResult, float, float]:
    """The result with the best loop factors and the whole simulation's best wall and CPU time."""
    results, whole = [], []
    for _ in range(3):
        c0, t0 = time.process_time(), time.perf_counter()
        res = simulate_joint_trajectory(real, robot, ref.t_s, ref.q_d, ref.v_d, ref.a_d, cfg, "full_friction",
                                        np.random.default_rng(0))
        results.append(res)
        whole.append((time.perf_counter() - t0, time.process_time() - c0))
    best = max(results, key=lambda r: r.realtime_factor)
    best.realtime_factor_cpu = max(r.realtime_factor_cpu for r in results)
    return best, min(w for w, _ in whole), min(c for _, c in whole)


def _measure(real, robot, ref, cfg, python_seconds: float) -> tuple[float, float, str]:
    t0 = time.perf_counter()
    k_warm = min(len(ref.t_s), 50)
    simulate_joint_trajectory(real, robot, ref.t_s[:k_warm], ref.q_d[:k_warm], ref.v_d[:k_warm], ref.a_d[:k_warm],
                              cfg, "full_friction", np.random.default_rng(0))
    print(f"compiled rollout ready in {time.perf_counter() - t0:.2f} s (gcc on first use, then cached on disk)")
    sim_s = len(ref.t_s) * cfg.sample_time_s + cfg.settle_time_s
    best, wall_s, cpu_s = _best_of_3(real, robot, ref, cfg)
    load = _load()
    print(f"compiled loop: {sim_s:.2f} s simulated in {best.wall_time_s:.3f} s wall -> real-time factor "
          f"{best.realtime_factor:.1f} (CPU-time based {best.realtime_factor_cpu:.1f}; best of 3; {load})")
    with _dm_path():
        dm, _, _ = _best_of_3(real, robot, ref, cfg)
    same = all(np.array_equal(getattr(best, k), getattr(dm, k)) for k in ("q", "v", "tau_cmd", "q_link"))
    print(f"same loop, DM in and out of every chunk: real-time factor {dm.realtime_factor:.1f} "
          f"(CPU {dm.realtime_factor_cpu:.1f}); buffered / DM {best.realtime_factor / dm.realtime_factor:.2f}x wall, "
          f"{best.realtime_factor_cpu / dm.realtime_factor_cpu:.2f}x CPU; outputs identical: {same}; {_load()}")
    print(f"whole control simulation (resample, feedforward, loop, tracker): {sim_s / wall_s:.1f} x real time wall, "
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
    return best.realtime_factor, best.realtime_factor_cpu, load


def _fit(x: list[float], y: list[float]) -> float:
    """Exponent ``p`` of ``y ~ x^p`` (least squares on log-log)."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def duration_scaling(robot, ref, cfg, fractions: tuple[float, ...] = (0.125, 0.25, 0.5, 1.0)) -> None:
    """Loop CPU time of the elastic plant on the first part of the ISO path against its duration."""
    real = RealRobot.create(robot, 1, TruthConfig())
    print("--- scaling of the compiled elastic loop with the simulated duration (ISO path prefixes)")
    sims, cpus = [], []
    for f in fractions:
        k = max(2, int(f * len(ref.t_s)))
        best = 0.0
        for _ in range(3):
            r = simulate_joint_trajectory(real, robot, ref.t_s[:k], ref.q_d[:k], ref.v_d[:k], ref.a_d[:k], cfg,
                                          "full_friction", np.random.default_rng(0))
            best = max(best, r.realtime_factor_cpu)
        sim_s = k * cfg.sample_time_s + cfg.settle_time_s
        sims.append(sim_s)
        cpus.append(sim_s / best)
        print(f"  {sim_s:6.2f} s simulated: {cpus[-1]:.3f} s CPU (real-time factor {best:.1f})")
    print(f"control loop time ~ duration^{_fit(sims, cpus):.2f} ({_load()})")


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
                                    inertia.toDynamicParameters(), [0.0, 5.0, 5.0, 500.0]]))
    p = np.concatenate([*rows, [0.0, 0.0, -9.81], [0.01]])
    return dynamics.ChainStructure(n, tuple(range(n)), axes), p


def joint_scaling(joints: tuple[int, ...] = (2, 3, 4, 6, 7, 8), samples: int = 2500, rounds: int = 5) -> None:
    """Compiled elastic loop CPU time per simulated second against the number of joints, ``t ~ n^p``.

    Synthetic chains (:func:`_synthetic_chain`) with two-mass joints: rotor 0.05 kgm^2, 1e4 Nm/rad,
    2 substeps per 200 us as on the RX130L, started at rest at q = 0 under a constant torque command;
    best of ``rounds`` interleaved rounds."""
    rng = np.random.default_rng(0)
    print("--- scaling of the compiled elastic loop with the number of joints (synthetic chains)")
    cases = []
    for n in joints:
        chain, p = _synthetic_chain(n, rng)
        ls = loop.LoopStructure(chain, 2, 2, 1, 250, elastic=True)
        transmission = np.tile([0.05, 1e4, 20.0, 1.0, 0.02, 0.1], n)
        P = loop.loop_parameters(p, np.full(n, 30.0), np.full(n, 500.0), np.full(n, 5e3), 0.4, 1e-7, 4e-4,
                                 transmission)
        U = np.zeros((samples, ls.n_input))
        U[:, n * 3:n * 5] = 10.0
        x0 = np.zeros(ls.n_state)
        loop.rollout(ls, x0, U[:ls.chunk_samples], P)   # compile or load the library
        cases.append((ls, x0, U, P))
    best = np.full(len(joints), np.inf)
    for _ in range(rounds):   # interleaved rounds: a burst of load on the shared machine hits every size
        for k, (ls, x0, U, P) in enumerate(cases):
            c0 = time.thread_time()
            loop.rollout(ls, x0, U, P)
            best[k] = min(best[k], time.thread_time() - c0)
    times = list(best / (samples * 4e-4))
    for n, t in zip(joints, times, strict=True):
        print(f"  {n} joints: {t * 1e3:.2f} ms CPU per simulated second (real-time factor {1 / t:.0f})")
    if 6 in joints and 7 in joints:
        six, seven = times[joints.index(6)], times[joints.index(7)]
        print(f"  7 / 6 axes: {seven / six:.2f}x the time (exponent {np.log(seven / six) / np.log(7 / 6):.2f})")
    print(f"control loop time ~ n_joints^{_fit(list(joints), times):.2f} (least squares on log-log, "
          f"{len(joints)} chains; {_load()})")


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(sys.argv[1] if len(sys.argv) > 1 else "rx130l", float(sys.argv[2]) if len(sys.argv) > 2 else 1.0)
    joint_scaling()
