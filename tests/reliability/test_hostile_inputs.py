"""Hostile and misleading inputs, one case each: a robot.yaml whose digests look like numbers (written
quoted, read back as text also when an earlier version left them unquoted), NaN/inf/non-numbers and
a lower limit above the upper in a URDF, a single identified joint, a torque log whose columns are
all dead or whose joints never move, a recorded measurement combined with a simulated one, and a
sweep of fewer stages than the run would take. Each ends in one line and exit 2 (nothing written)
or in a correct result."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import pipeline.run  # noqa: F401 - registers the stages
from pipeline import cli
from pipeline.core import artefacts
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import DataFileError
from pipeline.identification.config import Config as IdentificationConfig
from pipeline.identification.record import load_user_record
from pipeline.identification.report import torques_figure
from pipeline.robot import assumed_values
from pipeline.robot.exact import load_exact_robot, robots_equal, save_exact_robot
from pipeline.robot.model import RobotModel
from pipeline.run import second_pass
from pipeline.run.headline import read_headline
from pipeline.run.stage_io import combined_arms, write_provenance
from pipeline.run.stage_plan import plan_stages
from pipeline.run.sweep import SECOND_PASS_KEY, SweepSpec, grid

ROBOT_DIR = Path(__file__).resolve().parents[2] / "robots" / "rx130l"
URDF_TEXT = (ROBOT_DIR / "rx130l.urdf").read_text()


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


# ------------------------------------------------------------------ robot.yaml digests
#: digests that a YAML 1.2 reader resolves to a float and to an int (with a leading zero) unquoted
NUMBER_LIKE_DIGESTS = ["30425e4453996520", "0304254453996520"]


@pytest.fixture(params=NUMBER_LIKE_DIGESTS)
def initialised_with_digest(request, tmp_path, monkeypatch):
    """A robot folder written by ``robot init`` for the RX130L URDF with every digest ``request.param``."""
    monkeypatch.setattr(assumed_values, "value_digest", lambda value: request.param)
    folder = tmp_path / "arm"
    folder.mkdir()
    shutil.copy(ROBOT_DIR / "rx130l.urdf", folder / "rx130l.urdf")
    assert cli.main(["robot", "init", str(folder / "rx130l.urdf"), "--out", str(folder / "robot.yaml")]) == 0
    return folder, request.param


def test_digests_that_look_like_numbers_are_written_quoted_and_read_back(initialised_with_digest):
    folder, digest = initialised_with_digest
    text = (folder / "robot.yaml").read_text()
    assert f"sha256: '{digest}'" in text or f'sha256: "{digest}"' in text
    robot = RobotModel.load(folder)
    assert robot.spec.assumed and all(e["sha256"] == digest for e in robot.spec.assumed.values())


def test_an_earlier_robot_yaml_with_unquoted_digests_loads_and_a_handed_on_robot_reads_back(
        initialised_with_digest, tmp_path):
    folder, digest = initialised_with_digest
    path = folder / "robot.yaml"
    path.write_text(re.sub(r"sha256: ['\"](\w+)['\"]", r"sha256: \1", path.read_text()))   # as PyYAML wrote it
    assert f"sha256: {digest}}}" in path.read_text() or f"sha256: {digest}\n" in path.read_text()
    robot = RobotModel.load(folder)
    assumed = dict(robot.spec.assumed)
    assert assumed and all(e["sha256"] == digest for e in assumed.values())
    handed_on = tmp_path / "handed_on"                     # what a stage writes to <stage>/robot/
    save_exact_robot(robot, handed_on)
    again = load_exact_robot(handed_on)
    assert robots_equal(robot, again) and again.spec.assumed == assumed


@pytest.mark.slow
def test_a_calibration_run_on_an_earlier_robot_yaml_hands_on_a_robot_that_reads_back(initialised_with_digest,
                                                                                     tmp_path):
    folder, _ = initialised_with_digest
    path = folder / "robot.yaml"
    path.write_text(re.sub(r"sha256: ['\"](\w+)['\"]", r"sha256: \1", path.read_text()))
    out = tmp_path / "runs"
    assert cli.main(["run", "--config", str(CONFIGS_DIR / "quick.yaml"), "--stages", "calibration",
                     "--set", f"robot={folder}", "--set", "name=old", "--set", "calibration.second_pass=never",
                     "--out", str(out)]) == 0
    handed_on = load_exact_robot(out / "old" / "calibration" / "robot")
    assert handed_on.spec.assumed == RobotModel.load(folder).spec.assumed


# ------------------------------------------------------------------ URDF values
def _urdf_with(tmp_path: Path, old: str, new: str) -> Path:
    assert old in URDF_TEXT
    folder = tmp_path / "arm"
    folder.mkdir(exist_ok=True)
    path = folder / "arm.urdf"
    path.write_text(URDF_TEXT.replace(old, new, 1))
    return path


@pytest.mark.parametrize(("old", "new", "words"), [
    ('izz="0.729"', 'izz="nan"', "link link_1: <inertia izz>: not a finite number: 'nan'"),
    ('<mass value="45"/>', '<mass value="inf"/>', "link link_1: <mass value>: not a finite number: 'inf'"),
    ('izz="0.729"', 'izz="1e999"', "<inertia izz>: not a finite number"),
    ('izz="0.729"', 'izz="8.98846567431158e+307"', "<inertia izz>: '8.98846567431158e+307' is beyond 1e+100"),
    ('izz="0.729"', 'izz="abc"', "<inertia izz>: expected a number, got 'abc'"),
    ('<origin xyz="0 0 0.55000000000000004"', '<origin xyz="0 nan 0.55"', "<origin xyz>: not a finite number"),
    ('<origin xyz="0 0 0.55000000000000004"', '<origin xyz="0 0.55"', "<origin xyz>: expected 3 numbers"),
    # numbers Python's float() reads and urdfdom's istream does not: each would leave an Error on stderr
    ('<cylinder radius="0.25"', '<cylinder radius="\u00a00.25"', "<cylinder radius>: expected a number"),
    ('<mass value="45"/>', '<mass value="4_5"/>', "<mass value>: expected a number, got '4_5'"),
    ('<mass value="45"/>', '<mass value="45 "/>', "<mass value>: expected a number, got '45 '"),
    ('<origin xyz="0 0 0.55000000000000004"', '<origin xyz="0 0 \u0665"', "<origin xyz>: expected 3 numbers"),
    ('lower="-2.79252680319" upper="2.79252680319"', 'lower="2.79252680319" upper="-2.79252680319"',
     "joint joint_1: limit: lower 2.79252680319 is above upper -2.79252680319"),
    # a file committed in the middle of a merge
    ('<robot name="', '<<<<<<< HEAD\n<robot name="', "not valid XML"),
])
def test_a_hostile_urdf_value_is_one_line_exit_2_and_nothing_written(tmp_path, capfd, old, new, words):
    path = _urdf_with(tmp_path, old, new)
    assert cli.main(["robot", "init", str(path)]) == 2
    captured = capfd.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {path}: ") and words in err[0], captured.err
    assert "urdfdom" not in captured.err and not captured.out.strip()
    assert sorted(p.name for p in path.parent.iterdir()) == ["arm.urdf"]
    if new.startswith("<<<<<<<"):
        assert "an unresolved merge conflict (<<<<<<< on line" in err[0]


# ------------------------------------------------------------------ a single identified joint
def test_the_torque_figure_of_a_single_joint_has_one_panel_named_by_its_joint():
    t = np.linspace(0, 1, 50)
    fig = torques_figure(t, np.sin(t)[:, None], np.cos(t)[:, None], "one joint", np.array([3]))
    assert len(fig.axes) == 1 and fig.axes[0].get_ylabel() == "tau3 [N m]"
    assert len(torques_figure(t, np.ones((50, 2)), np.ones((50, 2)), "two", None).axes) == 2


@pytest.mark.slow
def test_identification_of_a_single_joint_runs_every_step_and_plot(tmp_path):
    from pipeline.identification import fourier, stage
    from tests.identification.helpers import quick_context
    from tests.identification.test_stage import _NoHiddenRobot, _write_csv

    ctx, real = quick_context(tmp_path / "run", overrides={"run_tx40": False, "friction_model": "viscous_coulomb",
                                                           "joints": ["joint_1"]})
    limits = fourier.ExcitationLimits.from_robot(ctx.robot, 0.95, 0.95, 0.95, 0.8, 0.05, 0.02)
    traj = fourier.random_feasible_trajectories(ctx.robot, limits, 5, 0.1, 1, np.random.default_rng(7))[0]
    t = np.arange(10_000) * 0.002
    meas = real.execute_joint_trajectory(t, *traj.evaluate(t), np.random.default_rng(8))
    _write_csv(tmp_path / "record.csv", t, meas.q_rad, meas.tau_Nm)
    ctx.config.data_file = str(tmp_path / "record.csv")
    ctx.real = _NoHiddenRobot()
    result = stage.run(ctx)
    assert result.summary["joints_used"] == ["joint_1"]
    assert len(result.figures["validation_torques"].axes) == 1
    assert result.figures["validation_torques"].axes[0].get_ylabel() == "tau1 [N m]"


# ------------------------------------------------------------------ torque logs that mislead
def _log(path: Path, q: np.ndarray, tau: np.ndarray, dt: float = 0.004) -> Path:
    t = np.arange(len(q)) * dt
    header = "t," + ",".join(f"q{i}" for i in range(1, 7)) + "," + ",".join(f"tau{i}" for i in range(1, 7))
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=header, comments="")
    return path


def _moving(n: int = 600) -> np.ndarray:
    return 0.4 * np.sin(np.outer(np.arange(n) * 0.004, np.arange(1, 7)) * 1.3)


def test_every_torque_column_dead_names_the_data_file_not_set(tmp_path, capsys):
    path = _log(tmp_path / "dead.csv", _moving(), np.full((600, 6), 1.5))
    assert cli.main(["check", "--set", f"identification.data_file={path}", "--stages", "identification",
                     "--out", str(tmp_path / "runs")]) == 2
    line = _one_error_line(capsys)
    assert line.startswith(f"error: {path}: tau: no torque column carries a signal (tau1, tau2, tau3, tau4, tau5, "
                           "tau6: constant torque column")
    assert "--set" not in line and "identification.joints" not in line
    assert not (tmp_path / "runs").exists()


def test_a_log_whose_joints_never_move_says_so(tmp_path, rx130l):
    q = np.tile(_moving()[100], (600, 1))
    tau = 20 + np.random.default_rng(0).normal(size=(600, 6))              # noise: the columns are not dead
    path = _log(tmp_path / "still.csv", q, tau)
    with pytest.raises(DataFileError, match=rf"{re.escape(str(path))}: q: the joints never move") as info:
        load_user_record(IdentificationConfig(data_file=str(path)), rx130l)
    assert "\n" not in info.value.one_line()
    frozen = _log(tmp_path / "frozen.csv", q, np.full((600, 6), 3.0))     # at rest the torques are constant too
    with pytest.raises(DataFileError, match="the joints never move"):
        load_user_record(IdentificationConfig(data_file=str(frozen)), rx130l)


# ------------------------------------------------------------------ two different arms
@pytest.fixture
def recorded_files(tmp_path):
    cal = tmp_path / "tracker.csv"
    cal.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n0,0,0,0,0,0,1,0,0\n")
    log = tmp_path / "torques.csv"
    log.write_text("t,q1\n0,0\n")
    return cal, log


def _provenances(sets: list[str], stages: str) -> dict:
    cfg = load_config(CONFIGS_DIR / "quick.yaml", sets, stages)
    return {p.name: p.provenance for p in plan_stages(cfg)}


def test_a_recorded_calibration_with_a_simulated_identification_is_named_everywhere(tmp_path, recorded_files):
    cal, log = recorded_files
    mixed = _provenances([f"calibration.measurements_csv={cal}"], "identification")
    sentence = combined_arms(mixed)
    assert sentence.startswith("two different arms combined: calibration is recorded (tracker.csv), "
                               "identification is simulated") and "identification uses both" in sentence
    reverse = combined_arms(_provenances([f"identification.data_file={log}"], "control"))
    assert "calibration is simulated" in reverse and "identification is recorded (torques.csv)" in reverse
    assert "control uses both" in reverse
    assert combined_arms(_provenances([f"identification.data_file={log}"], "identification")) == ""
    assert combined_arms(_provenances([], "control")) == ""
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    record = write_provenance(run_dir, mixed, "")
    assert artefacts.read_json(record)["arms_combined"] == sentence
    assert sentence in read_headline(run_dir, list(mixed)).warnings


# ------------------------------------------------------------------ sweeps of fewer stages
def test_a_sweep_of_calibration_alone_runs_no_identification(tmp_path):
    spec = SweepSpec(seeds=[0, 1], robots=[None], out_dir=tmp_path, config_path=str(CONFIGS_DIR / "quick.yaml"),
                     stages="calibration")
    for point in grid(spec):
        assert f"{SECOND_PASS_KEY}=never" in point.overrides
        cfg = load_config(point.config_path, point.overrides, point.stages)
        planned = [p.name for p in plan_stages(cfg)]
        assert planned == ["model", "calibration"]
        assert second_pass.decision(cfg, planned, ["model", "calibration", "identification"]) == (False, "")
    both = SweepSpec(seeds=[0], robots=[None], out_dir=tmp_path, config_path=str(CONFIGS_DIR / "quick.yaml"),
                     stages="calibration,identification")
    assert all(f"{SECOND_PASS_KEY}=never" not in p.overrides for p in grid(both))
    asked = SweepSpec(seeds=[0], robots=[None], out_dir=tmp_path, config_path=str(CONFIGS_DIR / "quick.yaml"),
                      stages="calibration", overrides=[f"{SECOND_PASS_KEY}=always"])
    assert all(f"{SECOND_PASS_KEY}=never" not in p.overrides for p in grid(asked))
