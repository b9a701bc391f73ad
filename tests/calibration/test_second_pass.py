"""Second calibration pass: the gravity torques of an upstream (identified) robot on this run's
kinematics, and joints without gravity load keep an unidentifiable compliance."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.calibration import error_model as em
from pipeline.calibration.elastostatic import gravity_model_of, negligible_compliances
from pipeline.robot.model import RobotModel


@pytest.fixture(scope="module")
def robot() -> RobotModel:
    return RobotModel.load("rx130l")


def _upstream(robot: RobotModel) -> RobotModel:
    """An 'identified' robot: its base tilted by 0.5 mrad (calibrated kinematics) and every centre
    of mass moved 5 mm off its nominal place (identified first moments)."""
    model = robot.model.copy()
    tilt = pin.SE3(pin.exp3(np.array([5e-4, 0.0, 0.0])), np.zeros(3))
    model.jointPlacements[1] = tilt * model.jointPlacements[1]
    for j in range(1, model.njoints):
        inertia = model.inertias[j]
        model.inertias[j] = pin.Inertia(inertia.mass, inertia.lever + np.array([5e-3, -5e-3, 5e-3]), inertia.inertia)
    return robot.with_model(model)


def test_upstream_inertias_on_this_runs_kinematics(robot):
    upstream = _upstream(robot)
    model = gravity_model_of(robot, upstream)
    for j in range(1, model.njoints):   # the kinematics are this run's, the inertias the upstream's
        assert model.jointPlacements[j].isApprox(robot.model.jointPlacements[j])
        assert model.inertias[j].isApprox(upstream.model.inertias[j])
    Q = em.random_configurations(robot, 20, np.random.default_rng(0))
    data = model.createData()
    tau1 = [pin.computeGeneralizedGravity(model, data, q)[0] for q in Q]
    assert np.max(np.abs(tau1)) < 1e-9   # a vertical axis 1 stays free of gravity torque


def test_joints_without_gravity_load_have_no_identifiable_compliance(robot):
    mm = em.MeasurementModel(robot, compliance=True)
    Q = em.random_configurations(robot, 60, np.random.default_rng(1))
    T = robot.tracker.transform_tracker_to_base

    def negligible() -> np.ndarray:
        _, J = mm.jacobian(Q, np.zeros(mm.n), T)
        return negligible_compliances(mm, J.reshape(-1, mm.n))

    nominal = negligible()
    assert nominal[0] and nominal[5] and not nominal[1] and not nominal[2]   # vertical axis 1, wrist roll; axes 2, 3
    mm.set_gravity_model(gravity_model_of(robot, _upstream(robot)))   # small off-axis moments on every link
    assert np.array_equal(negligible(), nominal)
