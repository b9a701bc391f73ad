"""Quality gates, integrity, locks and mixed runs in the runner (fake stages: fast)."""

from __future__ import annotations

import errno
import json
import os
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from pipeline import cli
from pipeline.core import config
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import ArtefactWriteError, PipelineError, QualityGateError
from pipeline.core.interrupts import INTERRUPT_STATUSES, raise_if_interrupted
from pipeline.quality import QualityGates
from pipeline.run import locking, stage_io
from pipeline.run import stages as stage_registry
from pipeline.run.locking import RunLockedError, run_lock
from pipeline.run.runner import run_pipeline
from pipeline.run.stage_io import file_sha256, load_run
from pipeline.stage_api import StageResult

QUIET = {"log": lambda m: None}


@dataclass
class GateConfig:
    value: float = 1.0            # the stage's figure of merit; gate: value <= 2
    n: int = 3


def _gate_stage(name: str, depends: tuple[str, ...], calls: list[str]) -> SimpleNamespace:
    def run(ctx):
        calls.append(name)
        (ctx.out_dir / "extra.txt").write_text("made by the stage\n")
        result = StageResult(summary={"value": ctx.config.value},
                             arrays={"x": np.arange(ctx.config.n, dtype=float)}, data={"ok": True})
        gates = QualityGates(name, accept_poor=ctx.run.accept_poor)
        gates.check("value", ctx.config.value, "<=", 2.0, "fake figure")
        return gates.finish(result)

    return SimpleNamespace(NAME=name, DEPENDS=depends, Config=GateConfig, run=run, __file__=None)


@pytest.fixture
def gate_stages(monkeypatch):
    calls: list[str] = []
    registry = {"a": _gate_stage("a", (), calls), "b": _gate_stage("b", ("a",), calls),
                "c": _gate_stage("c", ("b",), calls)}
    monkeypatch.setattr(stage_registry, "STAGES", registry)
    # the built-in robots' run_defaults name the real stages' sections, which the fakes replace
    monkeypatch.setattr(config, "robot_run_defaults", lambda cfg: None)
    return calls


# ------------------------------------------------------------------------------- quality gates
def test_failed_gate_keeps_result_aside_and_hands_nothing_on(gate_stages, tmp_path):
    with pytest.raises(QualityGateError, match=r"value = 5, must be <= 2"):
        run_pipeline(load_config(None, ["name=r", "b.value=5"]), out_root=tmp_path, **QUIET)
    run_dir = tmp_path / "r"
    assert gate_stages == ["a", "b"]                                 # c never ran
    assert (run_dir / "a" / "inputs.sha256").exists() and not (run_dir / "b").exists()
    rejected = run_dir / "b.rejected"
    assert json.loads((rejected / "summary.json").read_text())["value"] == 5.0
    assert (rejected / "extra.txt").exists() and not (rejected / "inputs.sha256").exists()
    assert json.loads((rejected / "manifest.json").read_text())["rejected"] is True
    assert set(load_run(run_dir)) == {"a"}                           # never loaded as a stage
    assert "b.rejected/" in (run_dir / "report.md").read_text()
    # a later good run removes the rejected result
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, **QUIET)
    assert not rejected.exists() and set(load_run(run_dir)) == {"a", "b", "c"}


def test_cli_gate_is_one_line_exit_3(gate_stages, tmp_path, capsys):
    code = cli.main(["run", "--set", "name=r", "--set", "a.value=9", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3
    assert err[-2].startswith("a: quality gate failed")       # progress log line, then the error line
    assert err[-1].startswith("quality gate failed: a: value: value = 9, must be <= 2")
    assert len([line for line in err if "quality gate failed: " in line]) == 1


def test_accept_poor_is_marked_and_not_reused_without_it(gate_stages, tmp_path):
    cfg = load_config(None, ["name=r", "b.value=5"])
    cfg.accept_poor = True
    run_pipeline(cfg, out_root=tmp_path, **QUIET)
    run_dir = tmp_path / "r"
    assert json.loads((run_dir / "b" / "summary.json").read_text())["accepted_poor"] is True
    report = (run_dir / "report.md").read_text()
    assert "ACCEPTED POOR" in report and "value = 5, must be <= 2" in report
    gate_stages.clear()
    cfg.accept_poor = True                                            # same flag: reused
    assert run_pipeline(cfg, out_root=tmp_path, **QUIET).reused == ["a", "b", "c"]
    messages: list[str] = []
    with pytest.raises(QualityGateError):                             # without: b re-runs and fails
        run_pipeline(load_config(None, ["name=r", "b.value=5"]), out_root=tmp_path, log=messages.append)
    assert gate_stages == ["b"]
    assert any("b: re-running because it was accepted with --accept-poor" in m for m in messages)


# ------------------------------------------------------------------------------------ integrity
@pytest.mark.parametrize("damage", ["delete_npz", "truncate_npz", "edit_summary", "delete_extra", "no_manifest"])
def test_damaged_stage_is_rerun_and_refused_by_load_run(gate_stages, tmp_path, damage):
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, **QUIET)
    b = tmp_path / "r" / "b"
    if damage == "delete_npz":
        (b / "results.npz").unlink()
    elif damage == "truncate_npz":
        data = (b / "results.npz").read_bytes()
        (b / "results.npz").write_bytes(data[: len(data) // 2])
    elif damage == "edit_summary":
        (b / "summary.json").write_text(json.dumps({"value": 0.5}))
    elif damage == "delete_extra":
        (b / "extra.txt").unlink()
    else:
        (b / "manifest.json").unlink()
    with pytest.raises(PipelineError, match=r"/r/b: "):
        load_run(tmp_path / "r")
    gate_stages.clear()
    messages: list[str] = []
    result = run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=messages.append)
    assert gate_stages == ["b"] and result.reused == ["a", "c"]
    assert any(m.startswith("b: re-running because its files are damaged") for m in messages)
    assert json.loads((b / "summary.json").read_text())["value"] == 1.0
    assert set(load_run(tmp_path / "r")) == {"a", "b", "c"}


def test_manifest_lists_every_file_with_its_sha256(gate_stages, tmp_path):
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, **QUIET)
    manifest = json.loads((tmp_path / "r" / "a" / "manifest.json").read_text())
    files = manifest["files_sha256"]
    assert set(files) == {"summary.json", "results.npz", "results.json", "extra.txt"}
    assert all(file_sha256(tmp_path / "r" / "a" / f) == h for f, h in files.items())


def test_mixed_run_is_refused(gate_stages, tmp_path):
    run_pipeline(load_config(None, ["name=r", "seed=1"]), out_root=tmp_path, **QUIET)
    run_pipeline(load_config(None, ["name=r", "seed=2", "stages=[a]"]), out_root=tmp_path, **QUIET)
    with pytest.raises(PipelineError, match="mixed run"):
        load_run(tmp_path / "r")
    run_pipeline(load_config(None, ["name=r", "seed=2"]), out_root=tmp_path, **QUIET)
    assert set(load_run(tmp_path / "r")) == {"a", "b", "c"}


# ------------------------------------------------------------------------------------------ lock
def test_second_run_on_a_locked_directory_names_the_holder(gate_stages, tmp_path, capsys):
    run_dir = tmp_path / "r"
    run_dir.mkdir()
    with run_lock(run_dir):
        with pytest.raises(RunLockedError, match=f"process {os.getpid()} is running on this run directory"):
            run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, **QUIET)
        assert cli.main(["run", "--set", "name=r", "--out", str(tmp_path)]) == 2
        assert f"process {os.getpid()}" in capsys.readouterr().err
        assert not (run_dir / "a").exists()
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, **QUIET)      # released
    assert (run_dir / "c" / "inputs.sha256").exists()


# ------------------------------------------------------------------------------------ interrupts
@pytest.mark.parametrize("status", sorted(INTERRUPT_STATUSES))
def test_interrupt_statuses_raise_keyboard_interrupt(status):
    with pytest.raises(KeyboardInterrupt):
        raise_if_interrupted({"return_status": status, "success": False})
    raise_if_interrupted({"return_status": "Solve_Succeeded"})
    raise_if_interrupted("Maximum_Iterations_Exceeded")        # a failure, not an interrupt


# ----------------------------------------------------------------------------------- check / cli
def test_check_writes_nothing_and_lists_run_or_reuse(gate_stages, tmp_path, capsys):
    assert cli.main(["check", "--set", "name=r", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "a: run (not run yet)" in out and not (tmp_path / "r").exists()
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, **QUIET)
    assert cli.main(["check", "--set", "name=r", "--set", "c.n=4", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "a: reuse" in out and "b: reuse" in out and "c: run (inputs changed: c.n)" in out
    assert cli.main(["check", "--set", "name=r", "--set", "c.n=x", "--out", str(tmp_path)]) == 2


def test_version_and_run_help_list_stages_and_robots(capsys):
    with pytest.raises(SystemExit):
        cli.main(["--version"])
    assert capsys.readouterr().out.startswith("pipeline ")
    with pytest.raises(SystemExit):
        cli.main(["run", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "model, calibration, identification, control, trajectory" in out and "rx130l" in out


def test_unwritable_run_dir_is_one_line(gate_stages, tmp_path, monkeypatch):
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, **QUIET)

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(stage_io, "new_stage_dir", full)
    before = (tmp_path / "r" / "c" / "summary.json").read_bytes()
    with pytest.raises(PipelineError, match="No space left on device"):
        run_pipeline(load_config(None, ["name=r", "c.n=5"]), out_root=tmp_path, **QUIET)
    assert (tmp_path / "r" / "c" / "summary.json").read_bytes() == before


def test_read_only_run_dir_reuses_everything_or_says_why_not(gate_stages, tmp_path, monkeypatch):
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, **QUIET)
    real_open = os.open

    def read_only(path, flags, *args):
        if str(path).endswith(".lock"):
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real_open(path, flags, *args)

    monkeypatch.setattr(locking.os, "open", read_only)
    messages: list[str] = []
    result = run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=messages.append)
    assert result.reused == ["a", "b", "c"] and "nothing written" in messages[-1]
    with pytest.raises(ArtefactWriteError, match="read-only and stage c must run"):
        run_pipeline(load_config(None, ["name=r", "c.n=7"]), out_root=tmp_path, **QUIET)


def test_check_validates_the_data_files_of_real_stages_and_writes_nothing(tmp_path, capsys):
    missing = tmp_path / "missing.csv"
    out = tmp_path / "runs"
    code = cli.main(["check", "--config", str(CONFIGS_DIR / "quick.yaml"), "--set",
                     f"identification.data_file={missing}", "--out", str(out)])
    assert code == 2 and capsys.readouterr().err.strip() == f"error: {missing}: file not found"
    assert not out.exists()
