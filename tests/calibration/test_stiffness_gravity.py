"""The elastostatic calibration's static-torque record and the stiffness re-expressed for identified inertias."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration import stage as st
from pipeline.control.joint_stiffness import feedforward_stiffness
from pipeline.robot.handoff import ElastostaticRecord
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.sim.truth import RealRobot

#: session fixtures that take seconds and serve several tests: their tests run on one pytest-xdist
#: worker, so each is built once per ``make test`` (tests/conftest.py, pytest_collection_modifyitems)
SHARED_COSTLY_FIXTURES = frozenset({"nominal_gravity_run"})


@pytest.fixture(scope="session")
def nominal_gravity_run(rx130l_generic_stiffness):
    """Default truth (elastic joints, inertias 15 % off) of the RX130L with the generic (softer) joint
    stiffness, all parameters, the nominal gravity model."""
    robot = rx130l_generic_stiffness
    real = RealRobot.create(robot, 4)
    cfg = st.Config(candidates="random", n_random_candidates=800, n_configurations=40, n_heldout=300,
                    figures=False, design_table=False)   # the table comes last: the fit is the same
    cfg.validate()
    return robot, real, st.calibrate(robot, real, cfg, np.random.default_rng(4))


def test_static_torque_record_matches_the_calibrated_stiffness(nominal_gravity_run):
    robot, _, out = nominal_gravity_run
    rec = out.notes.static_torques
    Q, torques = rec.configurations_rad, rec.torques_Nm
    assert Q is not None and torques is not None
    assert Q.shape == out.measurements.Q.shape and torques.shape == Q.shape
    np.testing.assert_allclose(torques, [robot.gravity_torque(q) for q in Q], atol=1e-9)
    assert not np.any(rec.payload_torques_Nm)                      # no payload readings here
    known = rec.stiffness_identified
    assert not known[0]                                            # vertical axis 1: no gravity load
    assert known[1] and known[2]
    std = rec.compliance_std_rad_Nm
    assert np.all(np.isfinite(std[known])) and np.all(std[known] > 0)
    assert np.all(1.0 / out.robot.spec.actuation.joint_stiffness_Nm_rad[[1, 2]] > 3 * std[[1, 2]])  # significant
    k = out.robot.spec.actuation.joint_stiffness_Nm_rad
    np.testing.assert_array_equal(k[~known], nominal_joint_stiffness_Nm_rad(robot)[~known])


def test_identified_gravity_moves_the_stiffness_to_the_truth(nominal_gravity_run):
    """The nominal inertias bias the stiffness of the loaded axes 2 and 3; re-expressed for the truth's
    inertias (a perfect identification) they land within a few per cent of the hidden stiffness."""
    _, real, out = nominal_gravity_run
    record = ElastostaticRecord.from_arrays(out.notes.static_torques.to_arrays(), 6)  # as saved and loaded
    identified = out.robot.copy()
    for j in range(1, identified.model.njoints):
        identified.model.inertias[j] = real.truth.model.inertias[j].copy()
    k_cal = out.robot.spec.actuation.joint_stiffness_Nm_rad
    choice = feedforward_stiffness(identified, record, identified_inertias=True)
    k_true = real.joint_stiffness_Nm_rad
    err_cal = np.abs(k_cal / k_true - 1.0)
    err_new = np.abs(choice.stiffness_Nm_rad / k_true - 1.0)
    for j in (1, 2):
        assert err_new[j] < err_cal[j], (j, err_cal, err_new)
        assert err_new[j] < 0.08, (j, err_new)
    assert choice.source[0] == "nominal" and choice.gravity_factor[0] == 1.0
