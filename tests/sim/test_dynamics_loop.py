"""The compiled plant/drive step against Pinocchio and against the plain Python loop."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.sim import dynamics, loop
from pipeline.sim.plant import Plant
from pipeline.sim.truth import RealRobot, TruthConfig


@pytest.fixture(scope="module")
def truth(rx130l):
    return RealRobot.create(rx130l, 3, TruthConfig()).truth


def test_sx_aba_matches_pinocchio_with_friction_and_saturation(truth):
    fd = dynamics.forward_dynamics_function(dynamics.chain_structure(truth.model))
    p = dynamics.parameter_vector(truth)
    rng = np.random.default_rng(0)
    lim = truth.limits.effort_Nm
    for _ in range(20):
        q = rng.uniform(truth.limits.lower_rad, truth.limits.upper_rad)
        v = rng.uniform(-2, 2, 6)
        tau = rng.uniform(-1.5, 1.5, 6) * lim  # partly beyond the limits: saturated
        expected = truth.forward_dynamics(q, v, np.clip(tau, -lim, lim))
        got = np.asarray(fd(q, v, tau, p)).ravel()
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize(("delay", "effort_scale"), [(0, 1.0), (2, 0.15)])
def test_compiled_rollout_equals_python_loop(truth, delay, effort_scale):
    robot = truth.copy()
    robot.model.effortLimit[:] = robot.model.effortLimit * effort_scale  # 0.15: saturates, anti-windup acts
    plant = Plant(robot, encoder_noise_rad=2e-6)
    ls = loop.LoopStructure(dynamics.chain_structure(truth.model), 2, 2, delay, 50)
    P = loop.loop_parameters(plant._p, np.full(6, 30.0), np.array([3e3, 5e3, 2e3, 50, 40, 20]),
                             np.array([2e5, 3e5, 1e5, 3e3, 2e3, 1e3]), 0.4, 1e-7, 4e-4)
    rng = np.random.default_rng(1)
    N = 100
    q0 = np.array([0.1, 0.3, 1.5, 0.2, 1.0, -0.3])
    t = 4e-4 * np.arange(N)
    qd = q0 + 0.2 * np.sin(2 * t)[:, None]
    vd = 0.4 * np.cos(2 * t)[:, None] * np.ones(6)
    tau = np.tile(truth.gravity_torque(q0), (N, 1))
    U = np.hstack([qd, vd, vd, tau, tau, 2e-6 * rng.standard_normal((N, 12))])
    x0 = np.concatenate([q0, np.zeros(6), np.zeros(6), q0, np.zeros(6), *([q0] * delay)])
    roll = loop.compiled_rollout(ls)
    Y = []
    x = x0
    for i in range(2):
        X, Yc = roll(x, U[i * 50:(i + 1) * 50].T, P)
        x = np.asarray(X)[:, -1]
        Y.append(np.asarray(Yc).T)
    Y = np.vstack(Y)
    x_py, Y_py = loop.python_rollout(ls, robot.model, plant._p, x0, U, P, plant._friction)
    if effort_scale < 1.0:
        assert Y[:, 18:24].max() > 1.5  # torque_ratio block: the saturated branch was exercised
    np.testing.assert_allclose(Y, Y_py, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(x, x_py, rtol=1e-9, atol=1e-9)


def test_plant_integrate_holds_gravity_and_quantises(truth):
    plant = Plant(truth, encoder_noise_rad=0.0, encoder_resolution_rad=1e-6)
    q = np.array([0.0, 0.4, 1.4, 0.0, 0.8, 0.0])
    g = truth.gravity_torque(q)
    q1, v1 = plant.integrate(q, np.zeros(6), g, 0.01)
    assert np.abs(q1 - q).max() < 1e-9 and np.abs(v1).max() < 1e-7  # gravity exactly compensated
    q2, _ = plant.integrate(q, np.zeros(6), np.zeros(6), 0.01)
    assert np.abs(q2 - q).max() > 1e-5  # unsupported arm falls
    enc = plant.read_encoders(q + 3.3e-7, np.random.default_rng(0))
    np.testing.assert_allclose(enc / 1e-6, np.round(enc / 1e-6), atol=1e-9)
    with pytest.raises(Exception, match="10 kHz"):
        Plant(truth, integration_rate_hz=5000.0)


def test_parameter_vector_rejects_prismatic():
    model = pin.Model()
    model.addJoint(0, pin.JointModelPZ(), pin.SE3.Identity(), "slider")
    with pytest.raises(Exception, match="not supported"):
        dynamics.chain_structure(model)
