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


def test_compiled_plant_switches_each_joints_coulomb_friction_with_its_own_width(truth):
    """A robot whose Coulomb smoothing differs per joint (an identified record's): the compiled ABA's
    friction is the model's, joint by joint, at speeds where the widths matter."""
    robot = truth.copy()
    robot.spec.actuation.coulomb_smoothing_rad_s = np.array([0.2, 0.05, 0.01, 0.1, 0.002, 0.03])
    fd = dynamics.forward_dynamics_function(dynamics.chain_structure(robot.model))
    p = dynamics.parameter_vector(robot)
    rng = np.random.default_rng(1)
    for _ in range(10):
        q = rng.uniform(robot.limits.lower_rad, robot.limits.upper_rad)
        v = rng.uniform(-0.1, 0.1, 6)
        tau = rng.uniform(-0.3, 0.3, 6) * robot.limits.effort_Nm
        np.testing.assert_allclose(np.asarray(fd(q, v, tau, p)).ravel(), robot.forward_dynamics(q, v, tau),
                                   rtol=1e-9, atol=1e-9)
    same = truth.copy()
    same.spec.actuation.coulomb_smoothing_rad_s = np.full(6, 0.01)
    assert not np.allclose(np.asarray(fd(q, v, tau, p)).ravel(), same.forward_dynamics(q, v, tau), atol=1e-6)


def _servo_inputs(truth, N: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Start pose and loop inputs (N x 42): a sine set point, its velocity, gravity feedforward, noise."""
    q0 = np.array([0.1, 0.3, 1.5, 0.2, 1.0, -0.3])
    t = 4e-4 * np.arange(N)
    qd = q0 + 0.2 * np.sin(2 * t)[:, None]
    vd = 0.4 * np.cos(2 * t)[:, None] * np.ones(6)
    tau = np.tile(truth.gravity_torque(q0), (N, 1))
    return q0, np.hstack([qd, vd, vd, tau, tau, 2e-6 * rng.standard_normal((N, 12))])


@pytest.mark.parametrize(("delay", "effort_scale"), [(0, 1.0), (2, 0.15)])
def test_compiled_rollout_equals_python_loop(truth, delay, effort_scale):
    robot = truth.copy()
    robot.model.effortLimit[:] = robot.model.effortLimit * effort_scale  # 0.15: saturates, anti-windup acts
    plant = Plant(robot, encoder_noise_rad=2e-6)
    ls = loop.LoopStructure(dynamics.chain_structure(truth.model), 2, 2, delay, 50)
    P = loop.loop_parameters(plant._p, np.full(6, 30.0), np.array([3e3, 5e3, 2e3, 50, 40, 20]),
                             np.array([2e5, 3e5, 1e5, 3e3, 2e3, 1e3]), 0.4, 1e-7, 4e-4)
    q0, U = _servo_inputs(truth, 100, np.random.default_rng(1))
    x0 = np.concatenate([q0, np.zeros(6), np.zeros(6), q0, np.zeros(6), *([q0] * delay)])
    x, Y = loop.rollout(ls, x0, U, P)
    x_py, Y_py = loop.python_rollout(ls, robot.model, plant._p, x0, U, P, plant._friction)
    if effort_scale < 1.0:
        assert Y[:, 18:24].max() > 1.5  # torque_ratio block: the saturated branch was exercised
    np.testing.assert_allclose(Y, Y_py, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(x, x_py, rtol=1e-9, atol=1e-9)


def test_buffered_rollout_is_the_plain_chunked_call_and_independent_of_the_chunk_length(truth):
    """``loop.rollout`` (numpy buffers, last chunk padded) gives the numbers of plain ``DM`` calls chunk
    after chunk, and the chunk length only splits the same sequence of steps."""
    plant = Plant(truth, encoder_noise_rad=2e-6)
    chain = dynamics.chain_structure(truth.model)
    P = loop.loop_parameters(plant._p, np.full(6, 30.0), np.full(6, 2e3), np.full(6, 1e5), 0.4, 1e-7, 4e-4)
    N = 130  # not a multiple of either chunk length: the last chunk is padded
    q0, U = _servo_inputs(truth, N, np.random.default_rng(2))
    x0 = np.concatenate([q0, np.zeros(6), np.zeros(6), q0, np.zeros(6), q0])
    ls = loop.LoopStructure(chain, 2, 2, 1, 50)
    x_buf, Y_buf = loop.rollout(ls, x0, U, P)
    roll = loop.compiled_rollout(ls)
    U_pad = np.vstack([U, np.repeat(U[-1:], 150 - N, axis=0)])
    U_pad[N:, 30:] = 0.0
    x, Y = x0, []
    for i in range(3):
        X, Yc = roll(x, U_pad[i * 50:(i + 1) * 50].T, P)
        x = np.asarray(X)[:, -1]
        Y.append(np.asarray(Yc).T)
    assert Y_buf.shape == (N, ls.n_output)
    assert np.array_equal(Y_buf, np.vstack(Y)[:N])
    x_40, Y_40 = loop.rollout(loop.LoopStructure(chain, 2, 2, 1, 40), x0, U, P)
    assert np.array_equal(Y_40, Y_buf) and np.array_equal(x_40, x_buf)  # the state after sample N, not the padding
    x_mid, Y_mid = loop.rollout(ls, x0, U[:100], P)
    assert np.array_equal(Y_mid, Y_buf[:100])
    assert np.array_equal(loop.rollout(ls, x_mid, U[100:], P)[1], Y_buf[100:])  # resumes where it stopped


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
