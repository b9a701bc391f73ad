"""A record's efforts read against the nominal model: joint torques used as logged, motor currents (or
motor-side torques) detected and converted with the stated assumption, a stated scale applied."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.core.errors import ConfigError
from pipeline.identification import fourier, stage
from pipeline.identification import measure as meas_mod
from pipeline.identification.effort_unit import MAX_NOMINAL_FACTOR, read_effort_unit
from pipeline.identification.measure import JointRecord
from pipeline.identification.regressor import RegressorModel, standard_parameters
from pipeline.robot.model import RobotModel

from .helpers import quick_context
from .test_stage import _NoHiddenRobot, _write_csv

#: joint-side N·m per ampere of a cobot's drives (k_t x gear ratio), per joint
CURRENT_SCALE_NM_A = np.array([12.0, 12.0, 10.0, 7.0, 7.0, 7.0])


def _hidden_robot_record(tmp_path, seed: int = 1):
    ctx, real = quick_context(tmp_path / "run", seed=seed,
                              overrides={"run_tx40": False, "friction_model": "viscous_coulomb"})
    limits = fourier.ExcitationLimits.from_robot(ctx.robot, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02)
    traj = fourier.random_feasible_trajectories(ctx.robot, limits, 5, 0.1, 1, np.random.default_rng(7))[0]
    t = np.arange(2 * 5000) * 0.002
    meas = real.execute_joint_trajectory(t, *traj.evaluate(t), np.random.default_rng(8))
    return ctx, t, meas.q_rad, meas.tau_Nm


def _processed(robot: RobotModel, t, q, tau):
    reg = RegressorModel(robot.model, np.eye(robot.nq), robot.actuation.coulomb_smoothing_rad_s)
    data = meas_mod.process_record(JointRecord(t, q, tau, "test"), reg, None, None, 5)
    act = robot.actuation
    zeros = np.zeros(robot.nq)
    p_rigid = standard_parameters(robot.model, act.rotor_inertia_kgm2, zeros, zeros)
    return data, p_rigid, reg.n_parameters - 4 * robot.nq


@pytest.fixture(scope="module")
def hidden_record(tmp_path_factory):
    return _hidden_robot_record(tmp_path_factory.mktemp("effort"))


def test_joint_torques_are_used_as_logged_and_currents_are_converted(hidden_record):
    ctx, t, q, tau = hidden_record
    robot = ctx.robot
    gear = np.asarray(robot.actuation.gear_ratio, float)
    data, p_rigid, n_link = _processed(robot, t, q, tau)
    as_torque = read_effort_unit(data, p_rigid, n_link, robot.nq, "auto", gear)
    assert as_torque.status == "joint torques" and np.all(as_torque.scale_Nm_per_unit == 1.0)
    assert as_torque.determined.sum() >= 3 and as_torque.note(np.arange(1, 7)) is None
    ratio = as_torque.nominal_ratio[as_torque.determined]
    assert np.all(np.abs(np.log(ratio)) < np.log(1.5)), ratio      # the hidden robot's masses: near nominal
    currents, _, _ = _processed(robot, t, q, tau / CURRENT_SCALE_NM_A)
    unit = read_effort_unit(currents, p_rigid, n_link, robot.nq, "auto", gear)
    assert unit.status == "converted" and not unit.motor_side_hint
    assert unit.median_ratio is not None and unit.median_ratio < 1 / MAX_NOMINAL_FACTOR
    # the scale is the drives' constant up to the hidden robot's mismatch with the nominal masses
    d = unit.determined
    np.testing.assert_allclose(unit.scale_Nm_per_unit[d], CURRENT_SCALE_NM_A[d] / ratio, rtol=1e-6)
    note = unit.note(np.arange(1, 7))
    assert note is not None and "ASSUMED" in note and "identification.effort_scale" in note
    stated = read_effort_unit(currents, p_rigid, n_link, robot.nq, list(CURRENT_SCALE_NM_A), gear)
    assert stated.status == "stated" and stated.within_band and stated.note(np.arange(1, 7)) is None
    np.testing.assert_allclose(stated.nominal_ratio[d], ratio, rtol=1e-6)
    wrong = read_effort_unit(currents, p_rigid, n_link, robot.nq, [1.0] * 6, gear)
    assert wrong.status == "stated" and "check the scale" in (wrong.note(np.arange(1, 7)) or "")
    # placeholder masses (robot init's, from the arm's size) cannot set a unit: reported, not acted on
    placeholder = read_effort_unit(currents, p_rigid, n_link, robot.nq, "auto", gear, placeholder_masses=True)
    assert placeholder.status == "unchecked" and np.all(placeholder.scale_Nm_per_unit == 1.0)
    assert "placeholders" in (placeholder.note(np.arange(1, 7)) or "")
    assert read_effort_unit(data, p_rigid, n_link, robot.nq, "auto", gear,
                            placeholder_masses=True).note(np.arange(1, 7)) is None
    unchecked = read_effort_unit(currents, p_rigid, n_link, robot.nq, "none", gear)
    assert unchecked.status == "unchecked" and "unchecked" in (unchecked.note(np.arange(1, 7)) or "")


def test_an_effort_of_reversed_sign_is_negated_as_stated(hidden_record):
    ctx, t, q, tau = hidden_record
    robot = ctx.robot
    gear = np.asarray(robot.actuation.gear_ratio, float)
    flipped = tau.copy()
    flipped[:, 1] *= -1.0                                        # the shoulder's driver logs the other sign
    for factor, status in ((1.0, "joint torques"), (1.0 / CURRENT_SCALE_NM_A, "converted")):
        data, p_rigid, n_link = _processed(robot, t, q, flipped * factor)
        unit = read_effort_unit(data, p_rigid, n_link, robot.nq, "auto", gear)
        assert unit.status == status and unit.reversed.tolist() == [False, True, False, False, False, False]
        assert unit.scale_Nm_per_unit[1] < 0 and np.all(unit.scale_Nm_per_unit[[0, 2, 3, 4, 5]] > 0)
        assert "joint(s) 2 log their effort with the opposite sign" in (unit.note(np.arange(1, 7)) or "")


def test_motor_side_torques_are_named_as_such(hidden_record):
    ctx, t, q, tau = hidden_record
    robot = ctx.robot
    gear = np.asarray(robot.actuation.gear_ratio, float)
    data, p_rigid, n_link = _processed(robot, t, q, tau / gear)
    unit = read_effort_unit(data, p_rigid, n_link, robot.nq, "auto", gear)
    assert unit.status == "converted" and unit.motor_side_hint
    assert "identification.data_side: motor" in (unit.note(np.arange(1, 7)) or "")


def _gravity_Nm(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    data = robot.model.createData()
    return np.array([pin.computeGeneralizedGravity(robot.model, data, qk) for qk in q])


def test_the_stage_converts_a_current_log_and_hands_on_gravity_torques_near_the_torque_logs(tmp_path,
                                                                                            hidden_record):
    """Through the stage: a CSV whose torque columns are currents fits as well as one in N·m, so only the
    check against the nominal model tells. Converted, the handed-on model's gravity torques (the part of
    the inertias the data identify best) are those of the N·m record to within the scale's error, where the
    currents taken as N·m would give a tenth of them."""
    _, t, q, tau = hidden_record
    gravity = {}
    poses = q[:: len(q) // 20]
    for name, efforts in (("torque", tau), ("current", tau / CURRENT_SCALE_NM_A)):
        ctx, _ = quick_context(tmp_path / name, overrides={"run_tx40": False, "friction_model": "viscous_coulomb"})
        path = tmp_path / f"{name}.csv"
        _write_csv(path, t, q, efforts)
        ctx.config.data_file = str(path)
        ctx.real = _NoHiddenRobot()
        res = stage.run(ctx)
        s = res.summary
        assert s["effort_unit_status"] == ("joint torques" if name == "torque" else "converted")
        assert any("ASSUMED" in w for w in s.get("warnings", [])) == (name == "current")
        assert ("read as joint torques in N·m" if name == "torque" else "ASSUMED converted") in res.report_md
        assert res.robot is not None
        gravity[name] = _gravity_Nm(res.robot, poses)
    rms = {k: np.sqrt(np.mean(g[:, 1:3] ** 2, axis=0)) for k, g in gravity.items()}   # shoulder and elbow
    assert np.all(np.abs(np.log(rms["current"] / rms["torque"])) < np.log(1.3)), rms


def test_a_stated_scale_of_the_wrong_length_is_refused_before_the_run(tmp_path, rx130l):
    path = tmp_path / "record.csv"
    t = np.arange(4000) * 0.004
    _write_csv(path, t, 0.3 * np.sin(np.outer(t, np.arange(1, 7))), np.cos(np.outer(t, np.arange(1, 7))))
    with pytest.raises(ConfigError, match="identification.effort_scale"):
        stage.check(stage.Config(data_file=str(path), run_tx40=False, effort_scale=[10.0, 10.0]), rx130l)
    with pytest.raises(ConfigError, match="identification.effort_scale"):
        stage.Config(data_file=str(path), effort_scale=[10.0, -1.0, 10.0, 10.0, 10.0, 10.0]).validate()
