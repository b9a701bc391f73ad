"""The Coulomb smoothing width per joint, chosen on a record's training part: the widths behind the
data are found on the joints that have them, the stated width is kept where it is right, the held-out
tail never enters, and the record's regressor at the chosen widths is the regressor built with them."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identification.coulomb_width import COULOMB_WIDTHS_RAD_S, choose_widths, with_widths
from pipeline.identification.measure import ProcessedData
from pipeline.identification.regressor import RegressorModel, base_parameters, standard_parameters
from pipeline.robot.model import RobotModel

STATED_RAD_S = 0.01
DT = 0.008
NOISE_NM = 0.2


@pytest.fixture(scope="module")
def robot() -> RobotModel:
    return RobotModel.load("rx130l")


def _states(nq: int, n: int = 2500) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) * DT
    f = 0.07 + 0.05 * np.arange(nq)[:, None] * np.array([1.0, 1.9, 3.1])[None]
    q = np.column_stack([0.5 * np.sum(np.sin(2 * np.pi * f[j] * t[:, None] + j), axis=1) for j in range(nq)])
    v = np.gradient(q, DT, axis=0)
    return q, v, np.gradient(v, DT, axis=0)


def _record(robot: RobotModel, true_widths: np.ndarray, seed: int = 0) -> tuple[ProcessedData, RegressorModel]:
    """Torques of the rigid model with Coulomb friction 8 N·m switching at ``true_widths``, the
    record's regressor at the stated width (what the stage starts from)."""
    nq = robot.nq
    q, v, a = _states(nq)
    truth = RegressorModel(robot.model, np.eye(nq), true_widths)
    p = standard_parameters(robot.model, np.full(nq, 0.5), np.full(nq, 3.0), np.full(nq, 8.0))
    tau = truth.torques(q, v, a, p) + np.random.default_rng(seed).normal(size=(len(q), nq)) * NOISE_NM
    stated = RegressorModel(robot.model, np.eye(nq), STATED_RAD_S)
    return ProcessedData(q, v, a, tau, stated.stacked(q, v, a), DT), stated


def _base(reg: RegressorModel):
    return base_parameters(reg, np.random.default_rng(1)).base_regressor


def test_the_widths_behind_the_data_are_found_and_the_stated_one_kept_elsewhere(robot):
    true = np.array([0.1, STATED_RAD_S, 0.05, STATED_RAD_S, 0.2, 0.002])
    data, reg = _record(robot, true)
    widths = choose_widths(data, reg, _base(reg), int(0.7 * data.n_samples))
    np.testing.assert_allclose(widths.chosen_rad_s, true)
    assert set(widths.changed) == {0, 2, 4, 5}
    assert np.all(widths.train_rms_chosen_Nm <= widths.train_rms_stated_Nm * 1.001)
    assert widths.train_rms_chosen_Nm[0] < 0.5 * widths.train_rms_stated_Nm[0]
    note = widths.note()
    assert note is not None and "joint 1 0.1 rad/s" in note and "joint 2" not in note


def test_a_record_at_the_stated_width_keeps_it(robot):
    data, reg = _record(robot, np.full(robot.nq, STATED_RAD_S), seed=3)
    widths = choose_widths(data, reg, _base(reg), int(0.7 * data.n_samples))
    np.testing.assert_allclose(widths.chosen_rad_s, STATED_RAD_S)
    assert widths.note() is None


def test_the_held_out_tail_does_not_enter(robot):
    true = np.array([0.1, STATED_RAD_S, 0.05, STATED_RAD_S, 0.2, 0.002])
    data, reg = _record(robot, true)
    n_train = int(0.7 * data.n_samples)
    spoiled = ProcessedData(data.q, data.v, data.a, data.tau.copy(), data.Y, DT)
    spoiled.tau[n_train:] = np.random.default_rng(9).normal(size=spoiled.tau[n_train:].shape) * 100.0
    a = choose_widths(data, reg, _base(reg), n_train)
    b = choose_widths(spoiled, reg, _base(reg), n_train)
    np.testing.assert_array_equal(a.chosen_rad_s, b.chosen_rad_s)
    np.testing.assert_allclose(a.train_rms_chosen_Nm, b.train_rms_chosen_Nm)


def test_the_regressor_at_chosen_widths_is_the_one_built_with_them(robot):
    data, reg = _record(robot, np.full(robot.nq, STATED_RAD_S))
    widths = np.array([COULOMB_WIDTHS_RAD_S[k % len(COULOMB_WIDTHS_RAD_S)] for k in range(robot.nq)])
    rebuilt = with_widths(data, reg, widths)
    direct = RegressorModel(robot.model, np.eye(robot.nq), widths).stacked(data.q, data.v, data.a)
    np.testing.assert_allclose(rebuilt.Y, direct, atol=1e-12)
    assert not np.allclose(rebuilt.Y, data.Y)


def test_coupled_axes_take_each_motors_width(robot):
    """A gear coupling (motor 6 driven with joint 5, as the TX40's wrist): column j of the Coulomb block is
    motor j's smoothed sign on every row the coupling reaches, at motor j's width."""
    nq = robot.nq
    K = np.diag(np.full(nq, 50.0))
    K[5, 4] = 20.0
    reg = RegressorModel(robot.model, K, STATED_RAD_S)
    q, v, a = _states(nq, 50)
    widths = np.array([0.01, 0.02, 0.05, 0.1, 0.2, 0.5])
    block = reg.coulomb_block(v, widths)
    vm = v @ K.T
    expected_col5 = np.tanh(vm[:, 5] / (50.0 * widths[5])) / 50.0
    np.testing.assert_allclose(block[:, 5, 5], K[5, 5] * expected_col5)
    np.testing.assert_allclose(block[:, 4, 5], K[5, 4] * expected_col5)
    direct = RegressorModel(robot.model, K, widths).stacked(q, v, a).reshape(50, nq, -1)[:, :, reg.coulomb_columns]
    np.testing.assert_allclose(direct, block)
