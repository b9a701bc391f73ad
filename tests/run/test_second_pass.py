"""The runner's second calibration pass (pipeline.run.second_pass): when it runs, what it hands on."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from pipeline.calibration.config import Config as CalibrationConfig
from pipeline.core.config import RunConfig
from pipeline.core.errors import ConfigError
from pipeline.run import second_pass, stage_io
from pipeline.stage_api import StageOutput


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
