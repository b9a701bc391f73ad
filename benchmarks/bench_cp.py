"""CP with the full friction model: reachability solver vs toppra vs the NLP reference, and scaling.

Run: ``.venv/bin/python benchmarks/bench_cp.py [--no-scaling] [robot ...]`` (default ``rx130l
staubli_tx40 ur5 panda``; ``ur5``, ``panda`` and the other names of
:data:`pipeline.robot.example_robots.EXAMPLE_ARMS`: the example-robot-data URDF alone on a
joint-space move, see :func:`urdf_joint_move`).
For each robot and CP piece (its default profile's ISO circle and line, torque and speed limits
only, N = 400, planning limits ``(1 - torque_reserve) x limit``), measured in this process as
process CPU time (the box is shared: CPU time excludes the other processes), first calls included
(a run plans once: a one-time set-up is part of its cost; the reachability solver's cached passes
are cleared before each of our timings, toppra is timed as its best of 3):

* one solve of the reachability CP (viscous + smooth Coulomb friction, torques at grid points and
  midpoints) / toppra's single solve (rigid body + sharp Coulomb, grid points);
* the verified plan (one solve, the fine-grid check with the full friction model, local re-solves
  of the intervals that exceed, as the stage does: :func:`pipeline.trajectory.solve.verified_cp`) /
  toppra's single solve: target <= 2 on every arm;
* duration / the NLP reference's (convex + IPOPT refinement, same constraints): target within 0.1 %;
* the verified plan's fine-grid torque violation: target <= 0.5 %;
* the same with the robot's acceleration limits (``trajectory.acceleration_limits``).

Then scaling (CPU time, each the best of 3, fitted exponent ``k`` of ``time ~ x^k`` by a
least-squares line in log-log): against the grid N = 100 ... 1600 and the path length (ISO cube
edges 0.4 ... 1 x the default; one solve and the verified plan, whose fine-grid check grows with
the motion's duration) on the first robot, and against the number of joints (joint-space
moves with a detour on the 6- and 7-axis example-robot-data arms, N = 400).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from bench_help import exit_on_help

from pipeline.core.errors import PipelineError
from pipeline.robot.defaults import iso_cube
from pipeline.robot.example_robots import EXAMPLE_ARMS, example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.run.stages import load_config
from pipeline.trajectory.baselines import toppra_cp
from pipeline.trajectory.cp import solve_cp_convex, solve_cp_refined
from pipeline.trajectory.design import JointPath
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.reachability import _passes, solve_cp_reachability
from pipeline.trajectory.solve import cp_joint_path, verified_cp
from pipeline.trajectory.trajectories import check_trajectory

REPEATS = 5
N_GRID = 400
SCALING_N = (100, 200, 400, 800, 1600)


def best_time(fn, repeats: int = REPEATS) -> tuple[float, object]:
    """Best process CPU time of ``repeats`` calls and the last result."""
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def first_time(fn) -> tuple[float, object]:
    t0 = time.process_time()
    out = fn()
    return time.process_time() - t0, out


def verified(pm: PlanningModel, path: JointPath, cfg, acceleration_limits: bool):
    """One reachability solve, then the stage's fine-grid verification and local re-solves."""
    def solve(scale, acceleration_scale, warm):
        return solve_cp_reachability(pm, path, N_GRID, torque_scale=scale, acceleration_limits=acceleration_limits,
                                     warm=warm, acceleration_scale=acceleration_scale)
    first = solve(None, None, None)
    return verified_cp(pm, path, first, cfg, solve)


def report(label: str, pm: PlanningModel, path: JointPath, cfg, acceleration_limits: bool, nlp=None) -> float:
    """Prints the figures of the module docstring for one path; returns verified / toppra."""
    # ours cold (first call, as in a run), toppra's best of 3 (the stricter comparison)
    _passes.cache_clear()
    t_ver, (ra, rounds) = first_time(lambda: verified(pm, path, cfg, acceleration_limits))
    _passes.cache_clear()
    t_one, _ = first_time(lambda: solve_cp_reachability(pm, path, N_GRID, acceleration_limits=acceleration_limits))
    t_tp, tp = best_time(lambda: toppra_cp(pm, path, N_GRID, acceleration_limits=acceleration_limits), 3)
    chk = check_trajectory(pm, ra.sample(path, cfg.fine_dt_s))
    ref = "" if nlp is None else f"; duration / NLP - 1 = {ra.duration_s / nlp.duration_s - 1:+.2e} (target <= 1e-3)"
    print(f"  {label}: toppra {1e3 * t_tp:.1f} ms CPU ({tp.duration_s:.5f} s); one solve {1e3 * t_one:.1f} ms "
          f"= {t_one / t_tp:.2f} x toppra; verified plan {1e3 * t_ver:.1f} ms = {t_ver / t_tp:.2f} x toppra (<= 2; "
          f"{rounds} re-solves) -> {ra.duration_s:.5f} s, fine-grid violation {100 * chk.violation:.3f} % (target "
          f"<= 0.5 %), max acceleration ratio {chk.max_acceleration_ratio:.4f}{ref}", flush=True)
    return t_ver / t_tp


def compare(robot: RobotModel, name: str, segment: str) -> list[float]:
    values = None if name == "rx130l" else {"robot": name}
    cfg = load_config(None, values=values).trajectory
    cfg.cp_segment = segment
    pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
    path, piece = cp_joint_path(robot, cfg)
    t0 = time.process_time()
    nlp = solve_cp_refined(pm, path, solve_cp_convex(pm, path, N_GRID))
    t_nlp = time.process_time() - t0
    print(f"{name} {segment} ({piece.length_m:.3f} m, N = {N_GRID}); NLP reference {t_nlp:.2f} s CPU "
          f"({nlp.duration_s:.5f} s)")
    return [report("torque and speed limits", pm, path, cfg, False, nlp),
            report("with acceleration limits", pm, path, cfg, True)]


def urdf_joint_move(arm: str = "ur5") -> tuple[PlanningModel, JointPath] | None:
    """An example-robot-data arm from its URDF alone (no robot.yaml: friction assumed, viscous 2 N m s/rad
    and Coulomb 3 N m per joint, acceleration limits 15 rad/s^2, 10 % torque reserve) on a joint-space
    move with a detour across 40 % of each joint's range (no ISO path: that needs the robot's IK setup)."""
    urdf = example_arm_urdf(arm)
    if urdf is None:
        return None
    robot = RobotModel.load(urdf)                   # the arm's joints (fingers locked)
    model = robot.model
    n = model.nq
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)
    pm = PlanningModel(model, robot.limits.lower_rad, robot.limits.upper_rad, robot.limits.velocity_rad_s,
                       0.9 * robot.limits.effort_Nm, np.full(n, 2.0), np.full(n, 3.0), 0.01, np.full(n, 15.0))
    s = np.linspace(0.0, 1.0, 60)
    q0, q1 = lo + 0.3 * (hi - lo), lo + 0.7 * (hi - lo)
    path = JointPath(s, q0 + np.outer(s, q1 - q0) + 0.1 * (hi - lo) * np.sin(np.pi * s)[:, None],
                     name=f"{arm} joint move")
    return pm, path


def arm_joint_move(arm: str) -> list[float]:
    made = urdf_joint_move(arm)
    if made is None:
        print(f"{arm}: example-robot-data not installed; skipped")
        return []
    pm, path = made
    cfg = load_config(None).trajectory
    nlp = solve_cp_refined(pm, path, solve_cp_convex(pm, path, N_GRID))
    print(f"{arm} (URDF only, {pm.nq} axes, joint move, N = {N_GRID}); NLP reference {nlp.duration_s:.5f} s")
    return [report("torque and speed limits", pm, path, cfg, False, nlp),
            report("with acceleration limits", pm, path, cfg, True)]


def fitted(label: str, x, t) -> None:
    k = np.polyfit(np.log(np.asarray(x, float)), np.log(np.asarray(t, float)), 1)[0]
    print(f"  {label}: time ~ x^k with k = {k:.2f}", flush=True)


def both_times(pm: PlanningModel, path: JointPath, n: int, ours: list, theirs: list):
    """Best-of-3 CPU times of the reachability CP and of toppra at grid ``n``, appended to the lists."""
    t_ra, ra = best_time(lambda: solve_cp_reachability(pm, path, n, acceleration_limits=False), 3)
    t_tp, _ = best_time(lambda: toppra_cp(pm, path, n), 3)
    ours.append(t_ra)
    theirs.append(t_tp)
    return t_ra, ra, t_tp


def fitted_pair(label: str, x, ours: list, theirs: list) -> None:
    fitted(f"{label}, reachability", x, ours)
    fitted(f"{label}, toppra", x, theirs)


def scaling(robot: RobotModel, name: str) -> None:
    values = None if name == "rx130l" else {"robot": name}
    cfg = load_config(None, values=values).trajectory
    pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
    path, _ = cp_joint_path(robot, cfg)
    ours: list[float] = []
    theirs: list[float] = []
    print(f"scaling on {name} ({cfg.cp_segment}), process CPU, best of 3:")
    for n in SCALING_N:
        t_ra, ra, t_tp = both_times(pm, path, n, ours, theirs)
        print(f"  N = {n:5d}: reachability {1e3 * t_ra:8.1f} ms ({ra.info['friction_rounds']} rounds), "
              f"toppra {1e3 * t_tp:8.1f} ms, ratio {t_ra / t_tp:.2f}")
    fitted_pair("grid N", SCALING_N, ours, theirs)
    cube = iso_cube(robot, cfg.cp_plane, None, frame=robot.frame_tcp)
    lengths: list[float] = []
    ours, theirs, checked = [], [], []
    for f in (0.4, 0.6, 0.8, 1.0):
        cfg.cp_edge_m, cfg.cp_centre_m = f * cube.edge_m, list(cube.centre_m)
        path, piece = cp_joint_path(robot, cfg)
        t_ra, ra, t_tp = both_times(pm, path, N_GRID, ours, theirs)
        t_ver, _ = best_time(lambda path=path: verified(pm, path, cfg, False), 3)
        checked.append(t_ver)
        lengths.append(piece.length_m)
        print(f"  path {piece.length_m:.3f} m: reachability {1e3 * t_ra:.1f} ms ({ra.duration_s:.4f} s motion), "
              f"verified plan {1e3 * t_ver:.1f} ms, toppra {1e3 * t_tp:.1f} ms")
    fitted_pair("path length (N fixed)", lengths, ours, theirs)
    # the fine-grid check grows with the motion's duration (one sample every fine_dt_s)
    fitted("path length (N fixed), verified plan", lengths, checked)
    joints: list[int] = []
    ours, theirs = [], []
    for arm in ("ur5", "z1", "ur10", "panda", "xarm7"):
        made = urdf_joint_move(arm)
        if made is None:
            continue
        t_ra, _, t_tp = both_times(*made, N_GRID, ours, theirs)
        joints.append(made[0].nq)
        print(f"  {arm} ({made[0].nq} axes, joint move): reachability {1e3 * t_ra:.1f} ms, toppra {1e3 * t_tp:.1f} ms")
    if len(set(joints)) > 1:
        fitted_pair("number of joints (6 and 7 axes)", joints, ours, theirs)


def main(*args: str) -> None:
    names = [a for a in args if a != "--no-scaling"] or ["rx130l", "staubli_tx40", "ur5", "panda"]
    ratios: dict[str, list[float]] = {}
    for name in names:
        if name in EXAMPLE_ARMS:
            ratios[name] = arm_joint_move(name)
            continue
        try:
            robot = RobotModel.load(name)
        except PipelineError as exc:
            print(f"{name}: no robot model in this tree ({exc}); skipped")
            continue
        cfg = load_config(None, values=None if name == "rx130l" else {"robot": name}).trajectory
        ratios[name] = []
        for segment in dict.fromkeys((cfg.cp_segment, "line")):
            ratios[name] += compare(robot, name, segment)
    print("verified plan / toppra's single solve (CPU), worst per arm: " + ", ".join(
        f"{n} {max(r):.2f}" for n, r in ratios.items() if r) + " (target <= 2)")
    worst = max((max(r) for r in ratios.values() if r), default=None)
    if worst is not None:
        print(f"{'PASS' if worst <= 2.0 else 'FAIL'}: worst verified plan / toppra {worst:.2f} (target <= 2)")
    built_in = [n for n in names if n not in EXAMPLE_ARMS]
    if built_in and "--no-scaling" not in args:
        scaling(RobotModel.load(built_in[0]), built_in[0])


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(*sys.argv[1:])
