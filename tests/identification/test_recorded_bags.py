"""A ROS 2 bag or a joint-state CSV as identification.data_file, and the filter settings that follow from any
log rate."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.core.errors import DataFileError
from pipeline.exchange.motion import JointStates
from pipeline.exchange.motion_csv import write_joint_states_csv
from pipeline.exchange.ros2_bag import write_joint_states
from pipeline.identification.config import Config
from pipeline.identification.record import load_user_record
from pipeline.identification.signals import record_filter_settings
from pipeline.robot.model import RobotModel


def _states(robot: RobotModel, rate_hz: float, duration_s: float, names: list[str]) -> JointStates:
    t = np.arange(int(duration_s * rate_hz)) / rate_hz
    q = 0.3 * np.sin(np.outer(t, 0.5 + 0.1 * np.arange(len(names))))
    return JointStates(tuple(names), t, q, np.full_like(q, np.nan), np.cos(q))


@pytest.mark.parametrize("rate_hz", [25.0, 30.0, 125.0, 1000.0, 4000.0])
def test_every_rate_from_25_hz_to_4_khz_passes_the_checks_with_the_defaults(tmp_path, rx130l, rate_hz):
    cutoff_hz, decimation = record_filter_settings(rate_hz)
    assert cutoff_hz < 0.5 * rate_hz and decimation >= 1
    assert rate_hz / decimation > 2 * cutoff_hz            # the decimated rate still carries the kept band
    names = [str(n) for n in rx130l.model.names[1:]]
    # enough samples for the fit at this rate's decimation (the check states the count)
    duration_s = 60.0 if rate_hz < 100 else 12.0
    bag = write_joint_states(tmp_path / "log", _states(rx130l, rate_hz, duration_s, names))
    rec = load_user_record(Config(data_file=str(bag)), rx130l)
    assert rec.q_rad.shape[1] == rx130l.nq
    assert rec.sample_time_s == pytest.approx(1.0 / rate_hz)


def test_joints_by_name_in_any_order_extra_joints_ignored_bare_db3(tmp_path, rx130l):
    model = [str(n) for n in rx130l.model.names[1:]]
    recorded = ["gripper_finger", *reversed(model)]
    states = _states(rx130l, 100.0, 30.0, recorded)
    bag = write_joint_states(tmp_path / "log", states)
    bare = tmp_path / "log.db3"
    shutil.copy(next(bag.glob("*.db3")), bare)
    rec = load_user_record(Config(data_file=str(bare)), rx130l)
    order = [recorded.index(name) for name in model]
    np.testing.assert_array_equal(rec.q_rad, states.q_rad[:, order])
    np.testing.assert_array_equal(rec.tau_Nm, states.effort_Nm[:, order])


def test_a_joint_state_csv_reads_as_the_same_record_as_the_bag(tmp_path, rx130l):
    """The CSV ``arm play`` logs (``t_s, q_<joint>_rad, qd_<joint>_rad_s, effort_<joint>_Nm``): joints by
    name in any order, extra joints ignored, the same record as the bag of the same states; uneven
    stamps resampled."""
    model = [str(n) for n in rx130l.model.names[1:]]
    recorded = ["gripper_finger", *reversed(model)]
    states = _states(rx130l, 125.0, 30.0, recorded)
    from_bag = load_user_record(Config(data_file=str(write_joint_states(tmp_path / "log", states))), rx130l)
    from_csv = load_user_record(Config(data_file=str(write_joint_states_csv(tmp_path / "log.csv", states))), rx130l)
    order = [recorded.index(name) for name in model]
    np.testing.assert_array_equal(from_csv.q_rad, states.q_rad[:, order])
    np.testing.assert_array_equal(from_csv.tau_Nm, states.effort_Nm[:, order])
    np.testing.assert_array_equal(from_csv.q_rad, from_bag.q_rad)
    np.testing.assert_allclose(from_csv.t_s, from_bag.t_s, rtol=0, atol=1e-9)    # the bag's stamps are in ns
    jitter = 1e-3 * np.sin(np.arange(states.n_samples))              # a logger's uneven stamps
    uneven = JointStates(states.joint_names, states.t_s + jitter, states.q_rad, states.qd_rad_s, states.effort_Nm)
    rec = load_user_record(Config(data_file=str(write_joint_states_csv(tmp_path / "uneven.csv", uneven))), rx130l)
    assert rec.max_gap_s is not None and np.ptp(np.diff(rec.t_s)) < 1e-9
    j = recorded.index(model[2])
    np.testing.assert_allclose(rec.q_rad[:, 2], np.interp(rec.t_s, uneven.t_s, uneven.q_rad[:, j]), atol=1e-3)


@pytest.mark.parametrize("fmt", ["bag", "csv"])
def test_renamed_joints_need_the_stated_mapping(tmp_path, rx130l, fmt):
    model = [str(n) for n in rx130l.model.names[1:]]
    renamed = [f"axis_{chr(ord('a') + k)}" for k in range(len(model))]
    states = _states(rx130l, 100.0, 30.0, renamed)
    log = (write_joint_states(tmp_path / "log", states) if fmt == "bag"
           else write_joint_states_csv(tmp_path / "log.csv", states))
    with pytest.raises(DataFileError, match="identification.joint_names"):
        load_user_record(Config(data_file=str(log)), rx130l)
    mapped = Config(data_file=str(log), joint_names=dict(zip(renamed, model, strict=True)))
    assert load_user_record(mapped, rx130l).q_rad.shape == (3000, rx130l.nq)
    if fmt == "csv":     # a joint-state CSV whose effort column is misnamed is named, not half-read
        header = log.read_text().splitlines()[0].replace("effort_axis_c_Nm", "torque_axis_c_Nm")
        log.write_text("\n".join([header, *log.read_text().splitlines()[1:]]) + "\n")
        with pytest.raises(DataFileError, match="effort_axis_c_Nm"):
            load_user_record(mapped, rx130l)


def test_a_short_log_names_the_decimation_that_would_fix_it(tmp_path, rx130l):
    names = [str(n) for n in rx130l.model.names[1:]]
    bag = write_joint_states(tmp_path / "log", _states(rx130l, 1000.0, 1.0, names))
    with pytest.raises(DataFileError, match="identification.data_decimation"):
        load_user_record(Config(data_file=str(bag)), rx130l)


def test_a_file_that_is_no_bag_is_named(tmp_path: Path, rx130l):
    junk = tmp_path / "log.db3"
    junk.write_bytes(b"\xde" * 100)
    with pytest.raises(DataFileError, match="log.db3"):
        load_user_record(Config(data_file=str(junk)), rx130l)


def test_the_numbered_csv_layout_takes_t_s_as_its_time_column(tmp_path, rx130l):
    states = _states(rx130l, 100.0, 30.0, [str(n) for n in rx130l.model.names[1:]])
    n = rx130l.nq
    header = ",".join(["t_s", *(f"q{i + 1}" for i in range(n)), *(f"tau{i + 1}" for i in range(n))])
    table = np.column_stack([states.t_s, states.q_rad, states.effort_Nm])
    np.savetxt(tmp_path / "log.csv", table, delimiter=",", header=header, comments="", fmt="%.17g")
    rec = load_user_record(Config(data_file=str(tmp_path / "log.csv")), rx130l)
    np.testing.assert_array_equal(rec.q_rad, states.q_rad)
    assert rec.sample_time_s == pytest.approx(0.01)


@pytest.mark.parametrize(("delimiter", "decimal"), [(";", ","), ("\t", ".")])
def test_the_numbered_csv_reads_with_a_spreadsheet_delimiter(tmp_path, rx130l, delimiter, decimal):
    """A record exported with ``;`` and decimal commas, or tab-separated, reads as the comma file."""
    t = np.arange(3000) * 0.004
    q = 0.3 * np.sin(np.outer(t, np.arange(1, 7)))
    tau = np.cos(np.outer(t, np.arange(1, 7)))
    header = ["t", *(f"q{i}" for i in range(1, 7)), *(f"tau{i}" for i in range(1, 7))]
    table = np.column_stack([t, q, tau])
    plain, exported = tmp_path / "plain.csv", tmp_path / "exported.csv"
    plain.write_text("\n".join([",".join(header)] + [",".join(repr(float(v)) for v in row) for row in table]) + "\n")
    exported.write_text("\n".join([delimiter.join(header)] + [
        delimiter.join(repr(float(v)).replace(".", decimal) for v in row) for row in table]) + "\n")
    a = load_user_record(Config(data_file=str(plain)), rx130l)
    b = load_user_record(Config(data_file=str(exported)), rx130l)
    np.testing.assert_array_equal(a.q_rad, b.q_rad)
    np.testing.assert_array_equal(a.tau_Nm, b.tau_Nm)


def _rtde_csv(path: Path, states: JointStates, effort_output: str, delimiter: str) -> Path:
    """An RTDE recording as UR's client (space) or ur_rtde (comma) writes it, with the controller's commanded
    torques beside the measured effort (never to be read)."""
    n = states.q_rad.shape[1]
    header = (["timestamp"] + [f"target_moment_{j}" for j in range(n)] + [f"actual_q_{j}" for j in range(n)]
              + [f"actual_qd_{j}" for j in range(n)] + [f"{effort_output}_{j}" for j in range(n)] + ["robot_mode"])
    table = np.column_stack([1234.5 + states.t_s, 99.0 * np.ones_like(states.q_rad), states.q_rad,
                             np.gradient(states.q_rad, states.t_s, axis=0), states.effort_Nm,
                             np.full(states.n_samples, 7.0)])
    path.write_text("\n".join([delimiter.join(header)] + [delimiter.join(repr(float(v)) for v in row)
                                                           for row in table]) + "\n")
    return path


@pytest.mark.parametrize(("effort_output", "delimiter"), [("actual_current", " "), ("actual_current_as_torque", ",")])
def test_a_ur_rtde_recording_reads_as_the_joint_state_csv(tmp_path, rx130l, effort_output, delimiter):
    """UR's RTDE client logs (space-delimited) and ur_rtde's (comma): joints by index, the measured effort,
    never the controller's commanded torque; times from the first sample."""
    model = [str(n) for n in rx130l.model.names[1:]]
    states = _states(rx130l, 125.0, 30.0, model)
    reference = load_user_record(Config(data_file=str(write_joint_states_csv(tmp_path / "log.csv", states))), rx130l)
    rtde = _rtde_csv(tmp_path / "rtde_log.csv", states, effort_output, delimiter)
    rec = load_user_record(Config(data_file=str(rtde)), rx130l)
    np.testing.assert_array_equal(rec.q_rad, reference.q_rad)
    np.testing.assert_array_equal(rec.tau_Nm, reference.tau_Nm)
    np.testing.assert_allclose(rec.t_s, reference.t_s, atol=1e-9)


def test_an_rtde_recording_of_another_number_of_joints_is_named(tmp_path, rx130l):
    states = _states(rx130l, 125.0, 30.0, [f"j{k}" for k in range(7)])
    with pytest.raises(DataFileError, match="7 actual_q_<i> columns for a model of 6 joints"):
        load_user_record(Config(data_file=str(_rtde_csv(tmp_path / "rtde.csv", states, "actual_current", " "))),
                         rx130l)


def test_an_rtde_recording_with_a_repeated_column_or_a_bad_time_stamp_is_named(tmp_path, rx130l):
    states = _states(rx130l, 125.0, 30.0, [str(n) for n in rx130l.model.names[1:]])
    good = _rtde_csv(tmp_path / "rtde.csv", states, "actual_current", " ")
    lines = good.read_text().splitlines()
    repeated = tmp_path / "repeated.csv"
    repeated.write_text("\n".join([lines[0] + " actual_q_0"] + [ln + " 0.0" for ln in lines[1:]]) + "\n")
    with pytest.raises(DataFileError, match="more than once"):
        load_user_record(Config(data_file=str(repeated)), rx130l)
    word = tmp_path / "word.csv"
    word.write_text("\n".join([*lines[:5], lines[5].replace(lines[5].split(" ")[3], "n/a", 1), *lines[6:]]) + "\n")
    with pytest.raises(DataFileError, match="line 6: not a number: 'n/a'"):
        load_user_record(Config(data_file=str(word)), rx130l)
    stamps = tmp_path / "stamps.csv"
    cells = lines[10].split(" ")
    cells[0] = lines[9].split(" ")[0]                                   # a repeated time stamp on line 11
    stamps.write_text("\n".join([*lines[:10], " ".join(cells), *lines[11:]]) + "\n")
    with pytest.raises(DataFileError, match="line 11, timestamp"):
        load_user_record(Config(data_file=str(stamps)), rx130l)
