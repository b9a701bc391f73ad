"""Reachability CP (TOPP-RA with the full friction model) against the NLP reference; acceleration
limits in every planner; IPOPT interrupt statuses."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from pipeline.core.errors import InfeasibleError
from pipeline.core.interrupts import INTERRUPT_STATUSES, raise_if_interrupted
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.trajectory.baselines import toppra_cp
from pipeline.trajectory.cp import cp_grid_activity, solve_cp_convex, solve_cp_refined
from pipeline.trajectory.design import JointPath
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.reachability import _argmax_concave, solve_cp_reachability
from pipeline.trajectory.solve import plan_cp, verified_cp
from pipeline.trajectory.trajectories import check_trajectory

N_SMALL = 80


@pytest.mark.parametrize("acc", [False, True])
def test_duration_matches_the_nlp(pm, line_path, acc):
    """Same discretisation, same constraints: the greedy reachability profile is the NLP's optimum."""
    ra = solve_cp_reachability(pm, line_path, N_SMALL, acceleration_limits=acc)
    nlp = solve_cp_refined(pm, line_path, solve_cp_convex(pm, line_path, N_SMALL, acceleration_limits=acc),
                           acceleration_limits=acc)
    assert abs(ra.duration_s / nlp.duration_s - 1.0) <= 1e-3
    assert ra.sdot[0] == 0.0 and ra.sdot[-1] == 0.0 and np.all(ra.sdot[1:-1] > 0)


def test_slower_than_toppra_with_viscous_friction(pm, line_path):
    """Viscous friction only removes torque headroom: never faster than toppra (Coulomb only)."""
    ra = solve_cp_reachability(pm, line_path, N_SMALL, acceleration_limits=False)
    tp = toppra_cp(pm, line_path, N_SMALL)
    assert ra.duration_s > tp.duration_s


def test_limits_hold_on_the_fine_grid(pm, line_path, quick_traj_config):
    cfg = dataclasses.replace(quick_traj_config, cp_smooth=False, cp_method="reachability", acceleration_limits=True)
    plan = plan_cp(pm, line_path, cfg)
    chk = plan.checks["cp"]
    tol = cfg.violation_tolerance
    assert chk.violation <= tol
    assert chk.max_velocity_ratio <= 1.0 + tol
    assert chk.max_acceleration_ratio <= 1.0 + tol
    # the acceleration limits bind on this path (without them the motion is faster and exceeds them)
    free = solve_cp_reachability(pm, line_path, cfg.cp_n_grid, acceleration_limits=False)
    assert check_trajectory(pm, free.sample(line_path, cfg.fine_dt_s)).max_acceleration_ratio > 1.0 + tol
    assert plan.optimal.duration_s > free.duration_s
    # the toppra baseline gets the same acceleration limits, at its collocation points (grid points)
    tp = plan.toppra
    _, dq, ddq = line_path.derivatives(tp.s[:-1])
    acc = ddq * (tp.sdot[:-1] ** 2)[:, None] + dq * tp.sddot[:, None]
    assert np.max(np.abs(acc) / pm.acceleration_rad_s2) <= 1.0 + 1e-6


def test_unholdable_path_raises(pm, line_path):
    weak = dataclasses.replace(pm, effort_Nm=pm.effort_Nm * 0.05)
    with pytest.raises(InfeasibleError, match="torque limit"):
        solve_cp_reachability(weak, line_path, 40)


def test_ptp_and_ruckig_respect_acceleration_limits(pm, big_move_plan, quick_traj_config):
    """The session's plan of the big move (conftest) is planned with the acceleration limits of the quick
    profile: its NLP solution and its torque-feasible ruckig baseline keep them."""
    cfg = quick_traj_config
    assert cfg.acceleration_limits
    res = big_move_plan.result                                # the time-optimal NLP solution (k1 = 1, k2 = 0.01)
    assert res.info["solver_status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    chk = check_trajectory(pm, res.sample(cfg.fine_dt_s))
    assert chk.max_acceleration_ratio <= 1.0 + 1e-6          # linear between nodes: node bounds are exact
    assert chk.violation <= cfg.violation_tolerance
    assert check_trajectory(pm, big_move_plan.ruckig.trajectory).max_acceleration_ratio <= 1.0 + 1e-6


@pytest.mark.parametrize("status", sorted(INTERRUPT_STATUSES))
def test_interrupt_statuses_are_interrupts(status):
    with pytest.raises(KeyboardInterrupt):
        raise_if_interrupted(status, "cp")
    raise_if_interrupted("Solve_Succeeded", "cp")              # no exception


def _panda_arm() -> PlanningModel:
    """The 7-axis Franka Panda of example-robot-data (fingers locked), with stated friction."""
    urdf = example_arm_urdf("panda")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    full = pin.buildModelFromUrdf(str(urdf))
    fingers = [full.getJointId(n) for n in full.names if "finger" in n]
    model = pin.buildReducedModel(full, fingers, pin.neutral(full))
    n = model.nq
    return PlanningModel(model, model.lowerPositionLimit.copy(), model.upperPositionLimit.copy(),
                         model.velocityLimit.copy(), model.effortLimit.copy(), np.full(n, 0.5), np.full(n, 1.0),
                         0.01, np.full(n, 10.0))


def test_seven_axes_match_the_nlp():
    """n axes: the same solver on a 7-axis arm and a joint-space path, against the NLP reference."""
    pm7 = _panda_arm()
    assert pm7.nq == 7
    s = np.linspace(0.0, 1.0, 40)
    q0 = np.array([0.0, -0.5, 0.0, -2.0, 0.0, 1.6, 0.8])
    q1 = np.array([1.2, 0.3, -0.6, -1.2, 0.7, 2.4, -0.4])
    q = q0 + np.outer(s, q1 - q0) + 0.2 * np.sin(np.pi * s)[:, None]
    path = JointPath(s, q, name="panda move")
    for acc in (False, True):
        ra = solve_cp_reachability(pm7, path, 60, acceleration_limits=acc)
        nlp = solve_cp_refined(pm7, path, solve_cp_convex(pm7, path, 60, acceleration_limits=acc),
                               acceleration_limits=acc)
        assert abs(ra.duration_s / nlp.duration_s - 1.0) <= 1e-3


def test_stage_maximiser_is_the_maximum_of_the_lower_envelope():
    """The maximiser of every stage's concave H(y) = min_r (p_r + s_r y) on [0, hi] reaches the
    largest value of H on a fine grid of [0, hi], from a cold start and from a perturbed warm start,
    also when H only rises (maximiser hi) or only falls (maximiser 0) on [0, hi]."""
    rng = np.random.default_rng(3)
    n, r = 300, 12
    p = rng.uniform(0.5, 2.0, (n, r))
    sl = rng.uniform(-3.0, 3.0, (n, r))
    sl[0] = np.abs(sl[0]) + 0.1                      # rising throughout
    sl[1] = -np.abs(sl[1])                           # falling throughout
    hi = rng.uniform(0.1, 2.0, n)
    grid = np.linspace(0.0, 1.0, 4001)[None, :] * hi[:, None]
    h_grid = np.min(p[:, :, None] + sl[:, :, None] * grid[:, None, :], axis=1).max(axis=1)
    cold = _argmax_concave(p, sl, hi)
    warm = _argmax_concave(p, sl, hi, cold * rng.uniform(0.9, 1.1, n))
    for y in (cold, warm):
        assert np.all((y >= 0.0) & (y <= hi))
        assert np.all(np.min(p + sl * y[:, None], axis=1) >= h_grid - 1e-12)
    assert cold[0] == hi[0] and cold[1] == 0.0


def test_local_tightening_reuses_the_solver_and_meets_the_tightened_limits(pm, line_path):
    """A re-solve of the NLP with the limits of some grid intervals tightened reuses the built solver
    with the previous primal and dual solution (fewer IPOPT iterations than the cold solve), keeps
    the torques within their limits at the check points, and is slower (a binding limit was tightened)."""
    cold = solve_cp_refined(pm, line_path, solve_cp_convex(pm, line_path, N_SMALL))
    level = cp_grid_activity(pm, line_path, cold)
    k = int(np.argmax(level[1:-1])) + 1                 # an interval with a binding limit
    scale = np.ones((N_SMALL, pm.nq))
    scale[max(k - 3, 0):k + 3] = 0.97
    again = solve_cp_refined(pm, line_path, cold, torque_scale=scale)
    assert again.nlp is cold.nlp and again.info["warm_started_multipliers"]
    assert again.info["iterations"] < cold.info["iterations"]
    assert again.duration_s > cold.duration_s * (1 + 1e-6)     # a binding limit tightened: the plan slows
    assert cp_grid_activity(pm, line_path, again).max() <= 1.0 + 1e-6
    assert again.info["solver_status"] == "Solve_Succeeded"


def test_batched_inverse_dynamics_equals_one_call_per_sample(pm):
    """The batched RNEA of the fine-grid check and the path coefficients gives pin.rnea's torques."""
    rng = np.random.default_rng(5)
    q, v, a = (rng.uniform(-1.0, 1.0, (40, pm.nq)) for _ in range(3))
    data = pm.model.createData()
    one_by_one = np.array([pin.rnea(pm.model, data, q[k], v[k], a[k]) for k in range(40)])
    assert np.allclose(pm.rigid_torques(q, v, a), one_by_one, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("method", ["reachability", "nlp"])
def test_fine_grid_acceleration_excess_is_tightened_away(pm, quick_traj_config, method):
    """A coarse grid on a curved path: the joint accelerations, enforced at each interval's ends and
    midpoint, exceed their limits between them; the fine-grid verification tightens those intervals."""
    cfg = dataclasses.replace(quick_traj_config, acceleration_limits=True)
    s = np.linspace(0.0, 1.0, 41)
    q = np.radians([0, 30, 60, 0, 45, 0]) + np.outer(np.sin(3 * np.pi * s), np.radians([40, 10, 15, 60, 30, 90]))
    path = JointPath(s, q, "wavy")
    n_grid = 20

    def solve(torque_scale, acceleration_scale, warm):
        if method == "reachability":
            return solve_cp_reachability(pm, path, n_grid, torque_scale=torque_scale, acceleration_limits=True,
                                         warm=warm, acceleration_scale=acceleration_scale)
        return solve_cp_refined(pm, path, warm, torque_scale=torque_scale, acceleration_limits=True,
                                acceleration_scale=acceleration_scale)

    first = solve(None, None, None if method == "reachability"
                  else solve_cp_convex(pm, path, n_grid, midpoints=True, acceleration_limits=True))
    tol = cfg.violation_tolerance
    assert check_trajectory(pm, first.sample(path, cfg.fine_dt_s)).max_acceleration_ratio > 1.0 + tol
    verified, rounds = verified_cp(pm, path, first, cfg, solve)
    check = check_trajectory(pm, verified.sample(path, cfg.fine_dt_s))
    assert rounds >= 1 and check.max_acceleration_ratio <= 1.0 + tol and check.violation <= tol
    assert verified.info["acceleration_scale"] is not None
    assert 1.0 <= verified.duration_s / first.duration_s < 1.01          # tightened only where it exceeded
