"""``python -m pipeline export``: a bad run directory ends in one line, exit 2, nothing written; a motion
that leaves a limit is refused; the samples of moves and re-sampled plans keep the limits; servo_gains.yaml
reads back exactly, whatever the joints are called."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.core.errors import InfeasibleError
from pipeline.core.yaml12 import load_yaml
from pipeline.exchange.joint_limits import JointLimitTable
from pipeline.exchange.motion import SampledMotion
from pipeline.robot.defaults import ready_pose_rad
from pipeline.run import export_motions as em
from pipeline.run.export import servo_gains_yaml
from pipeline.stage_api import StageOutput


@pytest.mark.parametrize("make", ["missing", "empty", "not_a_run"])
def test_a_bad_run_directory_is_one_line_exit_2_and_nothing_written(tmp_path: Path, capsys, make: str) -> None:
    run = tmp_path / "run"
    if make != "missing":
        run.mkdir()
    if make == "not_a_run":
        (run / "config.yaml").write_text("seed: [unclosed\n")
    out = tmp_path / "out"
    assert main(["export", str(run), "--to", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and str(run) in err
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_moves_keep_the_limits_and_a_motion_over_a_limit_is_refused(rx130l) -> None:
    limits = JointLimitTable.of_model(rx130l)
    q0 = ready_pose_rad(rx130l)
    q1 = q0 + 0.3 * np.sign(0.5 * (limits.lower_rad + limits.upper_rad) - q0 + 1e-9)
    zero = np.zeros(rx130l.nq)
    t, q, v, a = em.move(rx130l, limits, (q0, zero, zero), (q1, zero, zero), 500.0, "move")
    np.testing.assert_allclose(q[[0, -1]], [q0, q1], atol=1e-12)
    np.testing.assert_allclose(v[[0, -1]], 0.0, atol=1e-9)
    assert np.all(np.abs(v) <= em.MOVE_LIMIT_FRACTION * limits.velocity_rad_s + 1e-9)
    motion = em.joined(rx130l, [(t, q, v, a)], rx130l)
    em.check_limits(motion, limits, "move")
    over = 1.01 / np.max(np.abs(motion.qd_rad_s) / limits.velocity_rad_s)    # one sample 1 % over
    fast = SampledMotion(motion.joint_names, motion.t_s, motion.q_rad, over * motion.qd_rad_s, motion.qdd_rad_s2,
                         motion.tau_ff_Nm)
    with pytest.raises(InfeasibleError, match="qd_rad_s of joint .* over its velocity limit"):
        em.check_limits(fast, limits, "move")


def test_a_stored_plan_resampled_keeps_its_samples_and_derivatives() -> None:
    t = np.linspace(0.0, 2.0, 201)
    q = np.column_stack([np.sin(t), t ** 3])
    tr, qr, vr, ar = em.resample_plan(t, q, 1000.0)
    assert tr[0] == 0.0 and tr[-1] == pytest.approx(2.0) and np.allclose(np.diff(tr)[:-1], 1e-3)
    stored = np.isin(np.round(tr, 9), np.round(t, 9))
    np.testing.assert_allclose(qr[stored], q, atol=1e-12)                     # the plan's own samples
    np.testing.assert_allclose(qr, np.column_stack([np.sin(tr), tr ** 3]), atol=2e-4)
    np.testing.assert_allclose(vr, np.column_stack([np.cos(tr), 3 * tr ** 2]), atol=1e-3)
    np.testing.assert_allclose(ar[20:-20], np.column_stack([-np.sin(tr), 6 * tr])[20:-20], atol=1e-3)


def test_a_plan_at_its_acceleration_limit_stays_within_it_when_resampled() -> None:
    """Bang-bang acceleration (a time-optimal profile): the differences never exceed the plan's bound."""
    t = np.linspace(0.0, 1.0, 401)
    a_true = np.where(t < 0.5, 2.0, -2.0)
    v = np.concatenate([[0.0], np.cumsum(0.5 * (a_true[1:] + a_true[:-1]) * np.diff(t))])
    q = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])[:, None]
    _, _, _, ar = em.resample_plan(t, q, 1000.0)
    assert np.max(np.abs(ar)) <= 2.0 + 1e-9


def test_servo_gains_yaml_reads_back_exactly_with_any_joint_names(tmp_path: Path) -> None:
    names = ["1", "yes", "a: b", "joint 4"]
    rng = np.random.default_rng(0)
    arrays = {key: rng.uniform(1.0, 1e4, len(names)) for key in ("servo_kp_1_s", "servo_kv_Nms_rad", "servo_ki_Nm_rad")}
    summary = {"sample_time_s": 4e-4, "velocity_sample_time_s": 4e-4,
               "delay_samples": {"setpoint": 2, "measurement": 1}, "feedforward_advanced": True}
    back = load_yaml(servo_gains_yaml(StageOutput(summary, arrays, {}, None, tmp_path), names))
    assert list(back["axes"]) == names
    assert back["sample_time_s"] == 4e-4 and back["setpoint_delay_samples"] == 2
    assert back["feedforward_advanced"] is True
    for key in ("kp_1_s", "kv_Nms_rad", "ki_Nm_rad"):
        column = f"servo_{key}"
        assert [back["axes"][name][key] for name in names] == arrays[column].tolist()
