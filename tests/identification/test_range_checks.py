"""Range checks of every identification setting (load time: ``Config.validate``; robot-dependent
and file checks: ``stage.check``, before anything is written), the TX40 record's folder, and
implausible time units of a user record."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import ConfigError, DataFileError
from pipeline.identification import stage
from pipeline.identification.config import Tx40Config
from pipeline.identification.tx40 import TX40_DATA_DIR, check_tx40_config
from pipeline.robot.model import RobotModel

from .test_stage import _write_csv

QUICK = CONFIGS_DIR / "quick.yaml"


@pytest.fixture(scope="module")
def robot():
    return RobotModel.load("rx130l")


@pytest.mark.parametrize(("key", "value", "words"), [
    ("identification.tx40.max_iter", "-1", (">= 1", "-1")),
    ("identification.tx40.max_iter", "0", (">= 1",)),
    ("identification.tx40.regularization", "-0.1", (">= 0",)),
    ("identification.tx40.cutoff_hz", "3000", ("(0, 2500) Hz",)),
    ("identification.tx40.max_samples", "-5", (">= 0",)),
    ("identification.excitation.harmonics", "30", ()),      # n_samples 60 no longer resolves them
    ("identification.excitation.base_frequency_hz", ".inf", ("> 0",)),
    ("identification.excitation.floor_clearance_m", "50", ("[0, 1) m",)),
    ("identification.excitation.self_clearance_m", "-0.01", ("[0, 1) m",)),
    ("identification.excitation.cond_softness", ".nan", (">= 0",)),
    ("identification.base_tolerance", "2", ("(0, 1)",)),
    ("identification.regularization", ".inf", (">= 0",)),
    ("identification.sample_time_s", "0.5", ("(0, 0.05] s",)),
    ("identification.validation_sample_time_s", "0", ("(0, 0.05] s",)),
    ("identification.state_cutoff_factor", "600", ("Nyquist", "300 Hz")),
    ("identification.replay_rate_hz", "-1", ("> 0",)),
])
def test_bad_value_names_set_and_field_at_load_time(key, value, words):
    with pytest.raises(ConfigError) as info:
        load_config(QUICK, [f"{key}={value}"])
    message = str(info.value)
    field = "identification.excitation.n_samples" if key.endswith("harmonics") else key
    assert message.startswith(f"--set: {field}: "), message
    for word in words:
        assert word in message, (word, message)


def test_quick_and_full_defaults_pass_the_checks(robot):
    cfg = load_config(QUICK)
    cfg.identification.validate("quick.yaml")
    stage.check(cfg.identification, robot)
    stage.check(stage.Config(), robot)
    check_tx40_config(Tx40Config())


@pytest.mark.parametrize(("overrides", "field", "words"), [
    ({"base_samples": 5}, "identification.base_samples", ("at least 14",)),
    ({"decimation": 2000}, "identification.decimation", ("at most",)),
    ({"run_tx40": True, "tx40": Tx40Config(max_samples=200)}, "identification.tx40.max_samples", ("200 raw samples",)),
    ({"tx40": Tx40Config(data_dir="/nonexistent/tx40")}, "identification.tx40.data_dir", ("does not exist",)),
])
def test_robot_dependent_checks_name_the_field(robot, overrides, field, words):
    cfg = load_config(QUICK).identification
    for k, v in overrides.items():
        setattr(cfg, k, v)
    with pytest.raises(ConfigError) as info:
        stage.check(cfg, robot)
    assert info.value.field == field, str(info.value)
    for word in words:
        assert word in info.value.problem


def test_tx40_folder_without_its_files_names_the_file(tmp_path):
    shutil.copy(TX40_DATA_DIR / "pos_read_data.csv", tmp_path / "pos_read_data.csv")
    with pytest.raises(DataFileError) as info:
        check_tx40_config(Tx40Config(data_dir=str(tmp_path)))
    assert "curr_data.csv" in str(info.value) and "file not found" in str(info.value)
    # no TX40 study: its folder is not checked
    stage.check(stage.Config(run_tx40=False, tx40=Tx40Config(data_dir=str(tmp_path))), RobotModel.load("rx130l"))


def test_cli_tx40_dir_is_checked_before_any_stage_runs(tmp_path, capsys):
    code = main(["run", "--config", str(QUICK), "--stages", "identification", "--out", str(tmp_path / "runs"),
                 "--set", "identification.tx40.data_dir=/nonexistent"])
    err = capsys.readouterr().err
    assert code == 2
    assert "--set: identification.tx40.data_dir: '/nonexistent' does not exist" in err
    assert not (tmp_path / "runs").exists()   # model and calibration did not run


def _record(tmp_path, dt, scale_t=1.0, degrees=False):
    t = np.arange(3000) * dt
    q = 0.3 * np.sin(np.outer(np.arange(3000) * 0.002, np.arange(1, 7)))
    if degrees:
        q = np.degrees(q)
    path = tmp_path / "record.csv"
    _write_csv(path, t * scale_t, q, np.cos(q))
    return path


def test_time_in_milliseconds_blames_column_t(robot, tmp_path):
    path = _record(tmp_path, 0.004, scale_t=1000.0)
    with pytest.raises(DataFileError) as info:
        stage.check(stage.Config(data_file=str(path), run_tx40=False), robot)
    message = str(info.value)
    assert message.startswith(f"{path}: t: "), message
    assert "must be in seconds" in message and "0.25 Hz sample rate" in message
    assert "milliseconds" in message
    assert "data_cutoff_hz" not in message


@pytest.mark.parametrize(("scale", "unit"), [(1e6, "microseconds"), (1e9, "nanoseconds")])
def test_time_in_micro_or_nanoseconds_is_named(robot, tmp_path, scale, unit):
    path = _record(tmp_path, 0.004, scale_t=scale)
    with pytest.raises(DataFileError, match=f"look like {unit}"):
        stage.check(stage.Config(data_file=str(path), run_tx40=False), robot)


def test_slow_sampling_below_the_cutoff_mentions_column_t(robot, tmp_path):
    path = _record(tmp_path, 0.04)   # 25 Hz: Nyquist 12.5 Hz < a 20 Hz cut-off set by hand
    with pytest.raises(ConfigError) as info:
        stage.check(stage.Config(data_file=str(path), run_tx40=False, data_cutoff_hz=20.0), robot)
    assert info.value.field == "identification.data_cutoff_hz"
    assert "25 Hz sample rate" in info.value.problem and "t must be in seconds" in info.value.problem


def test_joint_positions_in_degrees_get_a_hint(robot, tmp_path):
    path = _record(tmp_path, 0.002, degrees=True)
    with pytest.raises(DataFileError, match="look like degrees"):
        stage.check(stage.Config(data_file=str(path), run_tx40=False), robot)


def test_cli_time_in_milliseconds_writes_nothing(tmp_path, capsys):
    path = _record(tmp_path, 0.004, scale_t=1000.0)
    code = main(["run", "--config", str(QUICK), "--stages", "identification", "--out", str(tmp_path / "runs"),
                 "--set", f"identification.data_file={path}", "--set", "identification.run_tx40=false"])
    err = capsys.readouterr().err
    assert code == 2
    assert "record.csv: t: column t implies a sample interval of 4 s" in err
    assert not (tmp_path / "runs").exists()
