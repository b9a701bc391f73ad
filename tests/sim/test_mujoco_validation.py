"""The identification's validation on the MuJoCo arm: what its closed-loop torques and sticking dry friction
add (the path's own noise from a second run, the stiction band left out), and the own arm left as it was."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identification.friction import best_friction_model
from pipeline.identification.measure import STICTION_BAND_OVER_WIDTH
from pipeline.identification.validate import iso_validation_trajectory, torque_rms
from pipeline.robot.model import RobotModel
from pipeline.sim.mujoco_robot import MujocoRealRobot, create_hidden_robot
from pipeline.sim.truth import RealRobot, TruthConfig


@pytest.fixture(scope="module")
def tx40() -> RobotModel:
    return RobotModel.load("staubli_tx40")


def test_torque_rms_counts_only_the_scored_samples() -> None:
    rng = np.random.default_rng(0)
    measured, predicted = rng.normal(size=(200, 3)), rng.normal(size=(200, 3))
    plain = torque_rms(measured, predicted)
    assert np.array_equal(torque_rms(measured, predicted, np.ones((200, 3), bool))[0], plain[0])
    scored = np.ones((200, 3), bool)
    scored[:50, 0], scored[:, 2] = False, False
    rms, rel = torque_rms(measured, predicted, scored)
    err = measured - predicted
    assert rms[0] == pytest.approx(np.sqrt(np.mean(err[50:, 0] ** 2)))
    assert rel[0] == pytest.approx(rms[0] / np.sqrt(np.mean(measured[50:, 0] ** 2)))
    assert rms[1] == pytest.approx(plain[0][1])
    assert np.isnan(rms[2]) and np.isnan(rel[2])


def test_a_joint_the_validation_could_not_score_is_left_out_of_every_models_average() -> None:
    sigma = np.ones(3)
    scored = {"a": np.array([1.0, 1.0, np.nan]), "b": np.array([1.1, 1.1, np.nan])}
    assert best_friction_model(scored, sigma) == "a"
    assert best_friction_model({"b": scored["b"], "a": scored["a"]}, sigma) == "a"


def test_only_the_mujoco_arm_asks_for_the_closed_loop_and_stiction_validation(tx40: RobotModel) -> None:
    own = create_hidden_robot(tx40, 5, TruthConfig())
    mj = create_hidden_robot(tx40, 5, TruthConfig(engine="mujoco"))
    assert isinstance(mj, MujocoRealRobot) and not isinstance(own, MujocoRealRobot)
    assert isinstance(own, RealRobot)
    assert not own.torques_in_closed_loop and not own.dry_friction_sticks
    assert mj.torques_in_closed_loop and mj.dry_friction_sticks


def _slow_residual_of_a_held_joint(real: RealRobot, robot: RobotModel) -> tuple[float, float]:
    """Joint 4 commanded at rest while the others move: RMS and largest magnitude of its torque residual
    against the true model, averaged over 0.1 s (the noise averaged out), after 0.2 s of settling."""
    dt, period = 4e-4, 1.5
    t = np.arange(int(round(period / dt))) * dt
    w = 2 * np.pi / period
    centre = np.array([0.0, 0.3, 1.4, 0.0, 0.6, 0.0])
    amp = np.array([0.3, 0.2, 0.2, 0.0, 0.3, 0.3])
    q = centre + amp * np.sin(w * t)[:, None]
    v = amp * w * np.cos(w * t)[:, None]
    a = -amp * w**2 * np.sin(w * t)[:, None]
    truth = real.truth
    predicted = np.array([truth.inverse_dynamics(qk, vk, ak) for qk, vk, ak in zip(q, v, a, strict=True)])
    meas = real.execute_joint_trajectory(t, q, v, a, np.random.default_rng(1))
    err = (meas.tau_Nm - predicted)[t > 0.2, 3]
    slow = np.convolve(err, np.ones(250) / 250, mode="valid")
    return float(np.sqrt(np.mean(slow**2))), float(np.max(np.abs(slow)))


def test_a_joint_held_by_mujocos_dry_friction_carries_a_torque_no_smooth_model_predicts(tx40: RobotModel) -> None:
    """A joint at rest on the MuJoCo arm is held by its dry friction: its torque is what the drive commands
    (the nominal feedforward and the integrator), a slow departure from the true model within the Coulomb
    level that is not noise; on the own arm (smooth friction, ideal tracking) the slow part is noise only."""
    mj = create_hidden_robot(tx40, 5, TruthConfig(engine="mujoco"))
    own = create_hidden_robot(tx40, 5, TruthConfig())
    rms_mj, max_mj = _slow_residual_of_a_held_joint(mj, tx40)
    rms_own, _ = _slow_residual_of_a_held_joint(own, tx40)
    assert rms_mj > 2.0 * rms_own, (rms_mj, rms_own)
    assert max_mj < float(mj.truth.actuation.coulomb_Nm[3])


@pytest.mark.slow   # the RX130L's ISO path twice in MuJoCo: about a minute
def test_on_the_rx130l_the_true_smooth_model_fits_mujocos_torques_to_the_noise_outside_the_stiction_band(
        capsys: pytest.CaptureFixture[str]) -> None:
    """The evidence for the validation's rule (docs/mujoco.md), with the true parameters (no identification
    error): the torque residual of the true smooth model on the ISO path over the path's own noise sigma (two
    runs) is at the noise where the joint moves (|v| >= v_s) and above it in the stiction band; printed."""
    robot = RobotModel.load("rx130l")
    real = create_hidden_robot(robot, 1, TruthConfig(engine="mujoco"))
    vt = iso_validation_trajectory(robot, 4e-3)
    runs = [real.execute_joint_trajectory(vt.t_s, vt.q, vt.v, vt.a, np.random.default_rng(s)).tau_Nm for s in (1, 2)]
    sigma = np.std(runs[0] - runs[1], axis=0) / np.sqrt(2.0)
    truth = real.truth
    err = runs[0] - np.array([truth.inverse_dynamics(q, v, a) for q, v, a in zip(vt.q, vt.v, vt.a, strict=True)])
    v_s = STICTION_BAND_OVER_WIDTH * robot.actuation.coulomb_smoothing_rad_s
    moving = np.abs(vt.v) >= v_s
    every = np.sqrt(np.mean(err**2, axis=0)) / sigma
    outside = torque_rms(runs[0], runs[0] - err, moving)[0] / sigma
    with capsys.disabled():
        print(f"\nRX130L ISO path in MuJoCo, true model, v_s = {np.round(v_s, 4).tolist()} rad/s: noise sigma "
              f"(two runs) "
              f"{np.round(sigma, 3).tolist()} N·m; RMS / sigma, every sample {np.round(every, 2).tolist()}, "
              f"|v| >= v_s {np.round(outside, 2).tolist()}, fraction scored {np.round(moving.mean(0), 3).tolist()}")
    scored = np.isfinite(outside)
    assert np.all(outside[scored] <= 1.05), outside
    assert np.max(every) > 1.2, every   # the stiction band is not noise
