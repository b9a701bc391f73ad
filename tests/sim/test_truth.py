"""The hidden real robot and its sensors."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.core.errors import ConfigError
from pipeline.robot.instruments import tracker_visibility
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import KinematicLayout, dynamic_parameter_problems
from pipeline.robot.payload import Payload, gravity_torques_Nm, with_payload
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.sim.sensors import LaserTracker
from pipeline.sim.truth import RealRobot, TruthConfig

IDEAL = dict(joint_compliance_scale=0.0, transmission_error_amplitude_rad=0.0, tracker_outlier_rate=0.0,
             tracker_stale_rate=0.0)


@pytest.fixture(scope="module")
def real(rx130l: RobotModel) -> RealRobot:
    return RealRobot.create(rx130l, seed=11)


def _visible_configurations(real: RealRobot, robot: RobotModel, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    found = []
    while sum(len(f) for f in found) < n:
        Q = rng.uniform(robot.limits.lower_rad, robot.limits.upper_rad, (4000, robot.nq))
        found.append(Q[real.tracker.visible(Q)])
    return np.concatenate(found)[:n]


def test_same_seed_same_truth_and_noise_bit_for_bit(rx130l: RobotModel) -> None:
    a, b = RealRobot.create(rx130l, 5), RealRobot.create(rx130l, 5)
    assert np.array_equal(a.kinematic_errors, b.kinematic_errors)
    assert np.array_equal(a.dynamic_parameters, b.dynamic_parameters)
    assert np.array_equal(a.transform_tracker_to_base.homogeneous, b.transform_tracker_to_base.homogeneous)
    Q = _visible_configurations(a, rx130l, 5)
    ra, rb = a.tracker.measure(Q, np.random.default_rng(9)), b.tracker.measure(Q, np.random.default_rng(9))
    assert np.array_equal(ra.position_m, rb.position_m)
    c = RealRobot.create(rx130l, 6)
    assert not np.array_equal(a.kinematic_errors, c.kinematic_errors)


def test_truth_deviates_by_the_stated_magnitudes(rx130l: RobotModel, real: RealRobot) -> None:
    layout = KinematicLayout(rx130l.nq)
    errors = real.kinematic_errors
    translations = np.concatenate([errors[layout.placement(i)][:3] for i in range(1, 7)])
    assert 0.1e-3 < np.std(translations) < 1.5e-3
    assert 0.2e-3 < np.std(errors[layout.joint_offsets]) < 3e-3
    rng = np.random.default_rng(1)
    Q = rng.uniform(rx130l.limits.lower_rad, rx130l.limits.upper_rad, (200, 6))
    tcp_error = np.linalg.norm(real.truth.positions(Q) - rx130l.positions(Q), axis=1)
    assert 0.5e-3 < np.mean(tcp_error) < 10e-3  # millimetres before calibration
    assert dynamic_parameter_problems(real.dynamic_parameters, 6) == []
    masses = np.array([real.truth.model.inertias[j].mass for j in range(1, 7)])
    nominal = np.array([rx130l.model.inertias[j].mass for j in range(1, 7)])
    assert np.all(np.abs(masses / nominal - 1) < 0.8) and not np.allclose(masses, nominal)


def test_tracker_noise_matches_its_model(rx130l: RobotModel, real: RealRobot) -> None:
    Q = _visible_configurations(real, rx130l, 40)
    exact = real.truth.positions(real.link_angles(Q), "reflector")  # the deflected arm
    to_tracker = real.transform_tracker_to_base.inverse()
    exact_tracker = exact @ to_tracker.rotation.T + to_tracker.translation
    rng = np.random.default_rng(2)
    residuals = []
    for _ in range(50):
        reading = real.tracker.measure(Q, rng)
        assert reading.visible.all()
        residuals.append((reading.position_m - exact_tracker) / reading.sigma_m[:, None])
    normalised = np.concatenate(residuals).ravel()
    assert abs(np.mean(normalised)) < 0.05
    assert np.std(normalised) == pytest.approx(1.0, abs=0.05)
    ranges = np.linalg.norm(exact_tracker, axis=1)
    assert np.allclose(reading.sigma_m, 8e-6 + 3e-6 * ranges, rtol=1e-12)


def test_invisible_configurations_give_nan(rx130l: RobotModel, real: RealRobot) -> None:
    rng = np.random.default_rng(3)
    Q = rng.uniform(rx130l.limits.lower_rad, rx130l.limits.upper_rad, (300, 6))
    reading = real.tracker.measure(Q, rng)
    assert (~reading.visible).any()
    assert np.isnan(reading.position_m[~reading.visible]).all()
    assert np.isfinite(reading.position_m[reading.visible]).all()


def test_visibility_respects_incidence_and_beam_blockage(rx130l: RobotModel) -> None:
    q = np.zeros(6)
    reflector = rx130l.fk(q, "reflector")
    axis = reflector.rotation @ rx130l.reflector_axis
    # a tracker straight along the reflector axis sees it; one 40 deg off-axis does not
    along = pin.SE3(np.eye(3), reflector.translation + 2.0 * axis)
    assert tracker_visibility(rx130l, along, q).visible[0]
    side = np.cross(axis, [0.0, 1.0, 0.0])
    off_axis = pin.SE3(np.eye(3), reflector.translation + 2.0 * (np.cos(0.7) * axis + np.sin(0.7) * side))
    vis = tracker_visibility(rx130l, off_axis, q)
    assert not vis.visible[0] and vis.incidence_rad[0] == pytest.approx(0.7, abs=1e-9)
    # a tracker behind the column: the beam passes through the link capsules
    behind = pin.SE3(np.eye(3), np.array([-2.0, 0.0, 0.3]))
    assert tracker_visibility(rx130l, behind, q, max_incidence_rad=np.pi).beam_clearance_m[0] < 0


def test_joint_measurements_carry_the_stated_noise(rx130l: RobotModel, real: RealRobot) -> None:
    rng = np.random.default_rng(4)
    n = 2000
    t = np.linspace(0, 1, n)
    q = np.tile(np.array([0.1, -0.2, 0.3, 0.0, 0.5, 0.0]), (n, 1))
    zeros = np.zeros_like(q)
    measured = real.execute_joint_trajectory(t, q, zeros, zeros, rng)
    exact = real.truth.inverse_dynamics(q[0], zeros[0], zeros[0])
    assert np.allclose(np.std(measured.tau_Nm - exact, axis=0) / measured.tau_sigma_Nm, 1.0, atol=0.1)
    assert np.allclose(measured.tau_sigma_Nm, 0.01 * rx130l.limits.effort_Nm)
    assert np.std(measured.q_rad - q) == pytest.approx(2e-6, rel=0.1)


def test_truth_config_rejects_negative_sigma(rx130l: RobotModel) -> None:
    with pytest.raises(ConfigError, match="truth.mass_relative_sigma"):
        RealRobot.create(rx130l, 0, TruthConfig(mass_relative_sigma=-1.0))


def test_ideal_truth_gives_back_the_rigid_robot_bit_for_bit(rx130l: RobotModel) -> None:
    ideal, real = RealRobot.create(rx130l, 5, TruthConfig(**IDEAL)), RealRobot.create(rx130l, 5)
    # the extra effects use their own stream: the geometric and inertial truth is unchanged
    assert np.array_equal(ideal.kinematic_errors, real.kinematic_errors)
    assert np.array_equal(ideal.dynamic_parameters, real.dynamic_parameters)
    assert np.all(np.isinf(ideal.joint_stiffness_Nm_rad))
    Q = _visible_configurations(ideal, rx130l, 20)
    assert ideal.link_angles(Q) is not None and np.array_equal(ideal.link_angles(Q), Q)
    rigid = LaserTracker(ideal.truth, ideal.transform_tracker_to_base)   # the sensor without any deflection
    a, b = ideal.tracker.measure(Q, np.random.default_rng(3)), rigid.measure(Q, np.random.default_rng(3))
    assert np.array_equal(a.position_m, b.position_m) and a.corrupted is None


def test_joints_deflect_under_gravity_and_payload(rx130l: RobotModel) -> None:
    real = RealRobot.create(rx130l, 7, TruthConfig(transmission_error_amplitude_rad=0.0))
    k = real.joint_stiffness_Nm_rad
    ratio = k / nominal_joint_stiffness_Nm_rad(rx130l)
    assert np.all((ratio > np.exp(-4 * 0.3)) & (ratio < np.exp(4 * 0.3))) and not np.allclose(ratio, 1.0)
    Q = _visible_configurations(real, rx130l, 20)
    deflection = real.link_angles(Q) - Q
    expected = -gravity_torques_Nm(real.truth.model, Q) / k
    assert np.allclose(deflection, expected, atol=1e-2 * np.abs(expected).max())   # first order in 1/k
    # joint 2 carries the arm: a good share of the twist its torque limit gives, never more than that twist
    twist_at_limit_rad = rx130l.limits.effort_Nm[1] / nominal_joint_stiffness_Nm_rad(rx130l)[1]
    assert 0.1 * twist_at_limit_rad < np.abs(deflection[:, 1]).max() < np.exp(4 * 0.3) * twist_at_limit_rad
    load = Payload(10.0, (0.0, 0.0, 0.1))
    heavy = with_payload(real.truth.model, rx130l.frame_flange, load)
    loaded = real.link_angles(Q, load) - Q
    assert np.allclose(loaded, -gravity_torques_Nm(heavy, Q) / k, atol=1e-2 * np.abs(loaded).max())
    assert np.abs(loaded[:, 1]).sum() > np.abs(deflection[:, 1]).sum()
    # doubling the compliance doubles the deflection (seeded: same spread)
    soft = RealRobot.create(rx130l, 7, TruthConfig(joint_compliance_scale=2.0, transmission_error_amplitude_rad=0.0))
    assert np.allclose(soft.link_angles(Q) - Q, 2 * deflection, atol=0.02 * np.abs(deflection).max())


def test_transmission_error_is_a_bounded_remainder(rx130l: RobotModel) -> None:
    real = RealRobot.create(rx130l, 7, TruthConfig(joint_compliance_scale=0.0, transmission_error_amplitude_rad=5e-6))
    Q = _visible_configurations(real, rx130l, 200)
    d = real.link_angles(Q) - Q
    assert np.abs(d).max() <= 5e-6 + 1e-15 and np.abs(d).max() > 3e-6


def test_gross_tracker_errors_are_injected_at_the_stated_rate(rx130l: RobotModel) -> None:
    cfg = TruthConfig(**(IDEAL | dict(tracker_outlier_rate=0.1, tracker_outlier_magnitude_m=2e-3,
                                      tracker_stale_rate=0.05)))
    real = RealRobot.create(rx130l, 3, cfg)
    Q = _visible_configurations(real, rx130l, 400)
    reading = real.tracker.measure(Q, np.random.default_rng(1))
    exact = LaserTracker(real.truth, real.transform_tracker_to_base).measure(Q, np.random.default_rng(1))
    off = np.linalg.norm(reading.position_m - exact.position_m, axis=1)
    bad = reading.corrupted
    assert 0.08 < bad.mean() < 0.22
    assert np.all(off[~bad] == 0.0) and np.all(off[bad] > 1e-4)
    stale = np.all(reading.position_m[1:] == reading.position_m[:-1], axis=1)
    assert stale.sum() >= 5 and np.all(bad[1:][stale])


def test_truth_config_rejects_a_rate_above_one_half(rx130l: RobotModel) -> None:
    with pytest.raises(ConfigError, match="truth.tracker_outlier_rate"):
        RealRobot.create(rx130l, 0, TruthConfig(tracker_outlier_rate=0.9))


def _sweep(robot: RobotModel, n: int = 400) -> tuple[np.ndarray, ...]:
    """A slow sinusoidal sweep of every joint (many samples below the Stribeck velocity)."""
    t = np.arange(n) * 0.01
    lim = robot.limits
    mid, amp = 0.5 * (lim.lower_rad + lim.upper_rad), 0.1 * (lim.upper_rad - lim.lower_rad)
    w = 2 * np.pi * np.linspace(0.2, 0.4, robot.nq)
    q = mid + amp * np.sin(w * t[:, None])
    return t, q, amp * w * np.cos(w * t[:, None]), -amp * w**2 * np.sin(w * t[:, None])


def test_measured_torque_without_stribeck_is_the_rigid_inverse_dynamics_bit_for_bit(rx130l: RobotModel) -> None:
    cfg = TruthConfig(stribeck_excess_relative=0.0, coulomb_load_coefficient=0.0, torque_noise_fraction_of_limit=0.0)
    real = RealRobot.create(rx130l, 7, cfg)
    t, q, v, a = _sweep(rx130l)
    measured = real.execute_joint_trajectory(t, q, v, a, np.random.default_rng(0))
    exact = np.array([real.truth.inverse_dynamics(*s) for s in zip(q, v, a, strict=True)])
    assert np.array_equal(measured.tau_Nm, exact)


def test_measured_torque_carries_the_plants_stribeck_and_load_dependent_friction(rx130l: RobotModel) -> None:
    """The measurement uses the plant's friction function with the motor torque as the load (a
    fixed point), and differs from the rigid viscous + Coulomb torques by up to the static excess."""
    real = RealRobot.create(rx130l, 7, TruthConfig(torque_noise_fraction_of_limit=0.0))
    tr = real.transmission
    assert tr.nonlinear_friction
    t, q, v, a = _sweep(rx130l)
    tau = real.execute_joint_trajectory(t, q, v, a, np.random.default_rng(0)).tau_Nm
    rigid = (np.array([real.truth.inverse_dynamics(*s) for s in zip(q, v, a, strict=True)])
             - real.truth.friction_torque(v))
    np.testing.assert_allclose(tau, rigid + tr.friction_torque(v, tau), rtol=0, atol=1e-9 * np.abs(tau).max())
    excess = np.abs(tau - rigid - real.truth.friction_torque(v))
    # near rest the static excess shows (its peak over v is ~0.8 f_s for w_s = 5 x the Coulomb width) ...
    assert np.all(excess.max(axis=0) >= 0.5 * tr.static_excess_Nm)
    # ... and never more than the excess and the load growth of Coulomb friction together
    grow = 1 + tr.coulomb_load_coefficient * np.abs(tau).max(axis=0) / tr.effort_Nm
    assert np.all(excess.max(axis=0) <= (tr.static_excess_Nm + tr.coulomb_Nm) * grow - tr.coulomb_Nm + 1e-9)
