"""The runner's second calibration pass (pipeline.run.second_pass): when it runs, what it hands on,
and (slow) one command running both passes, and a copied run with its second pass reused elsewhere.
The calibration with a given gravity model: tests/calibration/test_second_pass.py."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from pipeline.calibration.config import Config as CalibrationConfig
from pipeline.core.config import CONFIGS_DIR, RunConfig, load_config
from pipeline.core.errors import ConfigError
from pipeline.run import second_pass, stage_io
from pipeline.run.run_check import check_run
from pipeline.run.runner import run_pipeline
from pipeline.run.second_pass import GRAVITY_SHARE_FOR_SECOND_PASS
from pipeline.stage_api import StageOutput

#: 3 sigma of the tracker plus the unmodelled remainder (tests/calibration/test_second_pass.py)
HELDOUT_OVER_SIGMA_MAX = 3.5


def _output(path: Path, summary: dict, inputs_hash: str = "abc") -> StageOutput:
    (path / "robot").mkdir(parents=True, exist_ok=True)
    (path / "robot" / "robot.yaml").write_text(f"name: x\nhash: {inputs_hash}\n")
    (path / stage_io.INPUTS_HASH).write_text(inputs_hash)
    return StageOutput(summary, {}, {}, None, path)


def _cfg(mode: str = "auto", gravity_model: str | None = None) -> RunConfig:
    return RunConfig(sections={"calibration": CalibrationConfig(second_pass=mode, gravity_model=gravity_model)})


def test_wanted_needs_calibration_an_identification_stage_a_mode_and_no_user_gravity_model():
    stages = ["model", "calibration", "identification", "control"]
    assert second_pass.wanted(_cfg(), stages, stages)
    assert second_pass.wanted(_cfg(), ["model", "calibration"], stages)      # --stages calibration too
    assert not second_pass.wanted(_cfg(), ["model", "identification"], stages)  # no calibration (no tracker)
    assert not second_pass.wanted(_cfg(), stages[:2], stages[:2])            # no identification stage
    assert not second_pass.wanted(_cfg("never"), stages, stages)
    assert not second_pass.wanted(_cfg(gravity_model="some/robot"), stages, stages)
    assert not second_pass.wanted(RunConfig(sections={"calibration": {}}), stages, stages)   # a plain section
    assert second_pass.first_pass_config(_cfg()).stages == ["identification"]


@pytest.mark.parametrize(("mode", "share", "second"), [("auto", 0.7, True), ("auto", 0.2, False),
                                                       ("auto", None, False), ("always", 0.1, True)])
def test_second_pass_config_follows_the_gravity_share(tmp_path, mode, share, second):
    run_dir = tmp_path / "run"
    outputs = {"calibration": _output(tmp_path / "c", {"gravity_model_share": share}),
               "identification": _output(tmp_path / "i", {})}
    cfg = second_pass.second_pass_config(_cfg(mode), outputs, run_dir)
    assert (cfg is not None) == second
    if second:
        gm = Path(cfg.sections["calibration"].gravity_model)
        assert gm.is_dir() and gm.parent == (tmp_path / ".gravity_models").resolve()
        assert (gm / "robot.yaml").read_text() == (tmp_path / "i" / "robot" / "robot.yaml").read_text()
        # a changed first pass gives another folder (its inputs change, nothing stale is reused)
        outputs["identification"] = _output(tmp_path / "i2", {}, inputs_hash="def")
        assert second_pass.second_pass_config(_cfg(mode), outputs, run_dir).sections["calibration"].gravity_model \
            != str(gm)


def test_reuse_copies_the_first_pass_and_replaces_only_other_inputs(tmp_path):
    run_dir = tmp_path / "run"
    outputs = {"calibration": _output(tmp_path / "c", {}, "h1")}
    assert second_pass.reuse_first_pass(outputs, run_dir) == ["calibration"]
    assert stage_io.read_inputs_hash(run_dir / "calibration") == "h1"
    marker = run_dir / "calibration" / "kept"
    marker.write_text("same inputs: left alone")
    assert second_pass.reuse_first_pass(outputs, run_dir) == []
    assert marker.exists()
    outputs = {"calibration": _output(tmp_path / "c2", {}, "h2")}
    second_pass.reuse_first_pass(outputs, run_dir)
    assert stage_io.read_inputs_hash(run_dir / "calibration") == "h2" and not marker.exists()
    assert sorted(p.name for p in run_dir.iterdir()) == ["calibration"]


def test_bad_mode_names_the_field():
    with pytest.raises(ConfigError, match="second_pass"):
        replace(CalibrationConfig(), second_pass="twice").validate()


@pytest.mark.slow
def test_the_runner_runs_the_second_pass_when_the_gravity_model_dominates(tmp_path, rx130l_generic_stiffness_dir):
    """One command (quick profile, the RX130L with the generic joint stiffness, whose own weight
    dominates the first pass's predicted error): the first pass under ``first_pass/``, this run
    calibrated with its identified robot, and a repeated command reuses every stage of both."""
    logs: list[str] = []
    cfg = load_config(CONFIGS_DIR / "quick.yaml", ["name=one", f"robot={rx130l_generic_stiffness_dir}"])
    run_pipeline(cfg, out_root=tmp_path, log=logs.append)
    first = json.loads((tmp_path / "one" / "first_pass" / "one" / "calibration" / "summary.json").read_text())
    second = json.loads((tmp_path / "one" / "calibration" / "summary.json").read_text())
    assert first["gravity_model_share"] >= GRAVITY_SHARE_FOR_SECOND_PASS > second["gravity_model_share"]
    assert second["rms_after_over_sigma"] <= HELDOUT_OVER_SIGMA_MAX < first["rms_after_over_sigma"]
    assert f"{tmp_path}/.gravity_models/" in second["gravity_pass"]["gravity_model"]
    again = run_pipeline(cfg, out_root=tmp_path, log=lambda m: None)
    assert again.ran == [] and set(again.reused) == set(again.outputs)


@pytest.mark.slow
def test_a_copied_run_with_its_second_pass_is_reused_elsewhere(tmp_path):
    """The second pass's gravity model enters calibration's inputs by content: a run copied to
    another runs folder is reused there, stage by stage, and ``check`` says so beforehand."""
    small = ["name=q", "calibration.n_random_candidates=400", "calibration.n_configurations=24",
             "calibration.n_heldout=100", "calibration.second_pass=always"]
    cfg = load_config(CONFIGS_DIR / "quick.yaml", small, "calibration")
    run_pipeline(cfg, out_root=tmp_path / "a", log=lambda m: None)
    shutil.copytree(tmp_path / "a" / "q", tmp_path / "b" / "q")
    manifests = {p.relative_to(tmp_path / "b"): p.read_bytes() for p in (tmp_path / "b").rglob("manifest.json")}
    cfg = load_config(CONFIGS_DIR / "quick.yaml", small, "calibration")
    assert set(check_run(cfg, out_root=tmp_path / "b").reasons.values()) == {None}
    again = run_pipeline(cfg, out_root=tmp_path / "b", log=lambda m: None)
    assert again.ran == [] and set(again.reused) == {"model", "calibration"}
    assert {p.relative_to(tmp_path / "b"): p.read_bytes() for p in (tmp_path / "b").rglob("manifest.json")} == manifests
