"""Errors reported before anything runs or is written: the configuration at load time (with
the file or ``--set`` that set the bad value) and the user's record in the stage's ``check``
(called by the runner before calibration runs)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from pipeline.cli import main
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import ConfigError, DataFileError
from pipeline.identification import stage
from pipeline.robot.model import RobotModel
from pipeline.run.runner import run_pipeline

from .test_stage import _bad_record, _write_csv

QUICK = CONFIGS_DIR / "quick.yaml"


@pytest.mark.parametrize(("key", "value", "words"), [
    ("identification.excitation.n_samples", "-3", ("must be >= 10", "-3")),
    ("identification.periods", "0", ("must be >= 1",)),
    ("identification.excitation.torque_margin", "1.5", ("(0, 1]",)),
    ("identification.data_train_fraction", "1.0", ("(0, 1)",)),
    ("identification.sample_time_s", "0.003", ("does not divide",)),
])
def test_bad_value_from_set_names_set_at_load_time(key, value, words):
    with pytest.raises(ConfigError) as info:
        load_config(QUICK, [f"{key}={value}"])
    message = str(info.value)
    assert message.startswith(f"--set: {key}: "), message
    for word in words:
        assert word in message


def test_bad_value_from_a_file_names_the_file(tmp_path):
    data = yaml.safe_load(QUICK.read_text())
    data["identification"]["excitation"]["n_samples"] = -3
    path = tmp_path / "my.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"my\.yaml: identification\.excitation\.n_samples: must be >= 10"):
        load_config(path)
    # a later --set that repairs it wins, and a good value passes
    cfg = load_config(path, ["identification.excitation.n_samples=30"])
    assert cfg.identification.excitation.n_samples == 30


def test_cli_reports_a_bad_set_value_and_writes_nothing(tmp_path, capsys):
    code = main(["run", "--config", str(QUICK), "--stages", "identification", "--out", str(tmp_path / "runs"),
                 "--set", "identification.excitation.n_samples=-3"])
    err = capsys.readouterr().err
    assert code == 2
    assert "--set: identification.excitation.n_samples: must be >= 10" in err
    assert not (tmp_path / "runs").exists()


def test_cli_reports_a_bad_data_file_before_calibration_runs(tmp_path, capsys):
    path = _bad_record(tmp_path, "nan")
    code = main(["run", "--config", str(QUICK), "--stages", "identification", "--out", str(tmp_path / "runs"),
                 "--set", f"identification.data_file={path}", "--set", "identification.run_tx40=false"])
    err = capsys.readouterr().err
    assert code == 2
    assert "record.csv: q3: NaN or inf on line 125" in err
    assert not (tmp_path / "runs").exists()  # no calibration/, nothing at all


@pytest.mark.parametrize("problem", ["short_row", "outside_limits", "header_only", "too_few"])
def test_runner_checks_the_data_file_before_any_stage(tmp_path, problem):
    path = _bad_record(tmp_path, problem)
    cfg = load_config(QUICK, stages=["identification"],
                      values={"identification.data_file": str(path), "identification.run_tx40": False})
    with pytest.raises(DataFileError, match="record.csv"):
        run_pipeline(cfg, out_root=tmp_path / "runs")
    assert not (tmp_path / "runs" / cfg.name / "calibration").exists()
    assert not (tmp_path / "runs").exists()


def test_check_accepts_a_good_record_and_a_missing_file_is_named(tmp_path):
    robot = RobotModel.load("rx130l")
    t = np.arange(3000) * 0.002
    q = 0.3 * np.sin(np.outer(t, np.arange(1, 7)))
    _write_csv(tmp_path / "good.csv", t, q, np.cos(np.outer(t, np.arange(1, 7))))
    stage.check(stage.Config(data_file=str(tmp_path / "good.csv")), robot)
    stage.check(stage.Config(), robot)  # no data file: nothing to read
    with pytest.raises(DataFileError, match=r"nothere\.csv: file not found"):
        stage.check(stage.Config(data_file=str(tmp_path / "nothere.csv")), robot)
    # a cut-off above the record's Nyquist frequency (250 Hz) is reported early too
    with pytest.raises(ConfigError, match="data_cutoff_hz"):
        stage.check(stage.Config(data_file=str(tmp_path / "good.csv"), data_cutoff_hz=300.0), robot)
