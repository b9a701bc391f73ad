"""Provenance of a run's inputs (recorded or simulated): the stage plan never puts a simulated stage
upstream of a recorded one, a recorded stage gets no hidden robot, the second calibration pass runs
only when calibration and identification measured the same arm, and summary.json, provenance.json
and report.md say so. Fast: the calibration and identification stages are stand-ins that record
what the runner hands them (their real Config classes, RECORDED_INPUT and SIMULATES)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from pipeline.calibration import stage as cal_stage
from pipeline.core import artefacts
from pipeline.core import config as config_mod
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.identification import stage as ident_stage
from pipeline.robot.model import RobotModel
from pipeline.run import second_pass
from pipeline.run import stages as stage_registry
from pipeline.run.headline import read_headline
from pipeline.run.runner import run_pipeline
from pipeline.run.stage_plan import plan_stages, unavailable_stages
from pipeline.stage_api import PROVENANCE_FILE, Provenance, StageResult


def _stand_in(real_module, calls: list, summary: dict):
    def run(ctx):
        calls.append(SimpleNamespace(real=ctx.real, provenance=ctx.provenance, upstream=sorted(ctx.upstream)))
        return StageResult(summary=dict(summary), robot=ctx.robot)

    return SimpleNamespace(NAME=real_module.NAME, DEPENDS=real_module.DEPENDS, Config=real_module.Config, run=run,
                           RECORDED_INPUT=real_module.RECORDED_INPUT, SIMULATES=real_module.SIMULATES,
                           __file__=real_module.__file__)


@pytest.fixture
def stand_ins(monkeypatch):
    calls = {"calibration": [], "identification": []}
    registry = {"model": stage_registry.STAGES["model"],
                "calibration": _stand_in(cal_stage, calls["calibration"], {"gravity_model_share": 0.9}),
                "identification": _stand_in(ident_stage, calls["identification"], {"validation_rms_over_noise": [1.0]}),
                "control": stage_registry.STAGES["control"], "trajectory": stage_registry.STAGES["trajectory"]}
    monkeypatch.setattr(stage_registry, "STAGES", registry)
    return calls


def _cfg(tmp_path, stages, **values):
    record = tmp_path / "record.csv"
    record.write_text("t,q1\n0,0\n")
    files = {"identification.data_file": str(record), "calibration.measurements_csv": str(record)}
    return load_config(CONFIGS_DIR / "quick.yaml", stages=stages,
                       values={k: files[k] for k, v in values.items() if v})


def test_a_recorded_identification_runs_no_calibration(tmp_path, stand_ins):
    cfg = _cfg(tmp_path, ["identification"], **{"identification.data_file": True})
    logged: list[str] = []
    result = run_pipeline(cfg, out_root=tmp_path / "runs", log=logged.append)
    run_dir = result.run_dir
    assert not stand_ins["calibration"] and not (run_dir / "calibration").exists()
    assert not (run_dir / second_pass.FIRST_PASS_FOLDER).exists()
    (call,) = stand_ins["identification"]
    assert call.real is None and call.upstream == ["model"]         # no hidden robot, nominal kinematics
    assert call.provenance.recorded and call.provenance.left_out == ("calibration",)
    saved = Provenance.from_dict(artefacts.read_json(run_dir / "identification" / "summary.json")["provenance"])
    assert saved == call.provenance
    assert any(line.startswith("identification: running (recorded (record.csv)") for line in logged)
    report = (run_dir / "report.md").read_text()
    assert "recorded (record.csv), nominal kinematics" in report
    assert "the simulated calibration is not used" in report


def test_a_recorded_calibration_never_triggers_a_simulated_identification(tmp_path, stand_ins):
    cfg = _cfg(tmp_path, ["calibration"], **{"calibration.measurements_csv": True})
    result = run_pipeline(cfg, out_root=tmp_path / "runs", log=lambda _: None)
    assert not stand_ins["identification"] and not (result.run_dir / second_pass.FIRST_PASS_FOLDER).exists()
    (call,) = stand_ins["calibration"]
    assert call.real is None and call.provenance.recorded


def test_no_second_pass_with_a_recorded_calibration_and_a_simulated_identification(tmp_path, stand_ins):
    cfg = _cfg(tmp_path, ["calibration", "identification"], **{"calibration.measurements_csv": True})
    result = run_pipeline(cfg, out_root=tmp_path / "runs", log=lambda _: None)
    assert len(stand_ins["calibration"]) == 1 and len(stand_ins["identification"]) == 1
    assert not (result.run_dir / second_pass.FIRST_PASS_FOLDER).exists()
    note = artefacts.read_json(result.run_dir / PROVENANCE_FILE)["second_pass"]
    assert note.startswith("no second calibration pass") and "simulated" in note
    (row,) = [r for r in read_headline(result.run_dir, list(result.outputs)).rows
              if r.figure == "second calibration pass"]
    assert row.value == "not run" and row.against == note
    assert note in (result.run_dir / "report.md").read_text()
    # the simulated identification uses the recorded calibration's robot, and has its hidden robot
    (ident,) = stand_ins["identification"]
    assert ident.real is not None and "calibration" in ident.upstream and ident.provenance.simulated


@pytest.mark.parametrize(("calibration", "identification", "first_pass"),
                         [(False, False, True), (True, True, True), (True, False, False), (False, True, False)])
def test_second_pass_only_when_both_stages_measured_the_same_arm(tmp_path, stand_ins, calibration, identification,
                                                                first_pass):
    cfg = _cfg(tmp_path, ["calibration", "identification"], **{"calibration.measurements_csv": calibration,
                                                                "identification.data_file": identification})
    stages = config_mod.stage_names()
    wanted, why_not = second_pass.decision(cfg, ["model", "calibration", "identification"], stages)
    assert wanted == first_pass and bool(why_not) != first_pass


def test_both_recorded_the_identification_starts_from_the_recorded_calibration(tmp_path, stand_ins):
    cfg = _cfg(tmp_path, ["identification"], **{"calibration.measurements_csv": True,
                                                "identification.data_file": True})
    robot = RobotModel.load("rx130l")
    plans = {p.name: p for p in plan_stages(cfg, unavailable_stages(robot))}
    assert plans["identification"].closure == ["model", "calibration"]
    assert plans["identification"].provenance.left_out == ()
    assert plans["calibration"].provenance.recorded


def test_a_fully_simulated_run_keeps_its_second_pass(tmp_path, stand_ins):
    cfg = _cfg(tmp_path, ["calibration", "identification"])
    result = run_pipeline(cfg, out_root=tmp_path / "runs", log=lambda _: None)
    assert (result.run_dir / second_pass.FIRST_PASS_FOLDER).is_dir()
    assert len(stand_ins["calibration"]) == 2                       # first and second pass
    assert all(c.provenance.simulated and c.real is not None for c in stand_ins["calibration"])
    note = artefacts.read_json(result.run_dir / PROVENANCE_FILE)["second_pass"]
    assert note.startswith("second calibration pass")
