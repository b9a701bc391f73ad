"""Regressor, base parameters and the log-Cholesky map against Pinocchio and the symbolic bridge."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.identification.estimate import (
    dynamic_to_log_cholesky,
    is_physically_consistent,
    log_cholesky_to_dynamic,
)
from pipeline.identification.regressor import RegressorModel, base_parameters, standard_parameters
from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot


@pytest.fixture(scope="module")
def tx40():
    return RobotModel.load("staubli_tx40")


def _reg(robot):
    act = robot.actuation
    return RegressorModel(robot.model, act.gear_matrix, act.coulomb_smoothing_rad_s)


def test_regressor_matches_symbolic_and_inverse_dynamics(rx130l):
    reg = _reg(rx130l)
    sym = SymbolicRobot(rx130l)
    p = sym.nominal_dynamic_parameters()
    rng = np.random.default_rng(0)
    for _ in range(5):
        q, v, a = rng.normal(size=(3, rx130l.nq))
        Y = reg.regressor(q, v, a)
        np.testing.assert_allclose(Y, np.asarray(sym.regressor(q, v, a)), atol=1e-9)
        np.testing.assert_allclose(Y @ p, rx130l.inverse_dynamics(q, v, a), atol=1e-9)


def test_gear_coupling_columns_follow_the_motor_side_model(tx40):
    """Motor j: joint torque K^T e_j (J_j (K a)_j + b_j (K v)_j + c_j sign((K v)_j))."""
    reg = RegressorModel(tx40.model, tx40.actuation.gear_matrix, 0.0)
    K = tx40.actuation.gear_matrix
    assert K[5, 4] != 0  # axes 5 and 6 are coupled
    rng = np.random.default_rng(1)
    J, b, c = rng.uniform(1e-5, 1e-4, 6), rng.uniform(1e-3, 1e-2, 6), rng.uniform(0.01, 0.1, 6)
    v, a = rng.normal(size=(2, 6))
    tau_motor = J * (K @ a) + b * (K @ v) + c * np.sign(K @ v)
    kd = np.abs(np.diag(K))
    p_act = np.concatenate([J * kd**2, b * kd**2, c * kd, np.zeros(6)])
    cols = reg.actuator_columns(v, a)
    np.testing.assert_allclose(cols @ p_act, K.T @ tau_motor, rtol=1e-12)
    # motor 6 loads joint 5 with the acceleration of both axes 5 and 6
    assert cols[4, 5] == pytest.approx(a[4] + a[5])


def test_base_parameters_reproduce_the_torques(rx130l):
    reg = _reg(rx130l)
    base = base_parameters(reg, np.random.default_rng(2), lower=rx130l.limits.lower_rad,
                           upper=rx130l.limits.upper_rad)
    assert 30 < base.n_base < reg.n_parameters
    assert base.rank_gap < 1e-10  # a clean numerical gap below the tolerance
    rng = np.random.default_rng(3)
    p = rng.normal(size=reg.n_parameters)
    Q, V, A = rng.normal(size=(3, 40, rx130l.nq))
    Y = reg.stacked(Q, V, A)
    np.testing.assert_allclose(base.base_regressor(Y) @ base.from_standard(p), Y @ p, atol=1e-8)
    names = base.names
    assert len(names) == base.n_base and all(isinstance(n, str) for n in names)
    # joint 1's rotor inertia can only be seen together with the link inertias about axis 1
    assert any("j1.Ia" in n and "Izz" in n for n in names)


def test_log_cholesky_matches_pinocchio_and_round_trips():
    rng = np.random.default_rng(4)
    for _ in range(10):
        theta = rng.normal(size=10)
        p = log_cholesky_to_dynamic(theta)
        np.testing.assert_allclose(p, pin.LogCholeskyParameters(theta).toDynamicParameters(), atol=1e-12)
        np.testing.assert_allclose(dynamic_to_log_cholesky(p), theta, atol=1e-9)
        assert is_physically_consistent(p)
    # a rod with a negative inertia is not
    bad = np.array([1.0, 0, 0, 0, -0.1, 0, 0.1, 0, 0, 0.1])
    assert not is_physically_consistent(bad)


def test_standard_parameters_of_the_model(rx130l):
    act = rx130l.actuation
    p = standard_parameters(rx130l.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    np.testing.assert_allclose(p, SymbolicRobot(rx130l).nominal_dynamic_parameters())
