"""Quality gates of the identification: data that do not excite the model end with a
clear error; validation residual and predicted torques gated; an interrupted IPOPT solve is a
KeyboardInterrupt, never a stored result. A failed gate through the whole stage (the error names
figure and threshold, nothing is written): test_stage.py's joint CSV record run."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.core.errors import DataFileError
from pipeline.core.interrupts import raise_if_interrupted
from pipeline.identification import design as D
from pipeline.identification import fourier as F
from pipeline.identification import stage
from pipeline.identification.gates import add_result_gates, check_data_excites
from pipeline.identification.regressor import RegressorModel, base_parameters
from pipeline.quality import QualityGates
from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot

from .helpers import quick_context


def _write_csv(path, t, q, tau):
    nq = q.shape[1]
    header = "t," + ",".join(f"q{i + 1}" for i in range(nq)) + "," + ",".join(f"tau{i + 1}" for i in range(nq))
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=header, comments="")


def test_a_record_where_the_robot_never_moves_fails_with_a_message(tmp_path):
    ctx, _ = quick_context(tmp_path / "run", overrides={"run_tx40": False})
    robot = ctx.robot
    t = np.arange(3000) * 0.002
    q = np.tile(0.5 * (robot.limits.lower_rad + robot.limits.upper_rad), (len(t), 1))
    tau = np.random.default_rng(0).normal(size=q.shape)
    path = tmp_path / "still.csv"
    _write_csv(path, t, q, tau)
    ctx.config.data_file = str(path)
    with pytest.raises(DataFileError) as info:
        stage.run(ctx)
    msg = str(info.value)
    assert "still.csv" in msg and "never move" in msg and "min_joint_motion_rad" in msg
    assert not any(ctx.out_dir.iterdir())


def test_rank_and_condition_of_the_data_regressor():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(100, 2))
    W = rng.normal(size=(200, 5))
    assert check_data_excites(q, W, ["q1", "q2"], 0.05, 1e6, None) == pytest.approx(np.linalg.cond(W))
    W_def = W.copy()
    W_def[:, 4] = W[:, 0] + W[:, 1]                         # a combination the motion cannot separate
    with pytest.raises(DataFileError, match="rank 4 < 5"):
        check_data_excites(q, W_def, ["q1", "q2"], 0.05, 1e6, "rec.csv")
    W_ill = W.copy()
    W_ill[:, 4] = W[:, 0] + 1e-9 * W[:, 4]
    with pytest.raises(DataFileError, match="max_cond_base_regressor_data"):
        check_data_excites(q, W_ill, ["q1", "q2"], 0.05, 1e6, "rec.csv")
    q_still = q.copy()
    q_still[:, 1] = 0.3
    with pytest.raises(DataFileError, match="q2"):
        check_data_excites(q_still, W, ["q1", "q2"], 0.05, 1e6, "rec.csv")


def _gates(rms_over_noise, predicted, accept_poor=False, cond_data=100.0, cond_design=60.0):
    gates = QualityGates("identification", accept_poor=accept_poor)
    add_result_gates(gates, stage.Config(), cond_data, cond_design, np.asarray(rms_over_noise),
                     np.asarray(predicted), np.array([100.0, 50.0]))
    return gates


def test_result_gates_name_the_figure_and_threshold():
    ok = _gates([1.0, 1.1], [[90.0, -40.0], [10.0, 20.0]])
    assert not ok.failed
    bad = _gates([1.0, 2.5], [[90.0, -40.0]])
    assert [c.name for c in bad.failed] == ["validation_rms_over_noise"]
    assert "worst joint 2" in bad.failed[0].message and "2" in bad.failed[0].message
    torque = _gates([1.0, 1.0], [[90.0, -500.0]])           # the Panda case: ±500 N·m against a small limit
    assert [c.name for c in torque.failed] == ["predicted_torque_over_limit"]
    assert "joint 2" in torque.failed[0].message
    cond = _gates([1.0, 1.0], [[1.0, 1.0]], cond_data=1.42e5, cond_design=60.0)
    assert [c.name for c in cond.failed] == ["cond_data_over_design"]
    nan = _gates([np.nan, 1.0], [[1.0, 1.0]])
    assert [c.name for c in nan.failed] == ["validation_rms_over_noise"]
    gates = QualityGates("identification")
    add_result_gates(gates, stage.Config(), 100.0, 60.0, np.ones(2), np.ones((1, 2)), np.ones(2),
                     "Maximum_Iterations_Exceeded")
    assert [c.name for c in gates.failed] == ["physical_fit_status"]


def test_accept_poor_hands_on_and_records_it():
    gates = _gates([1.0, 2.5], [[90.0, -40.0]], accept_poor=True)
    result = SimpleNamespace(summary={})
    assert gates.finish(result) is result
    assert result.summary["accepted_poor"] is True and result.summary["quality_gates"]["passed"] is False


def test_interrupt_statuses_become_keyboard_interrupt():
    for status in ("NonIpopt_Exception_Thrown", "User_Requested_Stop"):
        with pytest.raises(KeyboardInterrupt):
            raise_if_interrupted(status)
    raise_if_interrupted("Solve_Succeeded")
    raise_if_interrupted("Maximum_Iterations_Exceeded")  # not an interrupt (the caller decides)


def test_ctrl_c_inside_the_excitation_ipopt_is_not_stored(monkeypatch):
    robot = RobotModel.load("rx130l")
    reg = RegressorModel(robot.model, np.eye(6), robot.actuation.coulomb_smoothing_rad_s)
    base = base_parameters(reg, np.random.default_rng(0), lower=robot.limits.lower_rad, upper=robot.limits.upper_rad)
    limits = F.ExcitationLimits.from_robot(robot, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02)
    calls = {"n": 0}
    original = D.ExcitationCriterion.value_and_gradient_states

    def interrupted(self, S, gradient=True):
        calls["n"] += 1
        if calls["n"] > 3:
            raise KeyboardInterrupt
        return original(self, S, gradient)

    monkeypatch.setattr(D.ExcitationCriterion, "value_and_gradient_states", interrupted)
    with pytest.raises(KeyboardInterrupt):
        D.optimize_excitation(robot, SymbolicRobot(robot), reg, base, limits, np.random.default_rng(3),
                              n_samples=30, n_starts=1, n_random=2, max_iter=20)
