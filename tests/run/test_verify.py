"""``arm verify``: a recorded execution of a motion judged against it (the stand-in arm plays it first)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import main as cli_main
from pipeline.exchange.motion import JointStates, SampledMotion
from pipeline.exchange.motion_csv import write_joint_states_csv, write_motion_csv
from pipeline.exchange.ros2_bag import read_joint_states
from pipeline.robot.model import RobotModel
from pipeline.run.verify import verify, verify_files
from pipeline.sim.player import play_file, read_motion_for
from pipeline.sim.truth import TruthConfig


def _move(robot: RobotModel, q0: np.ndarray, q1: np.ndarray, duration_s: float = 0.6,
          dt: float = 2e-3) -> SampledMotion:
    """A quintic rest-to-rest move with the model's torque as feedforward."""
    t = np.arange(int(round(duration_s / dt)) + 1) * dt
    x = t / duration_s
    shape = 10 * x**3 - 15 * x**4 + 6 * x**5
    rate = (30 * x**2 - 60 * x**3 + 30 * x**4) / duration_s
    curv = (60 * x - 180 * x**2 + 120 * x**3) / duration_s**2
    d = q1 - q0
    q, v, a = q0 + shape[:, None] * d, rate[:, None] * d, curv[:, None] * d
    tau = np.array([robot.inverse_dynamics(*s) for s in zip(q, v, a, strict=True)])
    return SampledMotion(tuple(str(n) for n in robot.model.names[1:]), t, q, v, a, tau)


@pytest.fixture(scope="module")
def played(tmp_path_factory, rx130l: RobotModel) -> tuple[Path, Path, SampledMotion]:
    folder = tmp_path_factory.mktemp("verify")
    q0 = np.array([0.1, -0.3, 1.2, 0.0, 0.5, 0.0])
    motion = _move(rx130l, q0, q0 + np.array([0.4, 0.3, -0.3, 0.5, -0.4, 0.6]))
    motion_csv = write_motion_csv(folder / "move.csv", motion)
    record = play_file(motion_csv, folder / "rec", robot="rx130l", engine="pipeline", seed=3, log_rate_hz=500.0,
                       truth=TruthConfig.ideal(), hold_s=0.4)
    return motion_csv, record.paths[0], motion


def test_the_played_motion_is_found_on_any_clock_and_tracked_closely(played, tmp_path, rx130l) -> None:
    motion_csv, record, _ = played
    result = verify_files(motion_csv, record, rx130l)
    assert result.limits_kept and abs(result.time_offset_s) < 2e-3 and result.effort_ratio_max.max() > 0.1
    assert np.all(result.tracking_max_rad < 5e-3) and result.tcp_deviation_max_m < 5e-3
    assert result.settle_time_s is not None and result.settle_time_s < 0.4
    assert np.all(result.effort_ratio_max > 0.0) and np.all(np.isfinite(result.effort_minus_feedforward_rms_Nm))
    # the same record on a logger's clock 12.3456 s later, as a joint-state CSV
    states = read_joint_states(record)
    shifted = write_joint_states_csv(tmp_path / "later.csv", JointStates(states.joint_names, states.t_s + 12.3456,
                                                                         states.q_rad, states.qd_rad_s,
                                                                         states.effort_Nm))
    later = verify_files(motion_csv, shifted, rx130l)
    assert later.time_offset_s == pytest.approx(result.time_offset_s, abs=1e-9)   # from the record's first sample
    np.testing.assert_allclose(later.tracking_max_rad, result.tracking_max_rad, rtol=1e-6)
    # a record that begins with the arm on its way to the start pose
    t_before = np.arange(-1.0, 0.0, states.t_s[1])
    q_before = states.q_rad[0] + np.outer(-t_before, np.full(states.q_rad.shape[1], 0.05))
    approach = JointStates(states.joint_names, np.concatenate([t_before, states.t_s]),
                           np.vstack([q_before, states.q_rad]), np.vstack([np.zeros_like(q_before), states.qd_rad_s]),
                           np.vstack([np.zeros_like(q_before) + states.effort_Nm[0], states.effort_Nm]))
    from_approach = verify(read_motion_for(rx130l, motion_csv), approach, rx130l)
    assert from_approach.time_offset_s == pytest.approx(result.time_offset_s, abs=1e-9)


def test_a_record_of_another_motion_or_over_the_limits_fails(played, tmp_path, rx130l) -> None:
    motion_csv, record, motion = played
    states = read_joint_states(record, list(motion.joint_names))
    q_half = states.q_rad.copy()
    q_half[states.t_s > 0.3] = motion.q_rad[0] + 0.5 * (motion.q_rad[-1] - motion.q_rad[0])   # stopped half-way
    halfway = JointStates(states.joint_names, states.t_s, q_half, states.qd_rad_s, states.effort_Nm)
    assert np.max(verify(motion, halfway, rx130l).tracking_max_rad) > 0.1
    assert not verify(motion, states, _weak(rx130l)).limits_kept
    # a drive at its limit logs the limit plus its sensor's noise: within the noise the limit is kept
    rng = np.random.default_rng(4)
    limit = float(rx130l.limits.effort_Nm[1])
    sigma = 0.01 * limit
    for excess_sigmas, kept in ((0.0, True), (10.0, False)):
        effort = states.effort_Nm.copy()
        effort[:, 1] += sigma * rng.normal(size=len(effort))
        window = (states.t_s > 0.2) & (states.t_s < 0.3)
        effort[window, 1] = limit + excess_sigmas * sigma + sigma * rng.normal(size=int(window.sum()))
        at_limit = JointStates(states.joint_names, states.t_s, states.q_rad, states.qd_rad_s, effort)
        result = verify(motion, at_limit, rx130l)
        assert result.effort_ratio_max[1] > 1.0 and result.limits_kept is kept, (excess_sigmas, result.lines()[0])


def test_a_record_without_efforts_is_judged_on_its_tracking(played, rx130l) -> None:
    _, record, motion = played
    states = read_joint_states(record, list(motion.joint_names))
    positions_only = JointStates(states.joint_names, states.t_s, states.q_rad, states.qd_rad_s,
                                 np.full_like(states.effort_Nm, np.nan))
    result = verify(motion, positions_only, _weak(rx130l))
    full = verify(motion, states, rx130l)
    assert not result.effort_recorded and result.limits_kept
    assert result.lines()[0].startswith("torques not judged")
    np.testing.assert_array_equal(result.tracking_max_rad, full.tracking_max_rad)


def test_efforts_in_amperes_are_not_judged_against_torque_limits_unless_scaled(played, tmp_path, rx130l,
                                                                              capsys) -> None:
    """Motor currents (k_t x gear ratio N·m per A) over a tenth of the limits would pass as torques: they are
    named and not judged; stated with --effort-scale they are judged, and fail the tenth of the limits."""
    motion_csv, record, motion = played
    states = read_joint_states(record, list(motion.joint_names))
    nm_per_a = np.array([40.0, 40.0, 25.0, 8.0, 8.0, 5.0])
    currents = write_joint_states_csv(tmp_path / "currents.csv", JointStates(
        states.joint_names, states.t_s, states.q_rad, states.qd_rad_s, states.effort_Nm / nm_per_a))
    weak = _weak(rx130l)
    as_logged = verify_files(motion_csv, currents, weak)
    assert not as_logged.effort_recorded and as_logged.limits_kept
    assert as_logged.effort_per_feedforward_median is not None and as_logged.effort_per_feedforward_median < 0.1
    assert "not joint torques in N·m" in as_logged.lines()[0]
    assert verify_files(motion_csv, record, rx130l).effort_recorded       # the N·m record reads as torques
    scaled = verify_files(motion_csv, currents, weak, effort_scale=list(nm_per_a))
    assert scaled.effort_recorded and not scaled.limits_kept
    weak_dir = weak.save(tmp_path / "weak")
    scale = ",".join(f"{k:g}" for k in nm_per_a)
    assert cli_main(["arm", "verify", str(motion_csv), str(currents), "--robot", str(weak_dir),
                     "--effort-scale", scale]) == 3
    capsys.readouterr()
    assert cli_main(["arm", "verify", str(motion_csv), str(currents), "--robot", str(weak_dir),
                     "--effort-scale", "1,2"]) == 2
    assert "--effort-scale" in capsys.readouterr().err


def _weak(robot: RobotModel) -> RobotModel:
    """``robot`` with a tenth of its effort limits."""
    model = robot.model.copy()
    model.effortLimit = 0.1 * np.asarray(model.effortLimit)
    return robot.with_model(model)


def test_the_cli_exits_3_over_a_limit_and_2_on_a_file_that_is_no_record(played, tmp_path, capsys) -> None:
    motion_csv, record, _ = played
    assert cli_main(["arm", "verify", str(motion_csv), str(record), "--robot", "rx130l"]) == 0
    assert "limits kept" in capsys.readouterr().out
    weak = _weak(RobotModel.load("rx130l")).save(tmp_path / "weak")
    assert cli_main(["arm", "verify", str(motion_csv), str(record), "--robot", str(weak)]) == 3
    assert "EFFORT LIMIT EXCEEDED" in capsys.readouterr().err
    (tmp_path / "notes.txt").write_text("no record\n")
    assert cli_main(["arm", "verify", str(motion_csv), str(tmp_path / "notes.txt"), "--robot", "rx130l"]) == 2
    assert "notes.txt" in capsys.readouterr().err
