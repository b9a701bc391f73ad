"""Point to point: one compiled problem shared by all tests (session fixture)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.errors import InfeasibleError, PipelineError, SolverError
from pipeline.trajectory.baselines import ruckig_torque_feasible
from pipeline.trajectory.ptp import energy_weights
from pipeline.trajectory.solve import plan_ptp
from pipeline.trajectory.trajectories import check_trajectory


@pytest.fixture(scope="module")
def plan(pm, ptp_problem, big_move, quick_traj_config):
    cfg = dataclasses.replace(quick_traj_config, ptp_pareto_k2=[0.1, 1.0])
    return plan_ptp(pm, ptp_problem, *big_move, cfg)


def test_rest_to_rest_within_limits(plan, pm, big_move, quick_traj_config):
    tr = plan.trajectories["ptp"]
    q0, q1 = big_move
    assert np.allclose(tr.q[0], q0) and np.allclose(tr.q[-1], q1, atol=1e-8)
    assert np.abs(tr.v[0]).max() < 1e-9 and np.abs(tr.v[-1]).max() < 1e-6
    assert np.abs(tr.a[0]).max() < 1e-6 and np.abs(tr.a[-1]).max() < 1e-6   # continuous acceleration
    chk = plan.checks["ptp"]
    assert chk.violation <= quick_traj_config.violation_tolerance
    assert chk.max_velocity_ratio <= 1.0 + quick_traj_config.violation_tolerance
    assert np.all(tr.q >= pm.lower_rad - 1e-9) and np.all(tr.q <= pm.upper_rad + 1e-9)


def test_faster_than_torque_feasible_ruckig(plan):
    assert plan.checks["ptp_ruckig"].max_torque_ratio <= 1.0 + 1e-9
    assert plan.result.duration_s < plan.ruckig.duration_s


def test_energy_optimum_at_ruckig_duration(plan):
    fixed = plan.at_ruckig_duration
    assert fixed.duration_s == pytest.approx(plan.ruckig.duration_s, rel=1e-9)
    assert plan.checks["ptp_energy_at_ruckig_duration"].energy < plan.checks["ptp_ruckig"].energy


def test_pareto_trades_time_for_energy(plan):
    T = [r.duration_s for r in plan.pareto]
    E = [r.energy for r in plan.pareto]
    assert T[-1] >= T[0] - 1e-6 and E[-1] <= E[0] + 1e-6


def test_warm_start_from_own_solution_stays_put(plan, ptp_problem, big_move):
    """Primal + dual warm start at a solution: IPOPT confirms it in a few iterations, same motion."""
    res = plan.result
    again = ptp_problem.solve(*big_move, res.k1, res.k2, weights=plan.weights,
                              effort_Nm=ptp_problem.pm.effort_Nm * np.asarray(res.info["torque_scale"]),
                              velocity_rad_s=ptp_problem.pm.velocity_rad_s * np.asarray(res.info["velocity_scale"]),
                              x0=res.info["x"], coulomb_widths_rad_s=(), multipliers=res.info["multipliers"])
    assert again.iterations <= 10 < res.iterations
    assert again.duration_s == pytest.approx(res.duration_s, rel=1e-5)


def test_goal_outside_limits_is_named(ptp_problem, big_move):
    q0, _ = big_move
    bad = q0.copy()
    bad[1] = np.radians(170.0)
    with pytest.raises(InfeasibleError, match="joint 2"):
        ptp_problem.solve(q0, bad)


def test_unattainable_duration_raises(ptp_problem, big_move, pm):
    with pytest.raises((InfeasibleError, SolverError)):
        ptp_problem.solve(*big_move, k1=0.0, k2=1.0, weights=energy_weights(pm, "normalised"), duration_s=0.05)


def test_compiled_library_is_reused(pm, rx130l, ptp_problem, quick_traj_config):
    from pipeline.trajectory.solve import ptp_problem as make

    mtime = ptp_problem.library.stat().st_mtime_ns
    again = make(pm, rx130l, quick_traj_config)
    assert again.library == ptp_problem.library
    assert again.library.stat().st_mtime_ns == mtime          # loaded from the cache, not rebuilt


def test_energy_measure_names(pm):
    assert np.allclose(energy_weights(pm, "torque"), 1.0)
    assert np.allclose(energy_weights(pm, "normalised"), pm.effort_Nm**-2)
    w = energy_weights(pm, "electrical", np.ones(6), np.ones(6), np.full(6, 10.0))
    assert np.allclose(w, 0.01)
    with pytest.raises(PipelineError):
        energy_weights(pm, "joules")


def test_ruckig_search_respects_torques(pm, big_move):
    rk = ruckig_torque_feasible(pm, *big_move, jerk_ratios_1_s=(25.0,), joint_rounds=1)
    chk = check_trajectory(pm, rk.trajectory)
    assert chk.max_torque_ratio <= 1.0
    assert np.diff(rk.trajectory.t_s).max() <= 5e-4 + 1e-12




def test_ruckig_refinement_is_feasible_and_not_slower(pm, big_move):
    """The Nelder-Mead refinement of the ruckig limits never returns a slower or an infeasible move
    (checked on the 0.5 ms grid), and it is counted in the evaluations."""
    q0, q1 = big_move
    plain = ruckig_torque_feasible(pm, q0, q1, jerk_ratios_1_s=(25.0,), joint_rounds=2)
    refined = ruckig_torque_feasible(pm, q0, q1, jerk_ratios_1_s=(25.0,), joint_rounds=2, refine_evaluations=200)
    assert refined.duration_s <= plain.duration_s + 1e-9
    assert refined.evaluations > plain.evaluations
    assert np.diff(refined.trajectory.t_s).max() <= 5e-4 + 1e-12
    assert check_trajectory(pm, refined.trajectory).max_torque_ratio <= 1.0 + 1e-9
