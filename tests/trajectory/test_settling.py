"""PtP on the elastic truth: smooth variant, settling time, move-and-settle trade-off."""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.ptp import energy_weights
from pipeline.trajectory.ptp_verified import solve_ptp_verified
from pipeline.trajectory.settling import (
    add_smooth_ptp,
    lowest_mode_hz,
    settle_study,
    settling_table,
    slowed_into_limits,
    smooth_trajectory,
    time_scaled,
)
from pipeline.trajectory.trajectories import FINE_GRID_ROUNDOFF, JointTrajectory, check_trajectory


def _bang_bang(dt: float = 1e-3, T: float = 0.4, n: int = 6) -> JointTrajectory:
    """Rest-to-rest move with a piecewise-constant acceleration (infinite jerk at the switches)."""
    t = np.arange(0.0, T + dt / 2, dt)
    amp = np.linspace(1.0, 3.0, n)
    first = t[:, None] < T / 2
    a = np.where(first, amp, -amp)
    a[[0, -1]] = 0.0
    v = np.where(first, amp * t[:, None], amp * (T - t[:, None]))
    q = np.where(first, 0.5 * amp * t[:, None] ** 2, amp * T**2 / 4 - 0.5 * amp * (T - t[:, None]) ** 2)
    return JointTrajectory("bang", t, q, v, a)


def test_smooth_trajectory_keeps_endpoints_and_bounds_jerk():
    tr = _bang_bang()
    T_f = 0.05
    sm = smooth_trajectory(tr, T_f)
    assert np.allclose(sm.q[0], tr.q[0]) and np.allclose(sm.q[-1], tr.q[-1], atol=1e-12)
    assert np.allclose(sm.v[[0, -1]], 0.0, atol=1e-12)
    assert abs(sm.duration_s - (tr.duration_s + T_f)) < 1.5e-3
    dt = sm.t_s[1] - sm.t_s[0]
    # consistent derivatives (the filter commutes with differentiation)
    assert np.allclose(np.gradient(sm.q, dt, axis=0)[1:-1], sm.v[1:-1], atol=2e-3 * np.abs(sm.v).max())
    jerk = np.abs(np.diff(sm.a, axis=0)) / dt
    assert np.all(jerk.max(axis=0) <= np.ptp(tr.a, axis=0) / T_f * 1.05)
    assert np.all(np.abs(sm.a).max(axis=0) <= np.abs(tr.a).max(axis=0) + 1e-12)


def test_lowest_mode_scales_with_sqrt_stiffness(rx130l):
    q = np.radians([0, 30, 60, 0, 30, 0])
    k = nominal_joint_stiffness_Nm_rad(rx130l)
    f = lowest_mode_hz(rx130l, q)
    assert 0.5 < f < 200.0
    assert np.isclose(lowest_mode_hz(rx130l, q, 4 * k), 2 * f, rtol=1e-9)
    assert lowest_mode_hz(rx130l, q, k * np.r_[0.5, np.ones(5)]) <= f   # a softer joint lowers it


def test_smooth_ptp_settles_faster_on_the_elastic_truth(rx130l_generic_stiffness, ptp_problem, quick_config):
    # an arm whose first mode rings visibly: the RX130L with the generic (33x softer) joint stiffness
    rx130l = rx130l_generic_stiffness
    cfg = quick_config.trajectory
    pm = PlanningModel.from_robot(rx130l, cfg.torque_reserve)    # as the stage plans
    q0, q1 = np.radians(cfg.ptp_start_deg), np.radians(cfg.ptp_goal_deg)
    # the time-optimal NLP plan slowed into its fine-grid limits, as the stage's plan_ptp makes it (without the
    # ruckig baseline, the energy plan and the Pareto sweep, which the settling study does not read), on the
    # session's compiled problem: the same NLP (its code holds neither the stiffness nor the torque limits,
    # which solve_ptp_verified passes from ``pm``); settle_study adds the smooth variant
    weights = energy_weights(pm, cfg.ptp_energy)
    res = solve_ptp_verified(pm, ptp_problem, q0, q1, cfg, cfg.ptp_k1, cfg.ptp_k2, weights)
    plans = {"ptp": slowed_into_limits(pm, res.sample(cfg.fine_dt_s, "ptp"), FINE_GRID_ROUNDOFF,
                                       cfg.acceleration_limits, weights)[0]}
    # the run's seed with the default truth (elastic joints, Stribeck friction), and a truth without the
    # Stribeck and load-dependent friction: their stick-slip creep of the wrist can set the last 0.1 mrad
    # on other seeds (seed 3: smooth 1.12 s vs 0.63 s; docs/stages/trajectory.md), the gear ringing never
    truths = [(quick_config.seed, TruthConfig()),
              (3, TruthConfig(stribeck_excess_relative=0.0, coulomb_load_coefficient=0.0))]
    for seed, truth in truths:
        real = RealRobot.create(rx130l, seed, truth)
        assert real.plant.elastic                                  # the default truth: elastic joints
        results, s = settle_study(real, rx130l, plans, None, np.random.default_rng(3))
        opt, sm = results["ptp"], results["ptp_smooth"]
        assert np.isfinite(opt.settling_time_s) and np.isfinite(sm.settling_time_s)
        assert sm.settling_time_s < opt.settling_time_s and s["ptp_smooth_settles_faster"], seed
        # the smoothing removes most of the ringing at the goal, for one filter length of motion time
        vib = lambda r: r.position_error_m[r.t_s >= r.duration_s].max()  # noqa: E731
        assert vib(sm) < 0.5 * vib(opt)
        assert np.isclose(sm.duration_s - opt.duration_s, s["ptp_smooth_filter_time_s"], atol=2e-3)
        assert s["ptp_move_and_settle_s"] == opt.duration_s + opt.settling_time_s
        # the elastic-joint feedforward drives the link, not the motor, along the plan: less ringing
        assert s["ptp_elastic_ff_residual_vibration_max_m"] < 0.5 * s["ptp_settle_residual_vibration_max_m"]
        assert "ptp (elastic_flat)" in results and "ptp_smooth_settles_faster_elastic_ff" in s
    table = settling_table(list(results.values()))
    assert "move + settle [s]" in table and all(f"| {n} |" in table for n in results)


def test_time_scaling_keeps_the_path_and_slows_the_derivatives():
    tr = _bang_bang()
    slow = time_scaled(tr, 1.25)
    assert np.array_equal(slow.q, tr.q) and slow.duration_s == 1.25 * tr.duration_s
    assert np.allclose(slow.v, tr.v / 1.25) and np.allclose(slow.a, tr.a / 1.25**2)


def test_smooth_ptp_is_slowed_into_the_limits(rx130l, pm, big_move_plan, quick_traj_config):
    """The moving average of a plan on its torque limits may leave them; with a tolerance the smooth
    plan is slowed down until its fine-grid check holds (and not slowed when it already does)."""
    cfg = quick_traj_config
    # its own dicts: add_smooth_ptp adds the smooth variant to the shared plan's trajectories and checks
    plan = dataclasses.replace(big_move_plan, trajectories=dict(big_move_plan.trajectories),
                               checks=dict(big_move_plan.checks))
    tol = cfg.violation_tolerance
    raw = smooth_trajectory(plan.trajectories["ptp"], 1.0 / lowest_mode_hz(rx130l, plan.q1))
    smooth = add_smooth_ptp(pm, rx130l, plan, tolerance=tol, acceleration_limits=cfg.acceleration_limits)
    chk = plan.checks["ptp_smooth"]
    assert chk.violation <= tol and chk.max_velocity_ratio <= 1 + tol
    raw_chk = check_trajectory(pm, raw)
    if raw_chk.violation <= tol and raw_chk.max_velocity_ratio <= 1 + tol:
        assert smooth.duration_s == raw.duration_s
    else:
        assert smooth.duration_s > raw.duration_s and smooth.info["time_scale"] > 1


def test_a_plan_over_its_limits_is_slowed_exactly_into_them(pm, big_move_plan):
    """The interpolated plan may pass a limit between the NLP's nodes: slowed_into_limits stretches
    time until every fine-grid ratio is within the tolerance, and leaves a plan within them alone."""
    traj = big_move_plan.trajectories["ptp"]
    fast = time_scaled(traj, 0.97, "ptp")             # 3 % too fast: over a speed or torque limit
    check = check_trajectory(pm, fast)
    assert check.max_velocity_ratio > 1.0 + 1e-4 or check.violation > 1e-4
    slowed, check = slowed_into_limits(pm, fast, 1e-4)
    assert check.violation <= 1e-4 and check.max_velocity_ratio <= 1.0 + 1e-4
    assert 1.0 < slowed.info["time_scale"] / 0.97 < 1.04     # not slower than needed (to the bisection)
    same, _ = slowed_into_limits(pm, slowed, 1e-4)
    assert same is slowed
