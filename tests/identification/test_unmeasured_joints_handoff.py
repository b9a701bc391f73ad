"""The model handed on after a fit that left joints out: the joints no torque validated keep the
previous model's link inertias and drive values."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identification import stage
from pipeline.identification.handed_on import unmeasured_joints_note, with_unmeasured_joints_kept
from pipeline.identification.joints import select_joints
from pipeline.identification.outcome import identified_robot
from pipeline.identification.regressor import standard_parameters
from pipeline.robot.model import RobotModel

from .helpers import quick_context


def _fitted(robot: RobotModel) -> np.ndarray:
    """Standard parameters that differ from the robot's in every entry (a fit's result)."""
    act = robot.actuation
    p = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    return p * 1.3 + 0.01


def test_a_one_joint_fit_hands_on_the_previous_values_of_the_other_joints(rx130l: RobotModel):
    names = [str(n) for n in rx130l.model.names[1:]]
    sel = select_joints([names[0]], names, {})
    p_fit = _fitted(rx130l)
    handed = identified_robot(rx130l, with_unmeasured_joints_kept(rx130l, sel, p_fit))
    fitted = identified_robot(rx130l, p_fit)
    act, act_fit, act_prev = handed.actuation, fitted.actuation, rx130l.actuation
    for j in range(rx130l.nq):
        source = fitted if j == 0 else rx130l
        np.testing.assert_allclose(handed.model.inertias[j + 1].toDynamicParameters(),
                                   source.model.inertias[j + 1].toDynamicParameters(), rtol=1e-12, atol=1e-15)
        for name in ("rotor_inertia_kgm2", "viscous_Nms_rad", "coulomb_Nm"):
            expected = getattr(act_fit if j == 0 else act_prev, name)[j]
            assert getattr(act, name)[j] == expected, (name, j)
    note = unmeasured_joints_note(sel)
    assert names[0] in note and all(n in note for n in names[1:])


def test_a_fit_of_every_joint_hands_on_the_fit_unchanged(rx130l: RobotModel):
    names = [str(n) for n in rx130l.model.names[1:]]
    sel = select_joints([], names, {})
    p_fit = _fitted(rx130l)
    assert np.array_equal(with_unmeasured_joints_kept(rx130l, sel, p_fit), p_fit)
    assert unmeasured_joints_note(sel) == ""


@pytest.mark.slow
def test_a_simulated_one_joint_identification_designs_for_that_joint_and_passes_its_gates(tmp_path):
    """The excitation is designed on the torque rows the fit uses: the data's condition number is
    the design's (gate ``cond_data_over_design``), and the handed-on model keeps the other joints."""
    ctx, _ = quick_context(tmp_path, overrides={"run_tx40": False, "joints": ["joint_1"]})
    result = stage.run(ctx)                     # raises on a failed quality gate
    s = result.summary
    assert s["joints_used"] == ["joint_1"]
    assert s["cond_base_regressor_data_structural"] / s["cond_optimized"] <= ctx.config.max_cond_data_over_design
    assert any("joint_1 only" in w for w in s["warnings"])
    assert result.robot is not None
    for j in range(2, ctx.robot.model.njoints):
        np.testing.assert_allclose(result.robot.model.inertias[j].toDynamicParameters(),
                                   ctx.robot.model.inertias[j].toDynamicParameters(), rtol=1e-12, atol=1e-15)
