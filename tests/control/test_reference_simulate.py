"""Reference generation (ruckig + IK) and the closed loop on the real robot's plant."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.control.config import ControlConfig
from pipeline.control.simulate import check_finite, simulate_joint_trajectory
from pipeline.core.errors import InfeasibleError, SolverError
from pipeline.robot.iso9283 import iso9283_path
from pipeline.robot.paths import CirclePath, LinePath, start_configuration
from pipeline.robot.reference import cartesian_reference
from pipeline.sim.truth import RealRobot, TruthConfig

DOWN = pin.utils.rotate("x", np.pi)
SEEDS = np.radians([[0.0, 17.0, 86.0, 0.0, 75.0, 0.0]])


@pytest.fixture(scope="module")
def real(rx130l):
    return RealRobot.create(rx130l, 5, TruthConfig.ideal())  # the rigid-arm figures


@pytest.fixture(scope="module")
def circle_ref(rx130l):
    path = CirclePath([0.9, 0.0, 0.35], [0, 0, 1], 0.1, [1, 0, 0], rotation=DOWN)
    q0 = start_configuration(rx130l, path.poses([0.0])[0], SEEDS)
    return cartesian_reference(rx130l, path, 4e-4, 0.5, 2.0, 20.0, q0)


def test_reference_is_consistent(rx130l, circle_ref):
    ref = circle_ref
    dt = 4e-4
    # IK: the nominal FK of q_d is the desired TCP
    np.testing.assert_allclose(rx130l.positions(ref.q_d[::50]), ref.tcp_d_m[::50], atol=1e-8)
    # v_d and a_d are the time derivatives of q_d and v_d
    v_fd = np.gradient(ref.q_d, dt, axis=0)
    a_fd = np.gradient(ref.v_d, dt, axis=0)
    assert np.abs(v_fd - ref.v_d)[1:-1].max() < 1e-3 * max(1.0, np.abs(ref.v_d).max())
    assert np.abs(a_fd - ref.a_d)[1:-1].max() < 2e-2 * max(1.0, np.abs(ref.a_d).max())
    # ruckig limits along the path: speed and tangential acceleration
    assert ref.tcp_speed_m_s.max() <= 0.5 + 1e-9
    assert np.abs(np.gradient(ref.tcp_speed_m_s, dt)).max() <= 2.0 * 1.01
    assert ref.tcp_speed_m_s[0] == 0.0 and abs(ref.tcp_speed_m_s[-1]) < 1e-6


def test_unreachable_point_names_time_and_joint(rx130l):
    path = LinePath([0.9, 0.0, 0.35], [2.4, 0.0, 0.35], rotation=DOWN)  # leaves the workspace
    q0 = start_configuration(rx130l, path.poses([0.0])[0], SEEDS)
    with pytest.raises(InfeasibleError, match=r"t = \d+\.\d+ s.*joint \d"):
        cartesian_reference(rx130l, path, 4e-4, 0.5, 2.0, 20.0, q0)


@pytest.fixture(scope="module")
def joint_traj():
    """A 2 s joint-space motion with the forearm near vertical (low gravity on joint 3)."""
    dt = 4e-4
    T = 2.0
    t = np.arange(0.0, T + dt / 2, dt)
    q0 = np.array([0.0, -0.15, 0.15, 0.0, 0.6, 0.0])
    A = np.array([0.8, 0.3, -0.3, 0.8, 0.6, 1.0])
    w = 2 * np.pi / T
    s, sd, sdd = (1 - np.cos(w * t)) / 2, w * np.sin(w * t) / 2, w * w * np.cos(w * t) / 2
    return t, q0 + A * s[:, None], A * sd[:, None], A * sdd[:, None]


def _lag(res):
    return np.abs(res.lag_error_rad).max(axis=0)


def test_feedforward_cuts_lag_errors(real, rx130l, joint_traj):
    t, q, v, a = joint_traj
    cfg = ControlConfig(settle_time_s=0.2)
    runs = {name: simulate_joint_trajectory(real, model, t, q, v, a, cfg, variant, np.random.default_rng(0))
            for name, model, variant in (("none", rx130l, "none"), ("nominal", rx130l, "full_friction"),
                                         ("truth", real.truth, "full_friction"))}
    none, nominal, exact = (_lag(runs[k]) for k in ("none", "nominal", "truth"))
    assert np.all(nominal[:3] < none[:3] / 3)   # nominal model (20 % off) still helps on axes 1-3
    assert np.all(exact < none / 5)             # the exact model: >= 5x on every axis
    r = runs["truth"]
    assert r.q.shape == q.shape and r.tcp_position_m.shape == (len(t), 3)
    assert r.realtime_factor > 1.0
    assert np.all(r.max_torque_ratio < 1.0)


def test_delays_hurt_unless_compensated(real, joint_traj):
    t, q, v, a = joint_traj
    lags = {}
    for adv in (True, False):
        cfg = ControlConfig(settle_time_s=0.2, advance_feedforward=adv)
        res = simulate_joint_trajectory(real, real.truth, t, q, v, a, cfg, "full_friction", np.random.default_rng(0))
        lags[adv] = _lag(res)[:3]
    # 2 samples late set points: lag ~ v * 0.8 ms, far above the compensated run
    assert np.all(lags[False] > 3 * lags[True])


def test_saturation_is_an_error_naming_time_and_joint(real, joint_traj):
    t, q, v, a = joint_traj
    free = simulate_joint_trajectory(real, real.truth, t, q, v, a, ControlConfig(settle_time_s=0.1),
                                     "full_friction", np.random.default_rng(0))
    weaker = 0.5 * float(free.max_torque_ratio.max())  # pretend the drives are weaker than needed
    cfg = ControlConfig(settle_time_s=0.1, saturation_ratio=weaker)
    with pytest.raises(InfeasibleError, match=r"saturation at t = \d+\.\d+ s on joint \d"):
        simulate_joint_trajectory(real, real.truth, t, q, v, a, cfg, "full_friction", np.random.default_rng(0))
    res = simulate_joint_trajectory(real, real.truth, t, q, v, a, ControlConfig(settle_time_s=0.1,
                                    saturation_ratio=weaker, on_saturation="clip"), "full_friction",
                                    np.random.default_rng(0))
    assert res.max_torque_ratio.max() > weaker


def test_resampling_of_a_coarse_trajectory(real, joint_traj):
    t, q, v, a = joint_traj
    k = slice(None, None, 5)  # 2 ms input grid
    cfg = ControlConfig(settle_time_s=0.1)
    res = simulate_joint_trajectory(real, real.truth, t[k], q[k], v[k], a[k], cfg, "full_friction",
                                    np.random.default_rng(0))
    assert np.allclose(np.diff(res.t_s), 4e-4)
    assert np.abs(res.q_d - q[: len(res.q_d)]).max() < 1e-6


def test_iso_path_reference_runs(rx130l):
    path = iso9283_path(rx130l, 0.5, [0.9, 0.0, 0.3], "diagonal_x", DOWN, segments=("line", "circle_small"))
    q0 = start_configuration(rx130l, path.poses([0.0])[0], SEEDS)
    ref = cartesian_reference(rx130l, path, 4e-4, 1.0, 5.0, 50.0, q0)
    assert set(ref.segment_labels) >= {"line P2-P4", "circle_small"}
    # the small circle (radius 25 mm) is run slower: normal acceleration v^2/r <= 5 m/s^2
    small = np.array(ref.segment_labels)[ref.segment] == "circle_small"
    assert ref.tcp_speed_m_s[small].max() <= np.sqrt(5.0 * 0.025) + 1e-9


def test_trajectory_starting_in_motion(real, joint_traj):
    t, q, v, a = joint_traj
    k = slice(len(t) // 4, None)  # starts at full speed
    res = simulate_joint_trajectory(real, real.truth, t[k], q[k], v[k], a[k], ControlConfig(), "full_friction",
                                    np.random.default_rng(0))
    assert len(res.t_s) == len(t[k])
    assert np.abs(res.lag_error_rad).max() < 1e-3  # no jump from a rest start


def test_a_diverged_loop_is_named_with_the_least_inertia_not_passed_on(rx130l):
    """A closed loop whose measured positions turn non-finite stops with the time, the joints and the joint
    of least inertia in the model (the servo gains' source), not with NaNs in the metrics."""
    n, nq = 5, rx130l.nq
    q = np.zeros((n, nq))
    q[3:, 4] = np.nan
    t = 4e-4 * np.arange(n)
    inertia = np.diag(rx130l.mass_matrix(np.zeros(nq)))
    least = int(np.argmin(inertia)) + 1
    with pytest.raises(SolverError, match=rf"diverged at t = 0\.0012 s \(joint\(s\) 5 not finite\).* joint {least}:"):
        check_finite(t, q, rx130l, np.zeros(nq))
    check_finite(t, np.zeros((n, nq)), rx130l, np.zeros(nq))
