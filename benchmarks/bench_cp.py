"""CP with the full friction model: reachability solver vs toppra vs the NLP reference, and scaling.

Run: ``.venv/bin/python benchmarks/bench_cp.py [robot ...]`` (default ``rx130l staubli_tx40 ur5``;
``ur5``: the example-robot-data URDF alone on a joint-space move, see :func:`ur5_joint_move`).
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
import pinocchio as pin

from pipeline.config import load_config
from pipeline.errors import PipelineError
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.trajectory.baselines import toppra_cp
from pipeline.trajectory.cp import solve_cp_convex, solve_cp_refined
from pipeline.trajectory.design import JointPath
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


def ur5_joint_move() -> None:
    """The UR5 of example-robot-data from its URDF alone (no robot.yaml: friction assumed, viscous
    2 N m s/rad and Coulomb 3 N m per joint, acceleration limits 15 rad/s^2, 10 % torque reserve)
    on a joint-space move with a detour (no ISO path: that needs the robot's IK setup)."""
    urdf = example_arm_urdf("ur5")
    if urdf is None:
        print("ur5: example-robot-data not installed; skipped")
        return
    model = pin.buildModelFromUrdf(str(urdf))
    n = model.nq
    pm = PlanningModel(model, model.lowerPositionLimit.copy(), model.upperPositionLimit.copy(),
                       model.velocityLimit.copy(), 0.9 * model.effortLimit.copy(), np.full(n, 2.0), np.full(n, 3.0),
                       0.01, np.full(n, 15.0))
    s = np.linspace(0.0, 1.0, 60)
    q0 = np.array([0.0, -1.2, 1.0, -1.4, -1.57, 0.0])
    q1 = np.array([2.0, -0.3, 2.2, -2.4, -0.6, 1.5])
    path = JointPath(s, q0 + np.outer(s, q1 - q0) + 0.3 * np.sin(np.pi * s)[:, None], name="ur5 joint move")
    t_tp, tp = best_time(lambda: toppra_cp(pm, path, N_GRID))
    t_ra, ra = best_time(lambda: solve_cp_reachability(pm, path, N_GRID, acceleration_limits=False))
    nlp = solve_cp_refined(pm, path, solve_cp_convex(pm, path, N_GRID))
    chk = check_trajectory(pm, ra.sample(path, 2e-4))
    print(f"ur5 (URDF only, joint move): toppra {1e3 * t_tp:.1f} ms ({tp.duration_s:.5f} s), reachability "
          f"{1e3 * t_ra:.1f} ms ({ra.duration_s:.5f} s); time ours / toppra = {t_ra / t_tp:.2f}; duration ours / NLP "
          f"- 1 = {ra.duration_s / nlp.duration_s - 1:+.2e}; fine-grid violation {100 * chk.violation:.3f} %; max "
          f"torque ratio {chk.max_torque_ratio:.3f}, speed ratio {chk.max_velocity_ratio:.3f}")


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
    names = list(robots) or ["rx130l", "staubli_tx40", "ur5"]
    for name in names:
        if name == "ur5":
            ur5_joint_move()
            continue
        try:
            robot = RobotModel.load(name)
        except PipelineError as exc:
            print(f"{name}: no robot model in this tree ({exc}); skipped")
            continue
        cfg = load_config(None, values=None if name == "rx130l" else {"robot": name}).trajectory
        for segment in dict.fromkeys((cfg.cp_segment, "line")):
            compare(robot, name, segment)
    built_in = [n for n in names if n != "ur5"]
    if not built_in:
        return
    first = built_in[0]
    segment = load_config(None, values=None if first == "rx130l" else {"robot": first}).trajectory.cp_segment
    print(f"scaling on {first} ({segment}):")
    scaling(RobotModel.load(first), first)


if __name__ == "__main__":
    main(*sys.argv[1:])
