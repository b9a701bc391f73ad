"""Continuous path: convex formulation vs toppra, friction refinement, smooth variant, errors."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from pipeline.core.errors import ConfigError, InfeasibleError
from pipeline.trajectory import baselines
from pipeline.trajectory.baselines import toppra_cp, toppra_within_limits
from pipeline.trajectory.cp import _fric_sx, solve_cp_convex, solve_cp_refined
from pipeline.trajectory.cp_smooth import solve_cp_smooth
from pipeline.trajectory.design import JointPath
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.solve import cp_joint_path, plan_cp, shorter_cp
from pipeline.trajectory.trajectories import FINE_GRID_ROUNDOFF, check_trajectory, within_limits


def test_convex_with_toppra_constraints_matches_toppra(pm, line_path):
    tp = toppra_cp(pm, line_path, 150)
    eq = solve_cp_convex(pm, line_path, 150, midpoints=False)
    assert abs(eq.duration_s / tp.duration_s - 1.0) < 0.005
    # rest to rest, speeds within limits at the grid
    assert eq.sdot[0] == pytest.approx(0.0, abs=1e-9) and eq.sdot[-1] == pytest.approx(0.0, abs=1e-9)
    q, dq, _ = line_path.derivatives(eq.s)
    assert np.all(np.abs(dq) * eq.sdot[:, None] <= pm.velocity_rad_s * (1 + 1e-6))


@pytest.mark.parametrize("method", ["reachability", "nlp"])
def test_refined_respects_full_friction_where_toppra_does_not(pm, line_path, quick_traj_config, method):
    # torque-limited (no acceleration limits): the case where toppra's missing viscous term shows
    plan = plan_cp(pm, line_path, dataclasses.replace(quick_traj_config, cp_smooth=False, cp_method=method,
                                                      acceleration_limits=False))
    tol = quick_traj_config.violation_tolerance
    assert plan.checks["cp"].violation <= tol
    assert plan.checks["cp_toppra"].violation > tol          # viscous friction is not in toppra
    assert plan.optimal.duration_s >= plan.equal.duration_s   # more torque demand -> not faster
    assert plan.summary()["cp_source"] == "ours"               # toppra's shorter profile breaks a limit
    tr = plan.trajectories["cp"]
    # the sampled trajectory follows the path from its start to its end, at rest at both ends
    assert np.allclose(tr.q[0], line_path(0.0), atol=1e-9) and np.allclose(tr.q[-1], line_path(1.0), atol=1e-6)
    assert np.abs(tr.v[0]).max() < 1e-9 and np.abs(tr.v[-1]).max() < 1e-6
    # time-optimal: some constraint is (nearly) active most of the time on the fine grid, and at
    # every grid point a constraint of an adjacent interval is active (necessary condition)
    assert plan.activity["active_fraction"] > 0.5
    assert plan.activity["grid_min_activity"] >= 0.999


def _scaled(profile, factor: float, name: str):
    """``profile`` run ``factor`` times as fast along the same path (speeds x factor)."""
    return dataclasses.replace(profile, name=name, sdot=factor * profile.sdot, sddot=factor**2 * profile.sddot,
                               duration_s=profile.duration_s / factor)


def test_the_cp_handed_on_is_toppras_feasible_profile_only_when_shorter(pm, line_path, quick_traj_config):
    tol, dt = quick_traj_config.violation_tolerance, quick_traj_config.fine_dt_s
    tp = toppra_cp(pm, line_path, 80, acceleration_limits=True)
    peer = toppra_within_limits(pm, line_path, tp, dt, tol, True)
    slow_ours = _scaled(tp, 0.5, "cp")
    chosen = shorter_cp(slow_ours, peer)
    assert chosen.info["source"] == "toppra" and chosen.name == "cp"
    assert chosen.duration_s == peer.duration_s and chosen.info["ours_duration_s"] == slow_ours.duration_s
    fast_ours = _scaled(peer, 1.001, "cp")
    assert shorter_cp(fast_ours, peer) is fast_ours and shorter_cp(slow_ours, None) is slow_ours
    plan = plan_cp(pm, line_path, dataclasses.replace(quick_traj_config, cp_smooth=False))
    assert plan.optimal.duration_s <= plan.toppra_feasible.duration_s          # never slower than the peer
    assert within_limits(plan.checks["cp"], tol, True)
    # the peer that may replace ours keeps the limits to round-off, not to the gates' slack
    peer_check = check_trajectory(pm, plan.toppra_feasible.sample(line_path, dt))
    assert within_limits(peer_check, FINE_GRID_ROUNDOFF, True)
    assert not within_limits(check_trajectory(pm, _scaled(plan.toppra_feasible, 1.002, "fast").sample(line_path, dt)),
                             FINE_GRID_ROUNDOFF, True)          # and is not slowed further than that needs


def test_toppra_over_a_limit_between_its_grid_points_is_refined_then_slowed_to_the_limits(
        pm, line_path, quick_traj_config, monkeypatch):
    tol, dt = quick_traj_config.violation_tolerance, quick_traj_config.fine_dt_s
    tp = toppra_cp(pm, line_path, 150, acceleration_limits=True)
    own = check_trajectory(pm, tp.sample(line_path, dt))
    assert not within_limits(own, tol, True)            # collocation: a joint acceleration over between points
    peer = toppra_within_limits(pm, line_path, tp, dt, tol, True)
    assert peer is not None and peer is not tp
    assert within_limits(check_trajectory(pm, peer.sample(line_path, dt)), tol, True)
    assert peer.info["n_grid"] in (300, 600, 1200) and "time_scale" not in peer.info   # a denser grid suffices
    monkeypatch.setattr(baselines, "TOPPRA_GRID_REFINEMENTS", ())                  # no refinement: slowed
    slowed = toppra_within_limits(pm, line_path, tp, dt, tol, True)
    assert slowed is not None and within_limits(check_trajectory(pm, slowed.sample(line_path, dt)), tol, True)
    scale = slowed.info["time_scale"]
    assert 1.0 < scale <= np.sqrt(own.max_acceleration_ratio) * (1 + 2 * tol)
    assert slowed.duration_s == pytest.approx(scale * tp.duration_s, rel=1e-12)
    assert slowed.duration_s > peer.duration_s         # the denser grid is the stronger peer
    fine = _scaled(tp, 0.5, "slow")                     # within the limits as it is: returned unchanged
    assert toppra_within_limits(pm, line_path, fine, dt, tol, True) is fine


#: session fixtures that take seconds and serve several tests: their tests run on one pytest-xdist
#: worker, so each is built once per ``make test`` (tests/conftest.py, pytest_collection_modifyitems)
SHARED_COSTLY_FIXTURES = frozenset({"refined_line"})


@pytest.fixture(scope="session")
def refined_line(pm, line_path):
    """The friction-refined time-optimal CP of the ISO line on 120 intervals (read, not changed, by its tests)."""
    return solve_cp_refined(pm, line_path, solve_cp_convex(pm, line_path, 120))


def test_smooth_variant_is_continuous_and_slower(pm, line_path, refined_line):
    opt = refined_line
    sm = solve_cp_smooth(pm, line_path, opt, n_intervals=40, torque_margin=0.004)
    assert sm.duration_s >= opt.duration_s * (1 - 1e-6)
    dt = 2e-4
    tr = sm.sample(line_path, dt)
    jump_a = np.abs(np.diff(tr.a, axis=0)).max(axis=0)
    jerk_bound = sm.jerk_limit_rad_s3
    # accelerations change at most by (jerk limit) * dt (+ slack for the sampled jerk limit)
    assert np.all(jump_a <= 2.0 * jerk_bound * dt + 1e-9)
    assert np.abs(tr.a[0]).max() < 1e-6 and np.abs(tr.a[-1]).max() < 1e-3
    assert check_trajectory(pm, tr).violation <= 0.01


def test_piecewise_acceleration_profile_jumps(line_path, refined_line):
    """The non-smooth optimum has acceleration jumps (that is what the smooth variant removes)."""
    tr = refined_line.sample(line_path, 2e-4)
    assert np.abs(tr.a[1] - tr.a[0]).max() < np.abs(np.diff(tr.a, axis=0)).max()


def test_unreachable_path_names_the_point(rx130l, quick_traj_config):
    cfg = dataclasses.replace(quick_traj_config, cp_centre_m=[2.5, 0.0, 0.3])
    with pytest.raises(InfeasibleError) as err:
        cp_joint_path(rx130l, cfg)
    assert "m" in str(err.value) and ("not reach" in str(err.value) or "point" in str(err.value))


def test_joint_path_rejects_too_few_samples():
    with pytest.raises(InfeasibleError):
        JointPath(np.linspace(0, 1, 4), np.zeros((4, 6)))


def test_impossible_torque_limits_raise(pm, line_path):
    weak = dataclasses.replace(pm, effort_Nm=pm.effort_Nm * 0.05)   # cannot even hold against gravity
    with pytest.raises(InfeasibleError, match="joint 2 torque limit"):
        solve_cp_convex(weak, line_path, 60)


SPLINE_POINTS_M = [[0.9, -0.3, 0.2], [1.0, -0.1, 0.35], [0.95, 0.15, 0.3], [0.85, 0.3, 0.45]]


def test_spline_through_points_is_followed(rx130l, pm, quick_traj_config):
    """cp_segment = spline: the joint path passes the given points (FK) and plans like the ISO pieces."""
    cfg = dataclasses.replace(quick_traj_config, cp_segment="spline", cp_points_m=SPLINE_POINTS_M, cp_smooth=False)
    path, piece = cp_joint_path(rx130l, cfg)
    data = rx130l.model.createData()
    fid = rx130l.model.getFrameId(rx130l.frame_tcp)
    for s, p in ((0.0, SPLINE_POINTS_M[0]), (1.0, SPLINE_POINTS_M[-1])):
        pin.framesForwardKinematics(rx130l.model, data, path(s))
        assert np.allclose(data.oMf[fid].translation, p, atol=1e-6)
    # an interior sample lies on the Cartesian spline
    pin.framesForwardKinematics(rx130l.model, data, path(0.4))
    assert np.min(np.linalg.norm(piece.position(np.linspace(0, piece.length_m, 4001)) - data.oMf[fid].translation,
                                 axis=1)) < 1e-3
    plan = plan_cp(pm, path, cfg)
    assert plan.checks["cp"].violation <= cfg.violation_tolerance


@pytest.mark.parametrize("points, field", [([[0.9, 0.0, 0.3], [1.0, 0.0, 0.3]], r"cp_points_m\b"),
                                           ([[0.9, 0.0, 0.3], [1.0, 0.0], [1.0, 0.1, 0.3]], r"cp_points_m\[1\]"),
                                           ([[0.9, 0.0, 0.3], [0.9, 0.0, 0.3], [1.0, 0.1, 0.3]],
                                            r"cp_points_m\[1\]")])
def test_bad_spline_points_are_named(rx130l, quick_traj_config, points, field):
    cfg = dataclasses.replace(quick_traj_config, cp_segment="spline", cp_points_m=points)
    with pytest.raises(ConfigError, match=field):
        cp_joint_path(rx130l, cfg)


def test_path_friction_switches_each_joint_with_its_own_width(rx130l) -> None:
    """The continuous-path NLP's friction along the path (``fv q' s' + fc tanh(q' s' / w_j)``) equals the
    planning model's, joint by joint, when the Coulomb smoothing differs per joint."""
    robot = rx130l.copy()
    robot.spec.actuation.coulomb_smoothing_rad_s = np.array([0.2, 0.05, 0.01, 0.1, 0.002, 0.03])
    pm = PlanningModel.from_robot(robot)
    dq = np.random.default_rng(4).normal(size=(5, robot.nq))
    sdot = np.array([0.001, 0.01, 0.02, 0.05, 0.1])
    x = ca.SX.sym("x", len(sdot))
    friction = ca.Function("friction", [x], [_fric_sx(pm, dq, x)])
    np.testing.assert_allclose(np.asarray(friction(sdot)), pm.friction(dq * sdot[:, None]), rtol=1e-12, atol=1e-12)
