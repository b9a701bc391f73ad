"""Stage 4 targets, measured in one run (paper 004 §5).

Run: ``.venv/bin/python benchmarks/bench_trajectory.py [robot] [cp_segment] [torque_reserve] [energy_starts]``
(default profile). ``robot`` is a built-in name (default ``rx130l``: NOMINAL dynamics) or a robot
folder, e.g. the identified model handed on by stage 2
(``<runs>/<name>/identification/robot``), which is what the pipeline's stage plans with; the
identified RX130L of the default run is heavier than the nominal one (axis-2 gravity torque at the
PtP goal 513 N m instead of 419 N m), so every duration there is longer. Every planner and
baseline (CP, toppra, PtP, ruckig) gets the same dynamics and the same torque limits
``(1 - torque_reserve) x limit`` (default reserve from ``TrajectoryConfig``, as in the stage).
Prints, each as a ratio measured here:

* CP: our duration with toppra's constraints / toppra's (target within 0.5 %), and the fine-grid
  torque violation with the full friction model of our solution and of toppra's (target: ours
  <= 0.5 % where toppra's exceeds it);
* PtP on (-45, 20, 30, 0, 40, 0) deg -> (45, 60, -20, 30, 50, 60) deg: duration / ruckig's
  torque-feasible duration (target <= 0.87), fine-grid violation (<= 0.5 %), energy at ruckig's
  duration / ruckig's (target <= 0.75, and within 2 % of the minimum with the torque limits removed),
  solve time after the one-time compile (target <= 2 s).

Torque and speed limits only (``acceleration_limits = False``: the torque-limited study of paper 004
section 5); ``benchmarks/bench_cp.py`` measures the CP solvers with and without acceleration limits.

``bench_trajectory.py moves [--moves N] [--refine K] [arm ...]``: ``N`` random feasible PtP moves per
arm (default 5, a quick look; the acceptance run is ``bench_trajectory.py moves --moves 50``, about
10 s of CPU per move), quick profile (``configs/quick.yaml``), torque and speed limits only. Arms
(default all): the robot folders rx130l and staubli_tx40, the example-robot-data URDFs ur5 and panda
(the public arms the tests use), and two public arms from another source, FIGAROH's UR10
(``data/figaroh_ur10_mocap/robot.urdf``) and TIAGo arm (``data/figaroh_tiago/tiago_48_schunk.urdf``,
7 axes); any other robot folder, example arm or URDF path may be named. Each arm's NLP is built and
compiled once, start and goal are its parameters. Per move the plan handed on
(:func:`best_ptp_candidate`: NLP from the quintic, from ruckig's profile, or ruckig's profile itself)
/ the torque-feasible ruckig duration, both on the fine grid; per arm the median and worst ratio and
how often each candidate won. Target: ratio <= 1 on every move; a move above 1 prints a ``FAIL`` line
and the exit code is 1. ``--refine K`` sets ``ruckig_refine_evaluations`` (0: bisection and joint
rounds only, faster). ``bench_trajectory.py scaling``: PtP solve time (process CPU) against move
length, grid N and number of joints (6 and 7 axes) with fitted exponents.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from bench_help import exit_on_help

from pipeline.core.errors import PipelineError
from pipeline.robot.defaults import ptp_move_rad
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.run.stages import load_config
from pipeline.trajectory.baselines import ruckig_resampled, ruckig_torque_feasible
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.ptp import energy_weights
from pipeline.trajectory.solve import (
    best_ptp_candidate,
    cp_joint_path,
    plan_cp,
    plan_ptp,
    ptp_problem,
    solve_ptp_verified,
)
from pipeline.trajectory.trajectories import check_trajectory

REPO = Path(__file__).resolve().parent.parent
QUICK = REPO / "configs" / "quick.yaml"
#: public arms from another source than example-robot-data (FIGAROH's published records)
PUBLIC_URDFS = {"figaroh_ur10": REPO / "data" / "figaroh_ur10_mocap" / "robot.urdf",
                "figaroh_tiago": REPO / "data" / "figaroh_tiago" / "tiago_48_schunk.urdf"}
MOVE_ARMS = ("rx130l", "staubli_tx40", "ur5", "panda", "figaroh_ur10", "figaroh_tiago")


def perturbed_starts(problem, q0: np.ndarray, q1: np.ndarray, duration_s: float, n: int, seed: int = 0):
    """Initial guesses for the fixed-duration energy problem: the quintic plus a random joint
    detour ``amp_j sin^2(pi u)`` (up to about 1 rad), to look for other local minima."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 1.0, problem.N + 1)[:, None]
    blend = (10 * u**3 - 15 * u**4 + 6 * u**5, 30 * u**2 - 60 * u**3 + 30 * u**4, 60 * u - 180 * u**2 + 120 * u**3)
    bump = (np.sin(np.pi * u) ** 2, np.pi * np.sin(2 * np.pi * u), 2 * np.pi**2 * np.cos(2 * np.pi * u))
    pm = problem.pm
    for _ in range(n):
        amp = rng.uniform(-1.0, 1.0, pm.nq) * rng.uniform(0.2, 1.0)
        q = np.clip(q0 + (q1 - q0) * blend[0] + amp * bump[0], pm.lower_rad, pm.upper_rad)
        v = ((q1 - q0) * blend[1] + amp * bump[1]) / duration_s
        a = ((q1 - q0) * blend[2] + amp * bump[2]) / duration_s**2
        yield problem.pack(duration_s, q, v, a)


def main(robot_name: str = "rx130l", segment: str = "circle_large", torque_reserve: str | None = None,
         energy_starts: str = "8") -> None:
    cfg = load_config(values={"robot": robot_name, "trajectory.cp_segment": segment,
                              "trajectory.acceleration_limits": False}).trajectory  # + run_defaults
    if torque_reserve is not None:
        cfg.torque_reserve = float(torque_reserve)
    robot = RobotModel.load(robot_name)
    pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
    q_start, q_goal = (ptp_move_rad(robot) if cfg.ptp_start_deg is None     # None: derived from the robot
                       else (np.radians(cfg.ptp_start_deg), np.radians(cfg.ptp_goal_deg)))
    print(f"dynamics: {robot_name} ({'robot folder' if Path(robot_name).is_dir() else 'built-in, nominal dynamics'}); "
          f"static torques at the PtP goal {np.round(pm.rigid_torques(q_goal, 0 * q_goal, 0 * q_goal)[0], 1)} N m")
    print(f"limits for every planner and baseline (CP, toppra, PtP, ruckig): torque (1 - {cfg.torque_reserve:g}) x "
          f"limit = {np.round(pm.effort_Nm, 1)} N m, speed {np.round(pm.velocity_rad_s, 2)} rad/s")
    t0 = time.perf_counter()
    path, piece = cp_joint_path(robot, cfg)
    cp = plan_cp(pm, path, cfg)
    s = cp.summary()
    print(f"CP {segment} ({piece.length_m:.3f} m, N = {cfg.cp_n_grid}), {time.perf_counter() - t0:.1f} s in all; "
          f"planning limits = {1 - cfg.torque_reserve:.2f} x torque limits (reserve for the servo)")
    print(f"  toppra {s['cp_toppra_duration_s']:.5f} s ({1e3 * s['cp_toppra_solve_time_s']:.0f} ms); ours with "
          f"toppra's constraints {s['cp_equal_constraints_duration_s']:.5f} s -> ratio "
          f"{s['cp_equal_vs_toppra_ratio']:.6f} (target |ratio - 1| <= 0.005)")
    print(f"  full friction ({s['cp_method']}): ours {s['cp_duration_s']:.5f} s ({s['cp_solve_time_s']:.2f} s), "
          "fine-grid violation "
          f"ours {100 * s['cp_fine_violation']:.3f} % vs toppra "
          f"{100 * s['cp_toppra_fine_violation_full_friction']:.2f} % (target ours <= 0.5 %)")
    print(f"  smooth variant {s['cp_smooth_duration_s']:.5f} s: time cost {100 * s['cp_smooth_time_cost']:.1f} %, "
          f"violation {100 * s['cp_smooth_fine_violation']:.3f} %, solve {s['cp_smooth_solve_time_s']:.2f} s")
    print(f"  constraint activity: lowest over the grid points {s['cp_grid_min_activity']:.5f} (1 = some limit "
          f"active at every grid point), share of the fine time grid >= 98 % active {s['cp_active_fraction']:.3f}")

    t0 = time.perf_counter()
    problem = ptp_problem(pm, robot, cfg)
    print(f"PtP problem (N = {cfg.ptp_n_intervals}): build {problem.build_time_s:.1f} s, compile "
          f"{problem.compile_time_s:.1f} s (0 when cached), ready after {time.perf_counter() - t0:.1f} s")
    q0, q1 = q_start, q_goal
    ptp = plan_ptp(pm, problem, q0, q1, cfg)
    p = ptp.summary()
    # solve time after compile: a second, cold-started solve of the same move
    again = solve_ptp_verified(pm, problem, q0, q1, cfg, cfg.ptp_k1, cfg.ptp_k2, ptp.weights)
    print(f"  PtP {p['ptp_duration_s']:.4f} s vs ruckig {p['ptp_ruckig_duration_s']:.4f} s -> ratio "
          f"{p['ptp_duration_vs_ruckig_ratio']:.3f} (target <= 0.87)")
    print(f"  fine-grid violation {100 * p['ptp_fine_violation']:.3f} % (target <= 0.5 %), ruckig "
          f"{100 * p['ptp_ruckig_fine_violation']:.3f} %")
    print(f"  energy ({cfg.ptp_energy}) at ruckig's duration / ruckig's: "
          f"{p['ptp_energy_at_ruckig_duration_ratio']:.3f} (target <= 0.75)")
    print(f"  solve time after compile {again.solve_time_s:.2f} s wall, {again.info['cpu_time_s']:.2f} s CPU "
          "(CPU time excludes the other processes on a shared box) (first solve "
          f"{again.info['first_solve_time_s']:.2f} s, {again.info['tightening_rounds']} tightening re-solves, "
          f"{again.iterations} IPOPT iterations; target <= 2 s)")
    for measure in ("torque", "normalised", "electrical"):
        w = energy_weights(pm, measure, cfg.motor_resistance_ohm, cfg.torque_constant_Nm_A, robot.actuation.gear_ratio)
        fixed = solve_ptp_verified(pm, problem, q0, q1, cfg, 0.0, 1.0, w, duration_s=ptp.ruckig.duration_s,
                                   coulomb_widths_rad_s=tuple(cfg.ptp_fixed_coulomb_widths_rad_s))
        e_nlp = check_trajectory(pm, fixed.sample(cfg.fine_dt_s), energy_weights=w).energy
        e_rk = check_trajectory(pm, ptp.ruckig.trajectory, energy_weights=w).energy
        print(f"  energy measure {measure:10s}: at ruckig's duration NLP / ruckig = {e_nlp / e_rk:.3f}")
    # what bounds the energy ratio: the same fixed-duration minimum with the torque limits removed
    # (a looser problem, so its optimum can only be lower), and ruckig's energy spent holding the
    # arm against gravity along its own path
    free = problem.solve(q0, q1, 0.0, 1.0, weights=ptp.weights, duration_s=ptp.ruckig.duration_s,
                         effort_Nm=1e3 * pm.effort_Nm,
                         coulomb_widths_rad_s=tuple(cfg.ptp_fixed_coulomb_widths_rad_s))
    rk = ptp.ruckig.trajectory
    e_rk = check_trajectory(pm, rk, energy_weights=ptp.weights).energy
    e_free = check_trajectory(pm, free.sample(cfg.fine_dt_s), energy_weights=ptp.weights).energy
    hold = pm.rigid_torques(rk.q, 0 * rk.v, 0 * rk.a)
    e_hold = float(np.trapezoid((hold**2) @ ptp.weights, rk.t_s))
    print(f"  energy at ruckig's duration / the minimum without torque limits = "
          f"{p['ptp_energy_at_ruckig_duration'] / e_free:.4f} (target <= 1.02)")
    print(f"  ({cfg.ptp_energy}) without any torque limit the minimum at ruckig's duration is {e_free / e_rk:.3f} x "
          f"ruckig's; holding against gravity along ruckig's path alone is {e_hold / e_rk:.3f} x ruckig's energy")
    ratios = []
    for x0 in perturbed_starts(problem, q0, q1, ptp.ruckig.duration_s, int(energy_starts)):
        try:
            r = problem.solve(q0, q1, 0.0, 1.0, weights=ptp.weights, duration_s=ptp.ruckig.duration_s, x0=x0)
        except Exception as exc:  # noqa: BLE001 - a failed start is reported, not fatal
            print(f"    a perturbed start failed: {exc}")
            continue
        c = check_trajectory(pm, r.sample(cfg.fine_dt_s), energy_weights=ptp.weights)
        if c.violation <= cfg.violation_tolerance:
            ratios.append(c.energy / e_rk)
    if ratios:
        print(f"  ({cfg.ptp_energy}) {len(ratios)} of {energy_starts} perturbed starts of the energy problem converged "
              f"within the limits: NLP / ruckig from {min(ratios):.3f} to {max(ratios):.3f}")
    print(f"  ruckig search {p['ptp_ruckig_search_time_s']:.1f} s; Pareto: " + ", ".join(
        f"k2={r['k2']:g}: {r['duration_s']:.4f} s / {r['energy']:.3f}{' (dominated)' if r.get('dominated') else ''}"
        for r in p["ptp_pareto"]))


def load_arm(name: str) -> RobotModel | None:
    """A public URDF of :data:`PUBLIC_URDFS`, a robot folder or URDF path, else an example-robot-data
    URDF by short name (None: not installed)."""
    if name in PUBLIC_URDFS:
        return RobotModel.load(PUBLIC_URDFS[name]) if PUBLIC_URDFS[name].is_file() else None
    try:
        return RobotModel.load(name)
    except PipelineError:
        urdf = example_arm_urdf(name)
        return None if urdf is None else RobotModel.load(urdf)


def random_moves(pm: PlanningModel, n: int, rng: np.random.Generator, min_step_rad: float = 0.3):
    """``n`` random rest-to-rest moves inside the middle 80 % of every joint range whose holding
    torques at start and goal are within the planning limits (a feasible move exists)."""
    lo, hi = pm.lower_rad, pm.upper_rad
    lo, hi = lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)
    zero = np.zeros(pm.nq)
    found = 0
    while found < n:
        q0, q1 = rng.uniform(lo, hi), rng.uniform(lo, hi)
        if np.max(np.abs(q1 - q0)) < min_step_rad:
            continue
        hold = np.abs(pm.rigid_torques(np.vstack([q0, q1]), np.vstack([zero, zero]), np.vstack([zero, zero])))
        if np.all(hold < 0.9 * pm.effort_Nm):
            found += 1
            yield q0, q1


def moves(*argv: str) -> int:
    """Random moves per arm: plan handed on / torque-feasible ruckig (module docstring). Returns the
    exit code: 1 when a move is slower than ruckig, else 0."""
    ap = argparse.ArgumentParser(prog="bench_trajectory.py moves")
    ap.add_argument("--moves", type=int, default=5, help="random moves per arm (acceptance: 50)")
    ap.add_argument("--refine", type=int, default=None, help="ruckig_refine_evaluations")
    ap.add_argument("arms", nargs="*", default=list(MOVE_ARMS))
    args = ap.parse_args(argv)
    cfg = load_config(QUICK).trajectory
    cfg.acceleration_limits = False                 # torque and speed limits: the full-dynamics case
    if args.refine is not None:
        cfg.ruckig_refine_evaluations = args.refine
    print(f"quick profile: N = {cfg.ptp_n_intervals}, ruckig jerk ratios {cfg.ruckig_jerk_ratios_1_s}, "
          f"{cfg.ruckig_refine_evaluations} ruckig refinement evaluations, fine grid "
          f"{1e3 * cfg.fine_dt_s:g} ms, torque and speed limits only; ratio = plan handed on / ruckig (both on the "
          f"fine grid); {args.moves} random moves per arm (seeded)")
    slower: list[str] = []
    not_planned: list[str] = []
    table: list[str] = []
    for name in args.arms:
        robot = load_arm(name)
        if robot is None:
            print(f"{name}: not installed; skipped")
            continue
        pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
        problem = ptp_problem(pm, robot, cfg)          # built and compiled once; start and goal are parameters
        w = energy_weights(pm, cfg.ptp_energy)
        ratios, sources, cpu, failed = [], {}, 0.0, 0
        for i, (q0, q1) in enumerate(random_moves(pm, args.moves, np.random.default_rng(7))):
            c0 = time.process_time()
            try:
                rk = ruckig_torque_feasible(pm, q0, q1, cfg.ruckig_check_dt_s, tuple(cfg.ruckig_jerk_ratios_1_s),
                                            joint_rounds=cfg.ruckig_joint_rounds,
                                            refine_evaluations=cfg.ruckig_refine_evaluations)
                rk_fine = ruckig_resampled(pm, q0, q1, rk, cfg.fine_dt_s)
                res, tr, _ = best_ptp_candidate(pm, problem, q0, q1, cfg, w, rk_fine)
            except PipelineError as exc:
                failed += 1
                not_planned.append(f"{name} move {i}")
                print(f"  {name} move {i}: {exc}")
                continue
            cpu += time.process_time() - c0
            ratios.append(tr.duration_s / rk.duration_s)
            nlp = tr.info["source"] == "nlp"
            key = tr.info["source"] + (f" (NLP from {res.info['warm_start']})" if nlp else "")
            sources[key] = sources.get(key, 0) + 1
            print(f"  {name} move {i}: ours {tr.duration_s:.4f} s / ruckig {rk.duration_s:.4f} s = "
                  f"{ratios[-1]:.4f} ({key}; NLP candidates {tr.info['nlp_candidates_s']})", flush=True)
            if ratios[-1] > 1.0:
                slower.append(f"{name} move {i} ({ratios[-1]:.4f})")
                print(f"FAIL: {name} move {i}: ours {tr.duration_s:.4f} s is slower than ruckig's "
                      f"{rk.duration_s:.4f} s", flush=True)
        if ratios:
            r = np.asarray(ratios)
            line = (f"{name} ({robot.nq} axes): {r.size} moves ({failed} not planned), ours / ruckig median "
                    f"{np.median(r):.4f}, max {r.max():.4f}, moves slower than ruckig {int(np.sum(r > 1.0))}; "
                    f"plan from {sources}; {cpu / r.size:.1f} s CPU per move")
            table.append(line)
            print(line, flush=True)
    print("summary (ours / ruckig per move, target <= 1 on every move):")
    for line in table:
        print(f"  {line}")
    if slower or not_planned:
        print(f"FAIL: {len(slower)} moves slower than ruckig: " + ", ".join(slower)
              + (f"; moves not planned: {', '.join(not_planned)}" if not_planned else ""))
        return 1
    print("PASS: every move planned, none slower than ruckig (the plan is the best candidate: NLP or ruckig's profile)")
    return 0


def fitted(label: str, x, t) -> None:
    k = np.polyfit(np.log(np.asarray(x, float)), np.log(np.asarray(t, float)), 1)[0]
    print(f"  {label}: time ~ x^k with k = {k:.2f}", flush=True)


def ptp_cpu_s(pm: PlanningModel, robot: RobotModel, cfg, q0: np.ndarray, q1: np.ndarray, n: int) -> tuple[float, float]:
    """Process CPU time of one cold, verified time-optimal solve (NLP not compiled: the CasADi
    virtual machine, so that no gcc run enters the figures) and the duration found."""
    cfg.ptp_n_intervals, cfg.ptp_jit = n, False
    problem = ptp_problem(pm, robot, cfg)
    w = energy_weights(pm, cfg.ptp_energy)
    r = solve_ptp_verified(pm, problem, q0, q1, cfg, cfg.ptp_k1, cfg.ptp_k2, w)
    return r.info["cpu_time_s"], r.duration_s


def scaling(*_: str) -> None:
    """PtP solve time against grid N, move length and number of joints, with fitted exponents."""
    cfg = load_config(QUICK).trajectory
    cfg.acceleration_limits = False
    robot = RobotModel.load("rx130l")
    pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
    q0, q1 = ptp_move_rad(robot)
    print("PtP scaling (process CPU of one cold verified solve, quick profile, torque and speed limits):")
    ns, ts = (12, 25, 50, 100), []
    for n in ns:
        t, d = ptp_cpu_s(pm, robot, cfg, q0, q1, n)
        ts.append(t)
        print(f"  rx130l N = {n:4d}: {t:.2f} s CPU ({d:.4f} s motion)", flush=True)
    fitted("grid N", ns, ts)
    lengths, ts = [], []
    for f in (0.25, 0.5, 0.75, 1.0):
        t, d = ptp_cpu_s(pm, robot, cfg, q0, q0 + f * (q1 - q0), 25)
        lengths.append(float(np.max(np.abs(f * (q1 - q0)))))
        ts.append(t)
        print(f"  rx130l move {lengths[-1]:.2f} rad (largest joint step), N = 25: {t:.2f} s CPU ({d:.4f} s motion)",
              flush=True)
    fitted("move length", lengths, ts)
    joints, ts = [], []
    for arm in ("ur5", "z1", "panda", "xarm7"):
        r = load_arm(arm)
        if r is None:
            continue
        pm_a = PlanningModel.from_robot(r, cfg.torque_reserve)
        a0, a1 = ptp_move_rad(r)
        try:
            t, d = ptp_cpu_s(pm_a, r, cfg, a0, a1, 25)
        except PipelineError as exc:
            print(f"  {arm}: {exc}")
            continue
        joints.append(r.nq)
        ts.append(t)
        print(f"  {arm} ({r.nq} axes), N = 25: {t:.2f} s CPU ({d:.4f} s motion)", flush=True)
    if len(set(joints)) > 1:
        fitted("number of joints (6 and 7 axes)", joints, ts)


if __name__ == "__main__":
    exit_on_help(__doc__)
    if sys.argv[1:2] == ["moves"]:
        sys.exit(moves(*sys.argv[2:]))
    elif sys.argv[1:2] == ["scaling"]:
        scaling(*sys.argv[2:])
    else:
        main(*sys.argv[1:])
