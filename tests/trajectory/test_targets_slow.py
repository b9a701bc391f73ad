"""Issue 6 targets in the default profile (slow: N = 400 CP grid, compiled N = 50 PtP problem).

Run with ``pytest -m slow tests/trajectory``; ``benchmarks/bench_trajectory.py`` prints the same.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.solve import cp_joint_path, plan_cp, plan_ptp, ptp_problem, solve_ptp_verified

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def setup(rx130l):
    cfg = TrajectoryConfig(ptp_pareto_k2=[])
    return cfg, PlanningModel.from_robot(rx130l, cfg.torque_reserve)


def test_cp_targets(rx130l, setup):
    cfg, pm = setup
    path, _ = cp_joint_path(rx130l, cfg)
    s = plan_cp(pm, path, cfg).summary()
    assert abs(s["cp_equal_vs_toppra_ratio"] - 1.0) <= 0.005
    assert s["cp_fine_violation"] <= 0.005 < s["cp_toppra_fine_violation_full_friction"]
    assert s["cp_smooth_fine_violation"] <= 0.005


@pytest.fixture(scope="module")
def ptp(rx130l, setup):
    cfg, pm = setup
    problem = ptp_problem(pm, rx130l, cfg)
    q0, q1 = np.radians(cfg.ptp_start_deg), np.radians(cfg.ptp_goal_deg)
    return problem, q0, q1, plan_ptp(pm, problem, q0, q1, cfg, pareto=False)


def test_ptp_targets(setup, ptp):
    cfg, pm = setup
    problem, q0, q1, plan = ptp
    s = plan.summary()
    assert s["ptp_duration_vs_ruckig_ratio"] <= 0.87
    assert s["ptp_fine_violation"] <= 0.005
    again = solve_ptp_verified(pm, problem, q0, q1, cfg, cfg.ptp_k1, cfg.ptp_k2, plan.weights)
    assert again.info["cpu_time_s"] <= 2.0        # CPU time: the box is shared


@pytest.mark.xfail(strict=True, reason="issue 6 target not met: against a ruckig baseline whose 12 acceleration "
                   "limits are searched jointly, the energy at ruckig's duration is 0.70-0.74 x ruckig's. The torque "
                   "limits are not what binds: with them removed the minimum is still 0.70 x (benchmarks/"
                   "bench_trajectory.py prints it); for a pure inertia a near bang-bang profile costs only 4/3 of the "
                   "minimum (ratio 0.75), and holding the arm against gravity is 0.3 of ruckig's energy on this move. "
                   "Quintic, stretched time-optimal, resampled ruckig, via-pose, Pareto-point and perturbed starts, "
                   "Coulomb-width continuation and N = 80 all give 0.70-0.78")
def test_ptp_energy_at_ruckig_duration(ptp):
    assert ptp[3].summary()["ptp_energy_at_ruckig_duration_ratio"] <= 0.6
