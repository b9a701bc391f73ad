"""Elastic joints and Stribeck friction in the plant, and the elastic-joint feedforward."""

from __future__ import annotations

import copy

import numpy as np
import pinocchio as pin
import pytest

from pipeline.control.config import ControlConfig
from pipeline.control.elastic_feedforward import elastic_feedforward, link_torque
from pipeline.control.simulate import feedforward_torque, simulate_joint_trajectory
from pipeline.control.validate import settling_time
from pipeline.core.config import load_config
from pipeline.robot.defaults import ik_seeds_or_derived_rad, iso_or_derived
from pipeline.robot.iso9283 import iso9283_path
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import cartesian_reference
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.sim.plant import Plant
from pipeline.sim.truth import RealRobot, TruthConfig

DOWN = pin.utils.rotate("x", np.pi)
Q0 = np.array([0.1, 0.3, 1.5, 0.2, 1.0, -0.3])


@pytest.fixture(scope="module")
def real(rx130l_generic_stiffness):
    return RealRobot.create(rx130l_generic_stiffness, 2, TruthConfig())


def test_stribeck_friction_seeded_and_zero_is_viscous_coulomb(rx130l, real):
    tr = real.transmission
    again = RealRobot.create(rx130l, 2, TruthConfig()).transmission
    other = RealRobot.create(rx130l, 3, TruthConfig()).transmission
    np.testing.assert_array_equal(tr.static_excess_Nm, again.static_excess_Nm)
    assert not np.allclose(tr.static_excess_Nm, other.static_excess_Nm)
    # near standstill the friction rises above Coulomb towards static = Coulomb (1 + x) (a Stribeck hump);
    # far above w_s it is Coulomb
    w = np.linspace(0.0, 0.3, 3001)[:, None] * np.ones(6)
    hump = (tr.friction_torque(w) - tr.viscous_Nms_rad * w).max(axis=0)
    x = tr.static_excess_Nm / tr.coulomb_Nm
    assert np.all(hump > tr.coulomb_Nm * (1 + 0.5 * x)) and np.all(hump <= tr.coulomb_Nm * (1 + x))
    w_fast = 20 * tr.stribeck_velocity_rad_s
    np.testing.assert_allclose(tr.friction_torque(w_fast) - tr.viscous_Nms_rad * w_fast, tr.coulomb_Nm, rtol=1e-6)
    assert np.all(tr.friction_torque(w_fast, tr.effort_Nm) > tr.friction_torque(w_fast))  # load grows Coulomb
    rigid = RealRobot.create(rx130l, 2, TruthConfig.ideal())
    assert not rigid.plant.elastic and not rigid.plant.stribeck
    v = np.linspace(-1, 1, 6)
    np.testing.assert_allclose(rigid.transmission.friction_torque(v, 100.0), rigid.truth.friction_torque(v), atol=1e-12)


@pytest.mark.parametrize("effort_scale", [1.0, 0.15])
def test_elastic_compiled_rollout_equals_python_loop(real, effort_scale):
    truth = real.truth.copy()
    truth.model.effortLimit[:] = truth.model.effortLimit * effort_scale
    tr = copy.copy(real.transmission)
    tr.effort_Nm = tr.effort_Nm * effort_scale  # 0.15: saturates, anti-windup acts
    plant = Plant(truth, encoder_noise_rad=2e-6, transmission=tr)
    assert plant.elastic
    gains = {"kp": np.full(6, 30.0), "kv": np.array([3e3, 5e3, 2e3, 50, 40, 20]),
             "ki": np.array([2e5, 3e5, 1e5, 3e3, 2e3, 1e3])}
    # two whole chunks of the default 250 samples and a padded one: the compiled library the elastic
    # tests and the settling study share (a chunk length of its own would be one more gcc build)
    N = 520
    t = 4e-4 * np.arange(N)
    qd = Q0 + 0.2 * np.sin(2 * t)[:, None]
    vd = 0.4 * np.cos(2 * t)[:, None] * np.ones(6)
    tau = np.tile(truth.gravity_torque(Q0), (N, 1))
    recs = [plant.run_servo(gains, 4e-4, 2, 1, 0.4, qd, np.hstack([vd, vd]), np.hstack([tau, tau]), Q0,
                            np.random.default_rng(1), engine=e) for e in ("compiled", "python")]
    a, b = recs
    if effort_scale < 1.0:
        assert a.torque_ratio.max() > 1.5
    for name in ("q_meas", "v_est", "tau_cmd", "q_link", "q_motor"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-9, atol=1e-9, err_msg=name)
    assert np.abs(a.q_motor - a.q_link).max() > 1e-5  # the joints do deflect


def test_stiff_joints_approach_the_rigid_plant(rx130l, real):
    """The two-mass plant tends to the rigid one as k -> inf (difference ~ 1/k), on a minimum-jerk move
    (a step in acceleration would ring the joints, paper 004 §5)."""
    T = 0.4
    t = np.arange(0.0, T, 4e-4)
    x = t / T
    s, sd, sdd = 10 * x**3 - 15 * x**4 + 6 * x**5, (30 * x**2 - 60 * x**3 + 30 * x**4) / T, \
        (60 * x - 180 * x**2 + 120 * x**3) / T**2
    A = np.array([0.1, 0.05, -0.05, 0.1, 0.1, 0.1])
    q, v, a = Q0 + A * s[:, None], A * sd[:, None], A * sdd[:, None]
    cfg = ControlConfig(settle_time_s=0.1, engine="python")
    rigid_real = RealRobot.create(rx130l, 2, TruthConfig.ideal())

    def tcp(real_robot, scale=None):
        if scale is not None:
            real_robot = copy.copy(real_robot)
            tr = copy.copy(real.transmission)
            tr.stiffness_Nm_rad = tr.stiffness_Nm_rad * scale
            tr.damping_Nms_rad = tr.damping_Nms_rad * np.sqrt(scale)
            tr.static_excess_Nm = 0 * tr.static_excess_Nm
            tr.coulomb_load_coefficient = 0 * tr.coulomb_load_coefficient
            real_robot._plant = Plant(real.truth, transmission=tr)
        return simulate_joint_trajectory(real_robot, real.truth, t, q, v, a, cfg, "full_friction",
                                         np.random.default_rng(0)).tcp_position_m

    base = tcp(rigid_real)
    d1 = np.abs(tcp(real, 1.0) - base).max()
    d100 = np.abs(tcp(real, 100.0) - base).max()
    assert d1 > 1e-4 and d100 < d1 / 20


def test_static_deflection_under_gravity(rx130l, real):
    """Holding still: the link hangs g(q)/k behind the motor the encoder reads."""
    t = np.arange(0.0, 0.2, 4e-4)
    q = np.tile(Q0, (len(t), 1))
    res = simulate_joint_trajectory(real, real.truth, t, q, 0 * q, 0 * q, ControlConfig(settle_time_s=0.5),
                                    "gravity", np.random.default_rng(0))
    deflection = (res.q_motor - res.q_link)[-1]
    expected = real.truth.gravity_torque(res.q_link[-1]) / real.transmission.stiffness_Nm_rad
    big = np.abs(expected) > 1e-5
    np.testing.assert_allclose(deflection[big], expected[big], rtol=0.02)
    np.testing.assert_allclose(res.q[-1], res.q_motor[-1], atol=2e-5)  # encoders on the motor


def test_elastic_feedforward_leads_by_the_deflection(rx130l):
    t = np.arange(0.0, 0.5, 4e-4)
    q = Q0 + 0.2 * np.sin(4 * t)[:, None]
    v = 0.8 * np.cos(4 * t)[:, None] * np.ones(6)
    a = -3.2 * np.sin(4 * t)[:, None] * np.ones(6)
    rigid = feedforward_torque(rx130l, q, v, a, "full_friction")
    k = nominal_joint_stiffness_Nm_rad(rx130l)
    th, om, tau = elastic_feedforward(rx130l, 4e-4, q, v, a, "elastic_static", rigid)
    np.testing.assert_allclose(th - q, link_torque(rx130l, q, v, a) / k, atol=1e-12)
    np.testing.assert_array_equal(tau, rigid)
    th2, om2, tau2 = elastic_feedforward(rx130l, 4e-4, q, v, a, "elastic_flat", rigid)
    np.testing.assert_allclose(th2, th)
    np.testing.assert_allclose(om2[5:-5], np.gradient(th2, 4e-4, axis=0)[5:-5], atol=1e-4)
    # two-mass inverse = rigid torque + J_m (theta'' - q'') and friction at the motor speed: close to rigid
    assert np.abs(tau2 - rigid).max() < 0.02 * rx130l.limits.effort_Nm.max()


@pytest.fixture(scope="module")
def iso_ref(rx130l):
    cfg = load_config(values={"robot": "rx130l"}).control          # the RX130L's run_defaults (paper 004)
    iso = iso_or_derived(rx130l, cfg.iso)
    path = iso9283_path(rx130l, iso.edge_m, iso.centre_m, iso.plane, DOWN, segments=("line", "circle_large"))
    q0 = start_configuration(rx130l, path.poses([0.0])[0], ik_seeds_or_derived_rad(rx130l, cfg.ik_seeds_deg))
    return cartesian_reference(rx130l, path, cfg.sample_time_s, iso.speed_m_s, iso.acceleration_m_s2,
                               iso.jerk_m_s3, q0)


def test_elastic_feedforward_on_the_iso_path(real, iso_ref):
    """The elastic feedforward target with the exact (identified) model: rigid full_friction leaves >= 3x the max TCP
    path error of the elastic feedforward, which cuts it >= 10x against no feedforward."""
    ref = iso_ref
    cfg = ControlConfig(settle_time_s=0.2)
    at_ref = real.plant.measure_tcp(ref.q_d)
    err = {}
    for variant in ("none", "full_friction", "elastic_static", "elastic_flat"):
        res = simulate_joint_trajectory(real, real.truth, ref.t_s, ref.q_d, ref.v_d, ref.a_d, cfg, variant,
                                        np.random.default_rng(0))
        err[variant] = np.linalg.norm(res.tcp_position_m - at_ref, axis=1).max()
    assert err["full_friction"] >= 3 * err["elastic_flat"]
    assert err["none"] >= 10 * err["elastic_flat"]
    assert err["elastic_static"] < err["full_friction"] / 3


def test_settling_time():
    t = np.arange(0.0, 1.0, 1e-3)
    goal = np.array([1.0, 0.0, 0.5])
    ring = 200e-6 * np.exp(-(t - 0.5).clip(0) / 0.05) * np.cos(2 * np.pi * 20 * t)
    p = goal + np.outer(ring, [1.0, 0.0, 0.0])
    ts = settling_time(t, p, goal, 0.5)
    # envelope 200 um e^{-x/0.05} < 50 um after 0.05 ln 4 = 69 ms; the last excursion is at or before that
    assert 0.03 < ts <= 0.05 * np.log(4) + 1e-3
    R = np.array([pin.utils.rotate("z", 1e-3 * np.exp(-x / 0.01)) for x in t])
    assert settling_time(t, p, goal, 0.5, R, np.eye(3)) >= ts
    assert settling_time(t, p + 1e-3, goal, 0.5) == np.inf
    assert settling_time(t, np.tile(goal, (len(t), 1)), goal, 0.5) == 0.0
