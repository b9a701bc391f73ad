"""Scaling curves: how the run time of a building block grows with the problem size.

Run: ``.venv/bin/python benchmarks/bench_scaling.py [robot] [--quick]`` (default rx130l).
(CP and PtP: ``bench_cp.py`` prints the CP solve time against grid N, path length and number of
joints, ``bench_trajectory.py scaling`` the PtP solve time against grid N, move length and joints,
each with fitted exponents.)

Each curve prints the times and the fitted exponent ``k`` of ``time ∝ N^k`` (least squares on
``log t = k log N + c``), so a regression (e.g. a quadratic step in a linear algorithm) shows:

1. remove-and-replace (paper ``004_abbe750b8bbcc3aa.txt`` §3) against the number of candidates
   (10³ … 10⁵, 40 configurations) and against the number of configurations (10 … 160, 10⁴
   candidates); candidates are random joint vectors inside the limits with their whitened
   Jacobians (no visibility filter: the design's cost does not depend on it);
2. the identification fit against the number of samples (OLS, Gautier's WLS and the physically
   consistent IPOPT fit on simulated torques of random states);
3. the 400 µs control loop (``simulate_joint_trajectory``) against the simulated seconds.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence

import numpy as np
from bench_help import exit_on_help

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import error_model as em
from pipeline.calibration.config import Config as CalibrationConfig
from pipeline.calibration.stage import identify_parameter_set
from pipeline.control.config import ControlConfig
from pipeline.control.simulate import simulate_joint_trajectory
from pipeline.core.blas import single_thread_blas
from pipeline.core.progress import Progress
from pipeline.identification import estimate as E
from pipeline.identification.regressor import RegressorModel, standard_parameters
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot, TruthConfig


def fitted_exponent(sizes: Sequence[float], times_s: Sequence[float]) -> float:
    """``k`` of ``time ∝ N^k``: slope of the least-squares line through (log N, log t)."""
    return float(np.polyfit(np.log(np.asarray(sizes, float)), np.log(np.asarray(times_s, float)), 1)[0])


def curve(label: str, unit: str, sizes: Sequence[float], run: Callable[[float], float], progress: Progress) -> float:
    """Time ``run(N)`` (seconds, measured by the caller) for every size, print and return ``k``."""
    times = [run(n) for n in progress.track(sizes, label)]
    points = ", ".join(f"{n:g} {unit}: {t:.3g} s" for n, t in zip(sizes, times, strict=True))
    k = fitted_exponent(sizes, times)
    print(f"{label}: {points}; fitted exponent k = {k:.2f}")
    return k


def _timed(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def design_curves(robot: RobotModel, quick: bool, progress: Progress) -> None:
    rng = np.random.default_rng(0)
    cfg = CalibrationConfig()
    mm = em.MeasurementModel(robot)
    _report, basis = identify_parameter_set(robot, mm, cfg, rng)
    n_max = 10_000 if quick else 100_000
    Q = em.random_configurations(robot, n_max, rng)
    chain = cd.chain_from_robot(robot)
    G = cd.build_candidate_set(chain, Q, basis, robot.tracker.transform_tracker_to_base).G
    spec, _ = ds.index_spec(cfg, robot, mm, basis, rng)    # the stage's criterion (V: its working region)

    evaluations: list[int] = []

    def rr(n_candidates: float, n_configurations: int = 40) -> float:
        sub = G[: int(n_candidates)]
        t0 = time.perf_counter()
        result = ds.remove_and_replace(sub, spec, n_configurations, np.random.default_rng(1))
        evaluations.append(result.evaluations)
        return time.perf_counter() - t0

    sizes = [1e3, 3e3, 1e4] if quick else [1e3, 3e3, 1e4, 3e4, 1e5]
    curve(f"remove-and-replace ({spec.name}, 40 configurations) vs candidates", "candidates", sizes, rr, progress)
    print(f"  (index evaluations: {', '.join(str(e) for e in evaluations)})")
    evaluations.clear()
    n_conf = [10, 20, 40] if quick else [10, 20, 40, 80, 160]
    curve("remove-and-replace (10^4 candidates) vs configurations", "configurations", n_conf,
          lambda n: rr(min(1e4, n_max), int(n)), progress)
    print(f"  (index evaluations: {', '.join(str(e) for e in evaluations)})")


def identification_curve(robot: RobotModel, quick: bool, progress: Progress) -> None:
    act = robot.actuation
    reg = RegressorModel(robot.model, act.gear_matrix, act.coulomb_smoothing_rad_s)
    p = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    rng = np.random.default_rng(0)
    n_max = 2000 if quick else 8000
    Q, V, A = rng.normal(size=(3, n_max, robot.nq))
    Y = reg.stacked(Q, V, A)
    y = Y @ p + 0.1 * rng.normal(size=Y.shape[0])
    nq = robot.nq

    def least_squares(n: float) -> float:
        rows = slice(0, int(n) * nq)
        return _timed(lambda: (E.ols(Y[rows], y[rows], nq), E.wls(Y[rows], y[rows], nq)))

    iterations: list[int] = []

    def physical(n: float) -> float:
        rows = slice(0, int(n) * nq)
        t0 = time.perf_counter()
        fit = E.physical_fit(Y[rows], y[rows], nq, p, regularization=1e-3)
        iterations.append(max(1, int(fit.iterations)))
        return (time.perf_counter() - t0) / iterations[-1]

    sizes = [250, 500, 1000, 2000] if quick else [500, 1000, 2000, 4000, 8000]
    curve("identification OLS + WLS (standard regressor) vs samples", "samples", sizes, least_squares, progress)
    curve("identification physically consistent fit (IPOPT), time per iteration, vs samples", "samples", sizes,
          physical, progress)
    print(f"  (IPOPT iterations: {', '.join(str(i) for i in iterations)})")


def control_curve(robot: RobotModel, quick: bool, progress: Progress) -> None:
    real = RealRobot.create(robot, 0, TruthConfig())
    config = ControlConfig()
    q0 = 0.5 * (robot.limits.lower_rad + robot.limits.upper_rad)
    amplitude_rad = 0.2

    def run(seconds: float) -> float:
        t = np.arange(0.0, seconds, config.sample_time_s)
        phase = 2 * np.pi * 0.5 * t[:, None]
        q_d = q0 + amplitude_rad * (1 - np.cos(phase))
        v_d = amplitude_rad * np.pi * np.sin(phase) * np.ones(robot.nq)
        a_d = amplitude_rad * np.pi ** 2 * np.cos(phase) * np.ones(robot.nq)
        return _timed(lambda: simulate_joint_trajectory(real, robot, t, q_d, v_d, a_d, config))

    sizes = [0.25, 0.5, 1.0] if quick else [0.25, 0.5, 1.0, 2.0, 4.0]
    run(0.05)     # warm-up: the first call builds the loop's compiled functions, which is not its scaling
    curve("control loop (400 us) vs simulated seconds", "s", sizes, run, progress)


def main(argv: list[str]) -> None:
    names = [a for a in argv if not a.startswith("--")]
    quick = "--quick" in argv
    robot = RobotModel.load(names[0] if names else "rx130l")
    with single_thread_blas(), Progress() as progress:
        design_curves(robot, quick, progress)
        identification_curve(robot, quick, progress)
        control_curve(robot, quick, progress)


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(sys.argv[1:])
