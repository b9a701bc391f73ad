"""Time-optimal targets in the default profile (slow: N = 400 CP grid, compiled N = 50 PtP problem),
torque and speed limits only (acceleration_limits false: the torque-limited study of paper 004 §5).

Run with ``pytest -m slow tests/trajectory``; ``benchmarks/bench_trajectory.py`` prints the same.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.robot.defaults import ptp_move_rad
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.solve import cp_joint_path, plan_cp, plan_ptp, ptp_problem
from pipeline.trajectory.trajectories import check_trajectory

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def setup(rx130l):
    cfg = TrajectoryConfig(ptp_pareto_k2=[], acceleration_limits=False)
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
    q0, q1 = (ptp_move_rad(rx130l) if cfg.ptp_start_deg is None       # None: derived from the robot
              else (np.radians(cfg.ptp_start_deg), np.radians(cfg.ptp_goal_deg)))
    return problem, q0, q1, plan_ptp(pm, problem, q0, q1, cfg, pareto=False)


def test_ptp_targets(setup, ptp):
    cfg, pm = setup
    problem, q0, q1, plan = ptp
    s = plan.summary()
    assert s["ptp_duration_vs_ruckig_ratio"] <= 0.87
    assert s["ptp_fine_violation"] <= 0.005
    # the solve time is a benchmark's figure (benchmarks/bench_trajectory.py), not a test's


def test_ptp_energy_at_ruckig_duration(setup, ptp):
    """At ruckig's duration the minimum-energy motion needs at most 0.75 x ruckig's energy (the
    bang-bang bound: a near bang-bang profile of a pure inertia costs 4/3 of the minimum), and it
    is within 2 % of the same minimum with the torque limits removed (a looser problem): the torque
    limits are not what leaves the energy where it is."""
    cfg, pm = setup
    problem, q0, q1, plan = ptp
    s = plan.summary()
    assert s["ptp_energy_at_ruckig_duration_ratio"] <= 0.75
    assert s["ptp_energy_at_ruckig_duration_fine_violation"] <= cfg.violation_tolerance
    free = problem.solve(q0, q1, 0.0, 1.0, weights=plan.weights, duration_s=plan.ruckig.duration_s,
                         effort_Nm=1e3 * pm.effort_Nm, coulomb_widths_rad_s=tuple(cfg.ptp_fixed_coulomb_widths_rad_s))
    e_free = check_trajectory(pm, free.sample(cfg.fine_dt_s), energy_weights=plan.weights).energy
    assert s["ptp_energy_at_ruckig_duration"] <= 1.02 * e_free
