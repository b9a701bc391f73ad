"""The structural base set: decided on the nominal model, identical for perturbed kinematics
(micrometres, a 4e-16 URDF round trip), and for 6 and 7 joints."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.identification.base_set import structural_base_parameters
from pipeline.identification.regressor import RegressorModel, base_parameters
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot

from .helpers import calibrated_robot


def _perturbed(model: pin.Model, size_m: float, rng: np.random.Generator) -> pin.Model:
    out = model.copy()
    for i in range(1, out.njoints):
        M = out.jointPlacements[i]
        out.jointPlacements[i] = pin.SE3(M.rotation @ pin.exp3(rng.normal(size=3) * size_m),
                                         M.translation + rng.normal(size=3) * size_m)
    return out


@pytest.fixture(scope="module")
def rx130l():
    return RobotModel.load("rx130l")


@pytest.mark.parametrize("size", [4e-16, 1e-6, 1e-3])
def test_same_set_for_nominal_calibrated_and_reloaded(rx130l, size):
    nominal = RegressorModel(rx130l.model, np.eye(6), rx130l.actuation.coulomb_smoothing_rad_s)
    current = RegressorModel(_perturbed(rx130l.model, size, np.random.default_rng(3)), np.eye(6),
                             rx130l.actuation.coulomb_smoothing_rad_s)
    lo, hi = rx130l.limits.lower_rad, rx130l.limits.upper_rad
    b_nom, b_cur = structural_base_parameters(nominal, current, np.random.default_rng(1), 300, lower=lo, upper=hi)
    assert b_cur.set_names == b_nom.set_names and b_cur.n_base == b_nom.n_base
    if size < 1e-12:
        assert b_cur.names == b_nom.names                     # the readable combinations too
    # the old per-model QR at 1e-8 finds an extra, merely kinematic, direction at 1e-3
    if size >= 1e-3:
        assert base_parameters(current, np.random.default_rng(1), 300, 1e-8, lo, hi).n_base > b_nom.n_base
    # the base values reproduce the regressor of the current model: Y p = Y_I beta (what is left is the
    # direction that only millimetre kinematics make visible)
    rng = np.random.default_rng(2)
    Q = rng.uniform(lo, hi, (50, 6))
    V, A = rng.normal(size=(2, 50, 6))
    Y = current.stacked(Q, V, A)
    p = rng.normal(size=Y.shape[1])
    err = np.linalg.norm(Y @ p - b_cur.base_regressor(Y) @ b_cur.from_standard(p)) / np.linalg.norm(Y @ p)
    assert err < max(10 * size, 1e-9)


def _seven_dof_model() -> pin.Model:
    """A 7-axis arm (alternating z/y axes, Panda-like lengths) built with Pinocchio."""
    model = pin.Model()
    axes = [pin.JointModelRZ(), pin.JointModelRY(), pin.JointModelRZ(), pin.JointModelRY(),
            pin.JointModelRZ(), pin.JointModelRY(), pin.JointModelRZ()]
    offsets = [0.333, 0.0, 0.316, 0.0825, 0.384, 0.0, 0.107]
    parent = 0
    rng = np.random.default_rng(0)
    for i, (jm, dz) in enumerate(zip(axes, offsets, strict=True)):
        parent = model.addJoint(parent, jm, pin.SE3(np.eye(3), np.array([0.0, 0.0, dz])), f"j{i + 1}")
        inertia = pin.Inertia(1.0 + i, rng.normal(size=3) * 0.05, np.diag([0.02, 0.03, 0.04]))
        model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    model.lowerPositionLimit[:] = -2.8
    model.upperPositionLimit[:] = 2.8
    return model


def test_seven_joints():
    model = _seven_dof_model()
    nominal = RegressorModel(model, np.eye(7), 0.01)
    current = RegressorModel(_perturbed(model, 1e-6, np.random.default_rng(4)), np.eye(7), 0.01)
    b_nom, b_cur = structural_base_parameters(nominal, current, np.random.default_rng(1), 300)
    assert b_nom.set_names == b_cur.set_names
    assert 7 * 4 < b_nom.n_base < 7 * 14                      # actuator columns + some link parameters
    assert all(name.startswith(("j", "universe")) for name in b_nom.set_names)


def test_calibrated_and_reloaded_robot_keep_the_nominal_set(rx130l, tmp_path):
    """The robot a calibration hands on, and the same robot reloaded from its files (URDF text
    round trip), give the nominal model's base set."""
    cal = calibrated_robot(rx130l, RealRobot.create(rx130l, 1))
    back = RobotModel.load(cal.save(tmp_path / "robot"))
    lo, hi = rx130l.limits.lower_rad, rx130l.limits.upper_rad
    w = rx130l.actuation.coulomb_smoothing_rad_s
    nominal = RegressorModel(rx130l.model, np.eye(6), w)
    sets = [structural_base_parameters(nominal, RegressorModel(r.model, np.eye(6), w), np.random.default_rng(5),
                                       300, lower=lo, upper=hi)[1].set_names for r in (rx130l, cal, back)]
    assert sets[0] == sets[1] == sets[2]
