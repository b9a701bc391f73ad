"""Relocatable runs, ``check`` agreeing with ``run``, and interrupts that surface as other errors
(fake stages: fast)."""

from __future__ import annotations

import json
import shutil
import signal
from dataclasses import dataclass
from typing import Annotated

import pytest

from pipeline import cli
from pipeline.core import interrupts
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.typed_config import FileInput
from pipeline.run import second_pass
from pipeline.run import stages as stage_registry
from pipeline.run.locking import run_lock
from pipeline.run.run_check import check_run
from pipeline.run.runner import run_pipeline

QUIET = {"log": lambda m: None}


def _manifests(run_dir):
    return {p.parent.name: json.loads(p.read_text()) for p in sorted(run_dir.glob("*/manifest.json"))}


def test_copied_run_reuses_every_stage_with_identical_artefacts(fake_stages, tmp_path):
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path / "one", **QUIET)
    shutil.copytree(tmp_path / "one", tmp_path / "elsewhere" / "two")
    before = _manifests(tmp_path / "elsewhere" / "two" / "r")
    again = run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path / "elsewhere" / "two", **QUIET)
    assert again.ran == [] and again.reused == ["a", "b", "c"]
    assert _manifests(tmp_path / "elsewhere" / "two" / "r") == before


def test_file_inputs_enter_the_hash_by_content_not_path(fake_stages, tmp_path, monkeypatch):
    fake = stage_registry.STAGES["a"]

    @dataclass
    class FileConfig(fake.Config):
        label: Annotated[str, FileInput] = "x"

    monkeypatch.setattr(fake, "Config", FileConfig)
    for folder in ("x", "y"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "data.csv").write_text("q1\n0.1\n")
    run_pipeline(load_config(None, ["name=r", f"a.label={tmp_path / 'x' / 'data.csv'}"]), out_root=tmp_path, **QUIET)
    moved = run_pipeline(load_config(None, ["name=r", f"a.label={tmp_path / 'y' / 'data.csv'}"]),
                         out_root=tmp_path, **QUIET)
    assert moved.ran == []                                   # same content elsewhere: reused
    (tmp_path / "y" / "data.csv").write_text("q1\n0.2\n")
    logs: list[str] = []
    edited = run_pipeline(load_config(None, ["name=r", f"a.label={tmp_path / 'y' / 'data.csv'}"]),
                          out_root=tmp_path, log=logs.append)
    assert edited.ran == ["a", "b", "c"]                     # same path, new content: re-run
    assert "a: re-running because inputs changed: a.label" in logs
    assert "b: re-running because inputs changed: upstream stage a" in logs


def test_check_reports_the_plan_run_follows(fake_stages, tmp_path):
    cfg = load_config(None, ["name=r"])
    fresh = check_run(cfg, out_root=tmp_path)
    assert fresh.reasons == {"a": "not run yet", "b": "not run yet", "c": "not run yet"}
    assert not (tmp_path / "r").exists()                     # check writes nothing
    run_pipeline(cfg, out_root=tmp_path, **QUIET)
    assert check_run(load_config(None, ["name=r"]), out_root=tmp_path).reasons == {"a": None, "b": None, "c": None}


def _interrupting_stage(fake_stages, monkeypatch, swallow: bool):
    """Stage b's run sends SIGINT to the process from inside its loop; the handler's KeyboardInterrupt
    then surfaces as CasADi's SWIG wrappers report it (a SystemError), or is swallowed."""
    inner = stage_registry.STAGES["b"].run

    def run(ctx):
        for i in range(10):
            if i == 3:
                try:
                    signal.raise_signal(signal.SIGINT)
                except KeyboardInterrupt as exc:
                    if not swallow:
                        raise SystemError("<function DM.__array__> returned a result with an exception set") from exc
        return inner(ctx)

    monkeypatch.setattr(stage_registry.STAGES["b"], "run", run)


@pytest.mark.parametrize("swallow", [False, True])
def test_interrupt_inside_a_stage_loop_exits_130_and_commits_nothing(fake_stages, tmp_path, monkeypatch, capsys,
                                                                      swallow):
    _interrupting_stage(fake_stages, monkeypatch, swallow)
    code = cli.main(["run", "--set", "name=r", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 130
    assert err[-1].startswith("interrupted:") and "Traceback" not in "\n".join(err)
    assert (tmp_path / "r" / "a" / "inputs.sha256").exists()
    assert not (tmp_path / "r" / "b").exists() and not (tmp_path / "r" / "c").exists()
    assert not [p for p in (tmp_path / "r").iterdir() if p.name.startswith(".b")]    # no staging left
    assert not interrupts.interrupted()


def test_caused_by_interrupt_follows_the_exception_chain():
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as ki:
            raise SystemError("returned a result with an exception set") from ki
    except SystemError as exc:
        assert interrupts.caused_by_interrupt(exc)
    assert not interrupts.caused_by_interrupt(ValueError("a plain error"))


def test_a_locked_first_pass_names_the_run_directory_the_user_gave(tmp_path, capsys):
    """The first calibration pass runs under ``<run>/first_pass/<name>``; a run holding that lock is
    reported against ``<run>``, the directory the user named."""
    cfg = load_config(CONFIGS_DIR / "quick.yaml", ["calibration.second_pass=always"], "calibration")
    run_dir = tmp_path / "runs" / cfg.name
    first_dir = second_pass.first_pass_root(run_dir) / cfg.name
    first_dir.mkdir(parents=True)
    with run_lock(first_dir):
        code = cli.main(["run", "--config", str(CONFIGS_DIR / "quick.yaml"), "--stages", "calibration",
                         "--set", "calibration.second_pass=always", "--out", str(tmp_path / "runs")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1].startswith(f"error: {run_dir}: process ") and "/first_pass/" not in err[-1]
