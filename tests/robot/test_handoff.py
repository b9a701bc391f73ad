"""Stage hand-off records: the arrays a run saves map to the record and back, old runs included."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.robot.handoff import ElastostaticRecord, JointFriction
from pipeline.robot.model import RobotModel


def _elastostatic(rng: np.random.Generator) -> ElastostaticRecord:
    torques = rng.normal(0.0, 300.0, (12, 6))
    return ElastostaticRecord(stiffness_identified=np.array([False, True, True, False, True, False]),
                              compliance_std_rad_Nm=np.where(rng.random(6) < 0.5, np.nan, 1e-7),
                              configurations_rad=rng.uniform(-1.0, 1.0, (12, 6)), torques_Nm=torques,
                              payload_torques_Nm=0.1 * torques)


def test_elastostatic_record_round_trips_through_the_saved_keys():
    rec = _elastostatic(np.random.default_rng(0))
    arrays = rec.to_arrays()
    assert set(arrays) == {"elastostatic_configurations_rad", "elastostatic_torques_Nm",
                           "elastostatic_payload_torques_Nm", "joint_stiffness_identified", "joint_compliance_std"}
    back = ElastostaticRecord.from_arrays(arrays, 6)
    assert back is not None
    for name in ElastostaticRecord.KEYS:
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name))
    assert back.stiffness_identified.dtype == bool


def test_elastostatic_record_of_older_or_rigid_runs():
    """No record (rigid calibration): None. Only the identified mask (an older run): no torques, std 0."""
    assert ElastostaticRecord.from_arrays({"base_beta": np.zeros(3)}, 6) is None
    old = ElastostaticRecord.from_arrays({"joint_stiffness_identified": np.ones(6, bool)}, 6)
    assert old is not None and not old.has_torques
    np.testing.assert_array_equal(old.compliance_std_rad_Nm, np.zeros(6))
    assert set(old.to_arrays()) == {"joint_stiffness_identified", "joint_compliance_std"}


@pytest.mark.parametrize("stribeck", [True, False])
def test_joint_friction_round_trips_and_lands_in_the_actuation(stribeck):
    rng = np.random.default_rng(1)
    fs, vs = (rng.uniform(1.0, 5.0, 6), rng.uniform(0.01, 0.1, 6)) if stribeck else (None, None)
    friction = JointFriction(rng.uniform(1.0, 10.0, 6), rng.uniform(5.0, 20.0, 6), fs, vs)
    back = JointFriction.from_arrays(friction.to_arrays())
    assert (back.static_excess_Nm is None) == (not stribeck)
    robot = RobotModel.load("rx130l")
    friction.apply_to(robot.spec.actuation)
    carried = JointFriction.of_actuation(robot.spec.actuation)
    for got in (back, carried):
        for name in JointFriction.KEYS:
            a, b = getattr(got, name), getattr(friction, name)
            assert (a is None and b is None) or np.array_equal(a, b)


def test_joint_friction_needs_both_stribeck_values():
    with pytest.raises(ValueError, match="together"):
        JointFriction(np.ones(6), np.ones(6), np.ones(6), None)
