"""CP with the full friction model: reachability solver vs toppra vs the NLP reference, and scaling.

Run: ``.venv/bin/python benchmarks/bench_cp.py [robot ...]`` (default ``rx130l staubli_tx40``).
For each robot and CP piece (its default profile's ISO circle and line, torque and speed limits
only, N = 400, planning limits ``(1 - torque_reserve) x limit``), measured in this process:

* solve time of the reachability CP (viscous + smooth Coulomb friction, torques at grid points and
  midpoints) / toppra's (rigid body + sharp Coulomb, grid points): target <= 3 (each the best of 5);
* duration / the NLP reference's (convex + IPOPT refinement, same constraints): target within 0.1 %;
* fine-grid torque violation with the full friction model (single solve, no tightening): <= 0.5 %;
* the same with the robot's acceleration limits (``trajectory.acceleration_limits``).

Then the scaling curve: solve time vs N = 100 ... 1600 on the first robot's circle and the fitted
exponent ``k`` of ``time ~ N^k`` (a least-squares line in log-log), for ours and toppra's.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from pipeline.config import load_config
from pipeline.errors import PipelineError
from pipeline.robot.model import RobotModel
from pipeline.trajectory.baselines import toppra_cp
from pipeline.trajectory.cp import solve_cp_convex, solve_cp_refined
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.reachability import solve_cp_reachability
from pipeline.trajectory.solve import cp_joint_path
from pipeline.trajectory.trajectories import check_trajectory

REPEATS = 5
N_GRID = 400
SCALING_N = (100, 200, 400, 800, 1600)


def best_time(fn, repeats: int = REPEATS) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def compare(robot: RobotModel, name: str, segment: str) -> None:
    values = None if name == "rx130l" else {"robot": name}
    cfg = load_config(None, values=values).trajectory
    cfg.cp_segment = segment
    pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
    path, _ = cp_joint_path(robot, cfg)
    t_tp, tp = best_time(lambda: toppra_cp(pm, path, N_GRID))
    t_ra, ra = best_time(lambda: solve_cp_reachability(pm, path, N_GRID, acceleration_limits=False))
    t0 = time.perf_counter()
    nlp = solve_cp_refined(pm, path, solve_cp_convex(pm, path, N_GRID))
    t_nlp = time.perf_counter() - t0
    viol = check_trajectory(pm, ra.sample(path, cfg.fine_dt_s)).violation
    print(f"{name} {segment}: toppra {1e3 * t_tp:.1f} ms ({tp.duration_s:.5f} s), reachability {1e3 * t_ra:.1f} ms "
          f"({ra.duration_s:.5f} s, {ra.info['friction_rounds']} friction rounds), NLP {t_nlp:.2f} s "
          f"({nlp.duration_s:.5f} s)")
    print(f"  time ours / toppra = {t_ra / t_tp:.2f} (target <= 3); NLP / ours = {t_nlp / t_ra:.0f}; duration ours / "
          f"NLP - 1 = {ra.duration_s / nlp.duration_s - 1:+.2e} (target |.| <= 1e-3); fine-grid violation "
          f"{100 * viol:.3f} % (target <= 0.5 %)")
    t_tpa, tpa = best_time(lambda: toppra_cp(pm, path, N_GRID, acceleration_limits=True))
    t_raa, raa = best_time(lambda: solve_cp_reachability(pm, path, N_GRID, acceleration_limits=True))
    chk = check_trajectory(pm, raa.sample(path, cfg.fine_dt_s))
    print(f"  with acceleration limits: ours {raa.duration_s:.5f} s in {1e3 * t_raa:.1f} ms (toppra {1e3 * t_tpa:.1f} "
          f"ms, {tpa.duration_s:.5f} s); fine grid: torque violation {100 * chk.violation:.3f} %, max acceleration "
          f"ratio {chk.max_acceleration_ratio:.4f}")


def scaling(robot: RobotModel, name: str) -> None:
    values = None if name == "rx130l" else {"robot": name}
    cfg = load_config(None, values=values).trajectory
    pm = PlanningModel.from_robot(robot, cfg.torque_reserve)
    path, _ = cp_joint_path(robot, cfg)
    ours, theirs = [], []
    for n in SCALING_N:
        t_ra, ra = best_time(lambda n=n: solve_cp_reachability(pm, path, n, acceleration_limits=False), 3)
        t_tp, _ = best_time(lambda n=n: toppra_cp(pm, path, n), 3)
        ours.append(t_ra)
        theirs.append(t_tp)
        print(f"  N = {n:5d}: reachability {1e3 * t_ra:8.1f} ms ({ra.info['friction_rounds']} rounds), "
              f"toppra {1e3 * t_tp:8.1f} ms, ratio {t_ra / t_tp:.2f}")
    logn = np.log(np.asarray(SCALING_N, float))
    k_ours = np.polyfit(logn, np.log(ours), 1)[0]
    k_tp = np.polyfit(logn, np.log(theirs), 1)[0]
    print(f"  scaling exponent (time ~ N^k): reachability k = {k_ours:.2f}, toppra k = {k_tp:.2f} (near linear: k ~ 1)")


def main(*robots: str) -> None:
    names = list(robots) or ["rx130l", "staubli_tx40"]
    for name in names:
        try:
            robot = RobotModel.load(name)
        except PipelineError as exc:
            print(f"{name}: no robot model in this tree ({exc}); skipped")
            continue
        cfg = load_config(None, values=None if name == "rx130l" else {"robot": name}).trajectory
        for segment in dict.fromkeys((cfg.cp_segment, "line")):
            compare(robot, name, segment)
    first = names[0]
    segment = load_config(None, values=None if first == "rx130l" else {"robot": first}).trajectory.cp_segment
    print(f"scaling on {first} ({segment}):")
    scaling(RobotModel.load(first), first)


if __name__ == "__main__":
    main(*sys.argv[1:])
