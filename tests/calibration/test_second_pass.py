"""Second calibration pass: the gravity torques of an upstream (identified) robot on this run's
kinematics, joints without gravity load keep an unidentifiable compliance, and both passes share their
compiled code.

End to end (slow, about 3 min per case): a run up to the identification, then a calibration run whose
``calibration.gravity_model`` is that run's identified robot. On the default (elastic) hidden robot of
an arm whose own weight deflects it by tenths of a millimetre (the RX130L with the generic joint
stiffness, and the TX40) the held-out error then reaches the tracker noise plus the stated unmodelled
remainder, the predicted error is honest and every identified joint stiffness is within 3 of its
standard deviations of the hidden one. When the runner runs the second pass by itself:
tests/run/test_second_pass.py."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from pipeline.calibration import error_model as em
from pipeline.calibration.elastostatic import gravity_model_of, negligible_compliances
from pipeline.core import codegen
from pipeline.core.compiled_on_demand import FLAGS
from pipeline.core.config import load_config
from pipeline.robot.model import RobotModel
from pipeline.run.runner import run_pipeline
from pipeline.sim.truth import RealRobot, TruthConfig

#: 3 sigma of the tracker plus the unmodelled remainder (3 µrad cyclic gear error at ~1.5 m: < 0.5 sigma)
HELDOUT_OVER_SIGMA_MAX = 3.5


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


def test_upstream_inertias_on_this_runs_kinematics(rx130l):
    robot = rx130l
    upstream = _upstream(robot)
    model = gravity_model_of(robot, upstream)
    for j in range(1, model.njoints):   # the kinematics are this run's, the inertias the upstream's
        assert model.jointPlacements[j].isApprox(robot.model.jointPlacements[j])
        assert model.inertias[j].isApprox(upstream.model.inertias[j])
    Q = em.random_configurations(robot, 20, np.random.default_rng(0))
    data = model.createData()
    tau1 = [pin.computeGeneralizedGravity(model, data, q)[0] for q in Q]
    assert np.max(np.abs(tau1)) < 1e-9   # a vertical axis 1 stays free of gravity torque


def test_joints_without_gravity_load_have_no_identifiable_compliance(rx130l):
    robot = rx130l
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


def test_both_passes_share_one_compiled_library_per_function(rx130l):
    """The gravity torques are an input of the compiled measurement functions, not constants in
    their code: a first pass (nominal inertias) and a second pass (identified inertias) build the
    same C code, hence one cached library per function and robot; the readings still move with
    the gravity model."""
    robot = rx130l
    first = em.MeasurementModel(robot, compliance=True)
    second = em.MeasurementModel(robot, compliance=True)
    second.set_gravity_model(gravity_model_of(robot, _upstream(robot)))
    for f, g in ((first.h, second.h), (first.hj, second.hj), (first.ht, second.ht), (first.base_pos, second.base_pos)):
        assert codegen.library_key([f], f.name(), FLAGS) == codegen.library_key([g], g.name(), FLAGS)
    Q = em.random_configurations(robot, 5, np.random.default_rng(2))
    x = np.zeros(first.n)
    x[first.sl_compliance] = 1e-6
    T = robot.tracker.transform_tracker_to_base
    assert not np.allclose(first.static_torques(Q), second.static_torques(Q), rtol=0, atol=1e-3)
    assert not np.allclose(first.predict(Q, x, T), second.predict(Q, x, T), rtol=0, atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "seed"), [("rx130l_generic", 0), ("rx130l_generic", 2), ("staubli_tx40", 0)])
def test_second_pass_with_the_identified_gravity_model(tmp_path, robot, seed, rx130l_generic_stiffness_dir):
    robot = str(rx130l_generic_stiffness_dir) if robot == "rx130l_generic" else robot
    quiet = {"out_root": tmp_path, "log": lambda m: None}
    run_pipeline(load_config(None, [f"robot={robot}", f"seed={seed}", "name=first", "calibration.second_pass=never"],
                             "identification"), **quiet)
    identified = tmp_path / "first" / "identification" / "robot"
    run_pipeline(load_config(None, [f"robot={robot}", f"seed={seed}", "name=second",
                                    f"calibration.gravity_model={identified}"], "calibration"), **quiet)
    first = json.loads((tmp_path / "first" / "calibration" / "summary.json").read_text())
    second = json.loads((tmp_path / "second" / "calibration" / "summary.json").read_text())
    assert second["rms_after_over_sigma"] <= HELDOUT_OVER_SIGMA_MAX
    assert 1 / 1.5 <= second["actual_over_predicted"] <= 1.5
    assert second["gravity_model_share"] < first["gravity_model_share"]
    assert second["gravity_pass"]["gravity_model"] == str(identified)
    results = np.load(tmp_path / "second" / "calibration" / "results.npz")
    identified_joints = results["joint_stiffness_identified"].astype(bool)
    assert identified_joints.sum() >= 2
    hidden = RealRobot.create(RobotModel.load(robot), seed, TruthConfig()).joint_stiffness_Nm_rad
    compliance = 1.0 / np.asarray(second["joint_stiffness_Nm_rad"])
    z = (compliance - 1.0 / hidden)[identified_joints] / results["joint_compliance_std"][identified_joints]
    assert np.all(np.abs(z) <= 3.0), z
