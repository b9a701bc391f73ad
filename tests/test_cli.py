"""The command line as a user meets it: one-line errors, exit code 2, nothing written."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline import cli
from pipeline.core.config import load_config
from pipeline.papers import registry as studies
from pipeline.run import stages as stage_registry
from pipeline.run.runner import run_pipeline

REPO = Path(__file__).resolve().parents[1]


def run_cli(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    """``python -m pipeline *args`` in a child process (the entry point and its exit code)."""
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, "-m", "pipeline", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture
def cli_in_process(capsys, monkeypatch):
    """``cli_in_process(*args) -> CompletedProcess``: :func:`pipeline.cli.main` in this process, run
    from the repository root, with its exit code and captured output (the same code path as
    :func:`run_cli` without a child interpreter's imports; any uncaught exception fails the test
    where the child process would have printed a traceback)."""
    monkeypatch.chdir(REPO)

    def call(*args: str) -> subprocess.CompletedProcess:
        capsys.readouterr()
        code = cli.main(list(args))
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(["pipeline", *args], code, out, err)

    return call


def assert_one_line_error(proc: subprocess.CompletedProcess, out: Path, *fragments: str) -> str:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and not ln.startswith("warning:")]
    assert len(lines) == 1, proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert not out.exists() or not any(out.rglob("*")), list(out.rglob("*"))
    return lines[0]


@pytest.fixture
def robot_copy(tmp_path):
    src = REPO / "robots" / "rx130l"
    dst = tmp_path / "myrobot"
    shutil.copytree(src, dst)
    return dst


def test_unknown_robot(tmp_path, cli_in_process):
    out = tmp_path / "runs"
    proc = cli_in_process("run", "--set", "robot=does_not_exist", "--out", str(out))
    assert_one_line_error(proc, out, "--set", "robot", "does_not_exist")


def test_urdf_not_xml(tmp_path, robot_copy, cli_in_process):
    (robot_copy / "rx130l.urdf").write_text("this is { not xml\n")
    out = tmp_path / "runs"
    proc = cli_in_process("run", "--stages", "model", "--set", f"robot={robot_copy}", "--out", str(out))
    assert_one_line_error(proc, out, str(robot_copy / "rx130l.urdf"), "XML")


def test_negative_mass_in_robot_yaml(tmp_path, robot_copy, cli_in_process):
    yaml_file = robot_copy / "robot.yaml"
    text = yaml_file.read_text()
    assert "payload_kg: 10.0" in text
    yaml_file.write_text(text.replace("payload_kg: 10.0", "payload_kg: -10.0"))
    out = tmp_path / "runs"
    proc = cli_in_process("run", "--stages", "model", "--set", f"robot={robot_copy}", "--out", str(out))
    assert_one_line_error(proc, out, yaml_file.name, "payload_kg")


def test_negative_link_mass_in_urdf(tmp_path, robot_copy, cli_in_process):
    urdf = robot_copy / "rx130l.urdf"
    urdf.write_text(urdf.read_text().replace('<mass value="35"/>', '<mass value="-35"/>', 1))
    out = tmp_path / "runs"
    proc = cli_in_process("run", "--stages", "model", "--set", f"robot={robot_copy}", "--out", str(out))
    assert_one_line_error(proc, out, str(urdf), "mass")


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        ("name: t\nstages: [model]\nbogus_key: 3\n", ["bogus_key", "unknown key"]),
        ("name: t\nstages: [model, no_such_stage]\n", ["stages", "no_such_stage"]),
        ("name: t\nstages: [model]\nmodel: {no_such_setting: 1}\n", ["model.no_such_setting", "unknown key"]),
        ("name: t\nstages: [model]\nmodel: {picture_size_in: big}\n", ["model.picture_size_in", "expected number"]),
    ],
)
def test_bad_config_file(tmp_path, text, fragments, cli_in_process):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(text)
    out = tmp_path / "runs"
    proc = cli_in_process("run", "--config", str(cfg), "--out", str(out))
    line = assert_one_line_error(proc, out, *fragments)
    assert line.startswith(f"error: {cfg}: ")


def test_bad_set_and_stage_in_process(tmp_path, capsys):
    out = tmp_path / "runs"
    assert cli.main(["run", "--stages", "model,nope", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert re.fullmatch(r"error: --stages: stages: unknown stage 'nope' .*\n", err)
    assert cli.main(["run", "--stages", "model", "--set", "model.views_deg=3", "--out", str(out)]) == 2
    assert "error: --set: model.views_deg: expected a list" in capsys.readouterr().err
    assert not out.exists()


def test_missing_stage_module_reported(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(stage_registry, "STAGES",
                        {**stage_registry.STAGES, "ghost": "pipeline.ghost_not_written.stage"})
    out = tmp_path / "runs"
    assert cli.main(["run", "--stages", "ghost", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "stage 'ghost' is not available" in err and "pipeline.ghost_not_written.stage" in err
    assert not out.exists()


def test_model_stage_end_to_end(tmp_path, cli_in_process):
    out = tmp_path / "runs"
    proc = run_cli("run", "--stages", "model", "--set", "name=e2e", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    run_dir = out / "e2e"
    report = (run_dir / "report.md").read_text()
    assert "](model/robot.png)" in report and "| dof | 6 |" in report
    png = (run_dir / "model" / "robot.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    # the second run in this process (the entry point is covered above): the stage is reused
    proc2 = cli_in_process("run", "--stages", "model", "--set", "name=e2e", "--out", str(out))
    assert proc2.returncode == 0 and "model: reused" in proc2.stderr


def test_study_registry(monkeypatch, capsys):
    calls = []
    monkeypatch.setitem(studies.STUDIES, "demo", f"{__name__}:_demo_study")
    globals()["_CALLS"] = calls
    assert cli.main(["study", "demo", "--n", "3"]) == 0
    assert calls == [["--n", "3"]]
    assert cli.main(["study"]) == 0 and "demo" in capsys.readouterr().out
    assert cli.main(["study", "nope"]) == 2
    assert "error: study: nope: unknown study" in capsys.readouterr().err


def _demo_study(argv: list[str]) -> None:
    globals()["_CALLS"].append(argv)


def test_joint_without_limits_is_one_line(tmp_path, robot_copy, cli_in_process):
    urdf = robot_copy / "rx130l.urdf"
    text = urdf.read_text()
    start = text.index("<limit", text.index('<joint name="joint_2"'))
    urdf.write_text(text[:start] + text[text.index("/>", start) + 2:])
    out = tmp_path / "runs"
    proc = cli_in_process("run", "--stages", "model", "--set", f"robot={robot_copy}", "--out", str(out))
    assert_one_line_error(proc, out, str(urdf), "joint joint_2: <limit>", "lower")


def test_out_that_is_a_file(tmp_path, cli_in_process):
    target = tmp_path / "a_file"
    target.write_text("")
    proc = cli_in_process("run", "--stages", "model", "--out", str(target))
    assert_one_line_error(proc, tmp_path / "nothing", "--out", "cannot create the run directory")


def test_stage_check_names_the_source(tmp_path, cli_in_process):
    out = tmp_path / "runs"
    proc = cli_in_process("run", "--set", "trajectory.cp_segment=zigzag", "--out", str(out))
    assert_one_line_error(proc, out, "--set", "trajectory.cp_segment")


@pytest.mark.slow
def test_second_robot_runs_every_stage(tmp_path):
    """The TX40 through the whole quick pipeline: its robot.yaml run_defaults put the ISO cube in
    its workspace; feedforward from its identified model beats feedback alone."""
    out = tmp_path / "runs"
    proc = run_cli("run", "--config", "configs/quick.yaml", "--set", "robot=staubli_tx40", "--set", "name=tx40",
                   "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-2000:]
    run = out / "tx40"
    assert (run / "report.md").is_file()
    control = json.loads((run / "control" / "summary.json").read_text())
    errors = control["tcp_error_max_m"]
    assert errors["full_friction"] < errors["none"]
    trajectory = json.loads((run / "trajectory" / "summary.json").read_text())
    assert trajectory["ptp_duration_s"] < trajectory["ptp_ruckig_duration_s"]


def test_model_pose_checked_before_anything_is_written(tmp_path, cli_in_process):
    """The user's repro: a pose that does not fit the robot is named with its source (--set)
    before the run directory is touched."""
    out = tmp_path / "runs"
    proc = cli_in_process("run", "--config", "configs/quick.yaml", "--stages", "model",
                   "--set", "model.pose_deg=[0,0,0,0,200,0]", "--out", str(out))
    assert_one_line_error(proc, out, "error: --set: model.pose_deg: ", "outside the joint limits")


def test_check_error_names_the_layer_of_the_field(tmp_path, capsys):
    cfg = tmp_path / "pose.yaml"
    cfg.write_text("name: t\nstages: [model]\nmodel: {pose_deg: [0, 0, 0]}\n")
    out = tmp_path / "runs"
    # --set touches another field of the section: the pose still came from the file
    assert cli.main(["run", "--config", str(cfg), "--set", "model.picture_size_in=4", "--out", str(out)]) == 2
    assert capsys.readouterr().err == f"error: {cfg}: model.pose_deg: expected 6 angles (deg), one per joint, got 3\n"
    assert cli.main(["run", "--config", str(cfg), "--set", "model.pose_deg=[0,0,0,0,0]", "--out", str(out)]) == 2
    assert capsys.readouterr().err.startswith("error: --set: model.pose_deg: expected 6 angles")
    assert not out.exists()


def test_failed_run_report_says_failed_and_marks_stale_stages(fake_stages, tmp_path):
    quiet = {"out_root": tmp_path, "log": lambda m: None}
    run_pipeline(load_config(None, ["name=r"]), **quiet)
    report = tmp_path / "r" / "report.md"
    assert "FAILED" not in report.read_text() and "stale" not in report.read_text()
    with pytest.raises(RuntimeError, match="failed halfway"):
        run_pipeline(load_config(None, ["name=r", "b.fail=true", "b.n=5"]), **quiet)
    text = report.read_text()
    head = text.split("## ")[0]
    assert "**FAILED in stage `b`**: RuntimeError: stage b failed halfway" in head
    sections = {s.split("\n", 1)[0]: s for s in text.split("## ")[1:]}
    assert "stale" not in sections["a"]                                     # reused: same inputs
    assert "_stale: this stage FAILED in this run" in sections["b"]
    assert "_stale: from an earlier run with different inputs" in sections["c"]
    # a successful run afterwards: no marker left
    run_pipeline(load_config(None, ["name=r"]), **quiet)
    assert "FAILED" not in report.read_text() and "stale" not in report.read_text()
