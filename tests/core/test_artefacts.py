"""Atomic files, stage directories, reuse by input hash, report.md (fake stages: fast)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.core import artefacts
from pipeline.core.config import load_config, resolve_robot_dir
from pipeline.core.errors import DataFileError, PipelineError
from pipeline.core.progress import Progress, task, track
from pipeline.run import inputs, stage_io
from pipeline.run import stages as stage_registry
from pipeline.run.runner import run_pipeline, stage_inputs_hashes
from pipeline.run.stage_io import load_run
from pipeline.run.stage_plan import plan_stages
from pipeline.stage_api import stage_rng


# ------------------------------------------------------------------------------ atomic files
def test_atomic_write_keeps_old_file_on_failure(tmp_path):
    p = tmp_path / "x.json"
    artefacts.write_json(p, {"a": 1})
    with pytest.raises(RuntimeError), artefacts.atomic_open(p, "w") as fh:
        fh.write('{"a": 2, "half')
        raise RuntimeError("crash while writing")
    assert json.loads(p.read_text()) == {"a": 1}
    assert [f.name for f in tmp_path.iterdir()] == ["x.json"]       # no temp file left


def test_json_converts_numpy_and_nonfinite(tmp_path):
    p = artefacts.write_json(tmp_path / "s.json", {"v": np.arange(3), "f": np.float64(1.5), "nan": float("nan"),
                                                   "t": (1, 2), "b": np.bool_(True)})
    assert artefacts.read_json(p) == {"v": [0, 1, 2], "f": 1.5, "nan": None, "t": [1, 2], "b": True}


def test_npz_round_trip_and_object_refused(tmp_path):
    p = artefacts.write_npz(tmp_path / "r.npz", {"a": np.eye(3), "b": [1, 2]})
    back = artefacts.read_npz(p)
    np.testing.assert_array_equal(back["a"], np.eye(3))
    np.testing.assert_array_equal(back["b"], [1, 2])
    with pytest.raises(TypeError, match="dtype object"):
        artefacts.write_npz(tmp_path / "o.npz", {"o": np.array([{}, 1], dtype=object)})


def test_commit_replaces_old_stage_dir(tmp_path):
    old = tmp_path / "s"
    old.mkdir()
    (old / "old.txt").write_text("old")
    staging = stage_io.new_stage_dir(tmp_path, "s")
    assert staging.name.startswith(".s.partial-")
    (staging / "new.txt").write_text("new")
    stage_io.commit_stage_dir(staging, old)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]
    assert [p.name for p in old.iterdir()] == ["new.txt"]


def test_inputs_hash_depends_on_every_input():
    base = dict(stage="a", stage_config={"n": 1}, run={"seed": 0}, robot_files_sha256="r",
                upstream={"x": "h"}, package_version="1")
    h0 = stage_io.inputs_hash(**base)
    assert h0 == stage_io.inputs_hash(**base)
    for key, value in [("stage", "b"), ("stage_config", {"n": 2}), ("run", {"seed": 1}),
                       ("robot_files_sha256", "r2"), ("upstream", {"x": "h2"}), ("package_version", "2")]:
        assert stage_io.inputs_hash(**{**base, key: value}) != h0, key


# ------------------------------------------------------------------------------------ runner
def test_run_writes_stage_dirs_and_report(fake_stages, tmp_path):
    result = run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=lambda m: None)
    run_dir = tmp_path / "r"
    assert result.run_dir == run_dir and result.ran == ["a", "b", "c"] and result.reused == []
    for s in "abc":
        d = run_dir / s
        names = {p.name for p in d.iterdir()}
        assert {"summary.json", "results.npz", "results.json", "plot.png", "inputs.sha256", "manifest.json",
                "report.md", "extra.txt"} <= names
        assert artefacts.read_npz(d / "results.npz")["x"].shape == (3,)
    assert [p.name for p in run_dir.iterdir() if p.name.startswith(".")] == [".lock"]   # no staging leftovers
    report = (run_dir / "report.md").read_text()
    for s in "abc":
        assert f"## {s}" in report and f"]({s}/plot.png)" in report
    assert "stage **b** says hello" in report and "| nested.gain | 1 |" in report
    assert fake_stages.contexts["c"].upstream.keys() == {"a", "b"}
    loaded = load_run(run_dir)
    assert list(loaded) == ["a", "b", "c"]
    assert loaded["b"].data["upstream"] == ["a"]


def test_failing_stage_leaves_no_directory(fake_stages, tmp_path):
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=lambda m: None)
    old_b = (tmp_path / "r" / "b" / "inputs.sha256").read_text()
    with pytest.raises(RuntimeError, match="failed halfway"):
        run_pipeline(load_config(None, ["name=r", "b.fail=true", "b.n=5"]), out_root=tmp_path, log=lambda m: None)
    run_dir = tmp_path / "r"
    assert [p.name for p in run_dir.iterdir() if p.name.startswith(".")] == [".lock"]   # staging removed
    assert (run_dir / "b" / "inputs.sha256").read_text() == old_b          # old result untouched
    # a fresh run directory: the failing stage leaves no <stage>/ at all
    with pytest.raises(RuntimeError):
        run_pipeline(load_config(None, ["name=fresh", "b.fail=true"]), out_root=tmp_path, log=lambda m: None)
    fresh = tmp_path / "fresh"
    assert (fresh / "a").is_dir()
    assert not (fresh / "b").exists() and not (fresh / "c").exists()
    assert [p.name for p in fresh.iterdir() if p.name.startswith(".")] == [".lock"]
    assert "## a" in (fresh / "report.md").read_text()                     # report of what finished


def test_reuse_when_inputs_unchanged(fake_stages, tmp_path):
    quiet = {"out_root": tmp_path, "log": lambda m: None}
    run_pipeline(load_config(None, ["name=r"]), **quiet)
    assert fake_stages.calls == ["a", "b", "c"]
    fake_stages.calls.clear()
    second = run_pipeline(load_config(None, ["name=r"]), **quiet)
    assert fake_stages.calls == [] and second.reused == ["a", "b", "c"]
    assert second.outputs["b"].summary["n"] == 3
    np.testing.assert_array_equal(second.outputs["c"].arrays["x"], np.arange(3.0))
    # a changed stage config re-runs that stage and everything downstream, not upstream
    third = run_pipeline(load_config(None, ["name=r", "b.n=4"]), **quiet)
    assert fake_stages.calls == ["b", "c"] and third.reused == ["a"]
    fake_stages.calls.clear()
    # a changed seed re-runs everything; --force re-runs although unchanged
    run_pipeline(load_config(None, ["name=r", "b.n=4", "seed=9"]), **quiet)
    assert fake_stages.calls == ["a", "b", "c"]
    fake_stages.calls.clear()
    run_pipeline(load_config(None, ["name=r", "b.n=4", "seed=9"]), force=["c"], **quiet)
    assert fake_stages.calls == ["c"]


def test_stage_selection_adds_dependencies(fake_stages, tmp_path):
    res = run_pipeline(load_config(None, ["name=r"], stages="b"), out_root=tmp_path, log=lambda m: None)
    assert res.ran == ["a", "b"] and not (tmp_path / "r" / "c").exists()


def test_rng_seeded_by_run_seed_and_stage(fake_stages, tmp_path):
    res = run_pipeline(load_config(None, ["name=r", "seed=3"]), out_root=tmp_path, log=lambda m: None)
    draws = {s: res.outputs[s].summary["draw"] for s in "abc"}
    assert len(set(draws.values())) == 3                                    # per-stage streams
    assert draws["b"] == stage_rng(3, "b").random()
    assert stage_rng(3, "b").random() != stage_rng(4, "b").random()


def test_robot_handed_on_to_later_stages(fake_stages, tmp_path, rx130l):
    fake_stages.hand_robot.add("a")
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=lambda m: None)
    assert (tmp_path / "r" / "a" / "robot").is_dir()
    ctx_b, ctx_a = fake_stages.contexts["b"], fake_stages.contexts["a"]
    np.testing.assert_allclose(ctx_a.robot.model.armature, rx130l.model.armature)      # nominal
    np.testing.assert_allclose(ctx_b.robot.model.armature, 2 * rx130l.model.armature)  # a's robot
    np.testing.assert_allclose(fake_stages.contexts["c"].robot.model.armature, 2 * rx130l.model.armature)
    # reloaded from disk on reuse
    fake_stages.calls.clear()
    again = run_pipeline(load_config(None, ["name=r", "c.n=2"]), out_root=tmp_path, log=lambda m: None)
    assert fake_stages.calls == ["c"]
    np.testing.assert_allclose(again.outputs["a"].robot.model.armature, 2 * rx130l.model.armature)
    np.testing.assert_allclose(fake_stages.contexts["c"].robot.model.armature, 2 * rx130l.model.armature)


def test_stage_check_hook_runs_before_anything_is_written(fake_stages, tmp_path):
    def check(cfg, robot):
        if cfg.label == "bad":
            raise DataFileError("measurements.csv", "q3", "not a number in row 4")

    stage_registry.STAGES["b"].check = check
    with pytest.raises(DataFileError, match="measurements.csv: q3"):
        run_pipeline(load_config(None, ["name=r", "b.label=bad"]), out_root=tmp_path, log=lambda m: None)
    assert not any(tmp_path.iterdir()) and fake_stages.calls == []


def test_progress_passes_items_through_with_or_without_display():
    for enabled in (False, True):
        with Progress(enabled=enabled) as prog:
            assert list(prog.track(iter(range(4)), "gen")) == [0, 1, 2, 3]      # no len()
            assert [i for i in track(range(3), "nested")] == [0, 1, 2]
            with task("work", total=2) as handle:
                handle.advance()
                handle.update(completed=2)
    assert list(track([5, 6], "standalone")) == [5, 6]


# ------------------------------------------------------------------ what the reuse hash covers
def _package_copy(tmp_path, monkeypatch):
    """A copy of the pipeline package's sources that the runner hashes instead of the real one."""
    copy = tmp_path / "pkg" / "pipeline"
    shutil.copytree(inputs.PACKAGE_ROOT, copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(inputs, "PACKAGE_ROOT", copy)
    return copy


def test_code_change_in_any_subpackage_reruns_every_stage(fake_stages, tmp_path, monkeypatch):
    copy = _package_copy(tmp_path, monkeypatch)
    quiet = {"out_root": tmp_path / "runs", "log": lambda m: None}
    run_pipeline(load_config(None, ["name=r"]), **quiet)
    fake_stages.calls.clear()
    assert run_pipeline(load_config(None, ["name=r"]), **quiet).reused == ["a", "b", "c"]
    edited = copy / "control" / "simulate.py"             # a module of another stage's subpackage
    edited.write_text(edited.read_text() + "\n# edited\n")
    again = run_pipeline(load_config(None, ["name=r"]), **quiet)
    assert fake_stages.calls == ["a", "b", "c"] and again.reused == []


def test_every_real_stage_hash_covers_the_whole_package(tmp_path, monkeypatch):
    copy = _package_copy(tmp_path, monkeypatch)
    cfg = load_config()
    plans = plan_stages(cfg)
    robot_dir = resolve_robot_dir(cfg)
    before = stage_inputs_hashes(cfg, plans, robot_dir)
    assert before == stage_inputs_hashes(cfg, plans, robot_dir)
    for edited in (copy / "robot" / "iso9283.py", copy / "sim" / "plant.py", copy / "trajectory" / "ptp.py",
                   copy / "cli.py"):
        edited.write_text(edited.read_text() + "\n# edited\n")
        after = stage_inputs_hashes(cfg, plans, robot_dir)
        assert set(after) == {"model", "calibration", "identification", "control", "trajectory"}
        assert all(after[s] != before[s] for s in after), edited
        before = after


def test_config_reads_enter_the_inputs_hash(fake_stages, tmp_path):
    stage_registry.STAGES["a"].CONFIG_READS = ("c.label",)
    quiet = {"out_root": tmp_path, "log": lambda m: None}
    run_pipeline(load_config(None, ["name=r"]), **quiet)
    fake_stages.calls.clear()
    run_pipeline(load_config(None, ["name=r", "c.gain=2"]), **quiet)   # not read by a: only c
    assert fake_stages.calls == ["c"]
    fake_stages.calls.clear()
    run_pipeline(load_config(None, ["name=r", "c.gain=2", "c.label=y"]), **quiet)   # read by a
    assert fake_stages.calls == ["a", "b", "c"]


def test_bad_config_reads_declaration_is_refused_before_writing(fake_stages, tmp_path):
    stage_registry.STAGES["b"].CONFIG_READS = ("nosuch.field",)
    with pytest.raises(PipelineError, match="CONFIG_READS.*nosuch.field"):
        run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=lambda m: None)
    assert not any(tmp_path.iterdir())


def test_config_yaml_lists_the_planned_stages(fake_stages, tmp_path):
    run_pipeline(load_config(None, ["name=r"]), out_root=tmp_path, log=lambda m: None)
    res = run_pipeline(load_config(None, ["name=r"], stages="b"), out_root=tmp_path, log=lambda m: None)
    assert res.reused == ["a", "b"]
    written = yaml.safe_load((tmp_path / "r" / "config.yaml").read_text())
    assert written["stages"] == ["a", "b"]          # the upstream stage a was part of the run
    assert load_config(tmp_path / "r" / "config.yaml").stages == ["a", "b"]


# ------------------------------------------------------------------------------------- docs
def test_architecture_layout_lists_exactly_the_package_files():
    repo = Path(__file__).resolve().parents[2]
    text = (repo / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    block = text.split("## Layout\n```", 1)[1].split("```", 1)[0]
    listed: dict[str, set[str]] = {}
    pkg: str | None = None
    for line in block.splitlines():
        m = re.match(r"^  (\w+)/", line)
        if m:
            pkg, rest = m.group(1), line[m.end():]
        elif re.match(r"^  \S", line):
            pkg, rest = "", line
        elif line.startswith("    ") and pkg is not None:
            rest = line
        else:
            pkg = None
            continue
        listed.setdefault(pkg, set()).update(re.findall(r"\b(\w+\.py)\b", rest))
    root = repo / "pipeline"
    actual = {"": {f.name for f in root.glob("*.py")} - {"__init__.py"}}
    for sub in root.iterdir():
        if sub.is_dir() and (sub / "__init__.py").exists():
            actual[sub.name] = {f.name for f in sub.glob("*.py")} - {"__init__.py"}
    assert listed == actual
