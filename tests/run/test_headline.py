"""The headline: every stage's key figure against its gate or anchor, on the console and atop report.md."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest
from rich.console import Console

from pipeline import cli
from pipeline.run import headline as hl
from pipeline.run import headline_rows as hr
from pipeline.run import stages as stage_registry
from pipeline.run.report import write_report
from pipeline.stage_api import Provenance, StageResult

GATES_PASS = {"passed": True, "checks": [
    {"name": "validation_rms_over_noise", "passed": True, "value": 1.03, "op": "<=", "threshold": 2.0},
    {"name": "cond_data_over_design", "passed": True, "value": 1.0, "op": "<=", "threshold": 2.0}]}
SUMMARIES = {
    "model": {"name": "arm", "dof": 6, "reach_m": 1.6, "moving_mass_kg": 12.0, "payload_kg": 16.0,
              "assumptions": ["payload 0 kg assumed"], "plausibility_warnings": ["moving mass 12 kg is light"]},
    "calibration": {"heldout_rms_position_error_after_m": 26e-6, "heldout_rms_position_error_before_m": 2e-3,
                    "tracker_noise_sigma_m": 13e-6, "predicted_rms_position_error_m": 52e-6,
                    "validation_source": "simulated tracker (held-out)",
                    "quality_gates": {"passed": True, "checks": [{"name": "chi2_per_dof", "passed": True}]}},
    "identification": {"validation_rms_over_noise": [1.0, 3.5, 1.2], "data_source": "/data/my_arm_record.csv",
                       "quality_gates": {"passed": False, "checks": [
                           {"name": "validation_rms_over_noise", "passed": False, "value": 3.5, "op": "<=",
                            "threshold": 2.0}]}, "accepted_poor": True},
    "control": {"tcp_error_max_m": {"none": 2.4e-3, "full_friction": 2.3e-3, "elastic_flat": 75e-6,
                                    "full_friction_nominal": 1e-9}},
    "trajectory": {"cp_duration_s": 0.54, "cp_toppra_duration_s": 0.50, "cp_segment": "line",
                   "ptp_duration_s": 0.8, "ptp_ruckig_duration_s": 1.0, "ptp_energy_at_ruckig_duration": 0.6,
                   "ptp_ruckig_energy": 0.9, "ptp_energy_measure": "normalised",
                   "ptp_move_and_settle_s": 1.3, "ptp_smooth_move_and_settle_s": 1.1,
                   "ptp_ruckig_move_and_settle_s": 1.5, "quality_gates": GATES_PASS},
}


def _write_run(tmp_path, summaries=SUMMARIES):
    run = tmp_path / "arm-quick"
    for stage, summary in summaries.items():
        (run / stage).mkdir(parents=True)
        (run / stage / "summary.json").write_text(json.dumps(summary))
        (run / stage / "inputs.sha256").write_text("0" * 64)
    return run


def _rows(headline, stage, figure_start):
    return [r for r in headline.rows if r.stage == stage and r.figure.startswith(figure_start)]


def test_each_stage_figure_stands_against_its_anchor_with_a_verdict(tmp_path):
    run = _write_run(tmp_path)
    headline = hl.read_headline(run, list(SUMMARIES))
    (noise,) = _rows(headline, "calibration", "held-out TCP error RMS / noise")
    # no anchor to judge the noise ratio by: the ratio alone, no verdict
    assert noise.ratio == hr.ratio(26e-6 / 13e-6) and noise.verdict == "" and noise.source == "simulated"
    (predicted,) = _rows(headline, "calibration", "held-out TCP error RMS, actual / predicted")
    assert predicted.ratio == hr.ratio(0.5) and predicted.verdict == "" and "52.0 µm" in predicted.against
    (ident,) = _rows(headline, "identification", "validation torque RMS")
    assert ident.verdict == hr.FAIL and "joint 2" in ident.value and "≤ 2" in ident.against
    assert ident.ratio == hr.ratio(3.5)
    assert ident.source == "recorded (my_arm_record.csv)"
    (gates,) = _rows(headline, "identification", "quality gates")
    assert gates.verdict == hr.FAIL and "failed: validation_rms_over_noise" in gates.value
    assert "--accept-poor" in gates.value
    (ff,) = _rows(headline, "control", "feedforward gain")
    # the best variant the stage ran (the nominal-model comparison is no variant of the run)
    assert "elastic_flat" in ff.value and ff.ratio == hr.ratio(2.4e-3 / 75e-6) and ff.verdict == hr.PASS
    # simulated on a model identified from the user's record: the row says so
    assert "recorded (my_arm_record.csv)" in ff.source
    ratios = {r.figure.split(" (")[0]: r.ratio for r in headline.rows if r.stage == "trajectory"}
    verdicts = {r.figure.split(" (")[0]: r.verdict for r in headline.rows if r.stage == "trajectory"}
    assert ratios["CP duration"] == hr.ratio(0.54 / 0.50) and verdicts["CP duration"] == hr.WARN   # slower
    assert ratios["PtP duration"] == hr.ratio(0.8) and verdicts["PtP duration"] == hr.PASS
    assert ratios["PtP energy at ruckig's duration"] == hr.ratio(0.6 / 0.9)
    assert ratios["PtP move + settle"] == hr.ratio(1.1 / 1.5)     # the better of the two plans
    assert verdicts["quality gates"] == hr.PASS
    assert {r.verdict for r in headline.rows} <= {hr.PASS, hr.WARN, hr.FAIL, ""}
    assert headline.assumptions == ["payload 0 kg assumed"] and headline.warnings == ["moving mass 12 kg is light"]
    assert headline.failed
    (model,) = _rows(headline, "model", "robot")
    assert model.verdict == hr.WARN and "1 warning(s)" in model.against


def test_an_executed_remedy_of_the_cp_is_the_duration_judged(tmp_path):
    """A slowed CP executed (its time-optimal plan over the servo gate): both durations shown, the
    executed one against toppra's; the time-optimal plan executed: the plain row."""
    slowed = {**SUMMARIES["trajectory"], "cp_duration_s": 0.48, "cp_executed": "slowed",
              "cp_executed_duration_s": 0.53}
    headline = hl.read_headline(_write_run(tmp_path, {"trajectory": slowed}), ["trajectory"])
    (row,) = _rows(headline, "trajectory", "CP duration")
    assert row.value == "time-optimal 0.480 s, executed (slowed) 0.530 s" and row.against == "toppra 0.500 s"
    assert row.ratio == hr.ratio(0.53 / 0.50) and row.verdict == hr.WARN
    as_planned = {**slowed, "cp_executed": "time_optimal", "cp_executed_duration_s": 0.48}
    headline = hl.read_headline(_write_run(tmp_path / "b", {"trajectory": as_planned}), ["trajectory"])
    (row,) = _rows(headline, "trajectory", "CP duration")
    assert row.value == "0.480 s" and row.ratio == hr.ratio(0.48 / 0.50) and row.verdict == hr.PASS


def test_a_cp_that_is_toppras_profile_judges_our_solver_against_it(tmp_path):
    """toppra's profile handed on: the row judges our solver's duration, which is longer (a warning)."""
    peer = {**SUMMARIES["trajectory"], "cp_duration_s": 0.50, "cp_toppra_duration_s": 0.50,
            "cp_source": "toppra", "cp_ours_duration_s": 0.5023}
    headline = hl.read_headline(_write_run(tmp_path, {"trajectory": peer}), ["trajectory"])
    (row,) = _rows(headline, "trajectory", "CP duration")
    assert row.figure == "CP duration (line path), our solver" and row.value.startswith("0.502 s (toppra's 0.500 s")
    assert row.ratio == hr.ratio(0.5023 / 0.50) and row.verdict == hr.WARN
    refined = {**peer, "cp_toppra_within_limits": False, "cp_toppra_feasible_duration_s": 0.503,
               "cp_duration_s": 0.503, "cp_n_grid": 150, "cp_toppra_feasible_n_grid": 1200}
    headline = hl.read_headline(_write_run(tmp_path / "b", {"trajectory": refined}), ["trajectory"])
    (row,) = _rows(headline, "trajectory", "CP duration")
    assert row.against == "toppra on 1200 intervals 0.503 s (as planned 0.500 s, over a limit)"
    assert row.ratio == hr.ratio(0.5023 / 0.503) and row.verdict == hr.PASS


def test_missing_stages_and_figures_leave_rows_out(tmp_path):
    run = _write_run(tmp_path, {"model": {"name": "x"}, "control": {"tcp_error_max_m": {"none": 1e-3}}})
    headline = hl.read_headline(run, ["model", "calibration", "control"])
    assert headline.rows == [] and not headline.failed
    assert "_no finished stage yet_" in hl.headline_markdown(headline)


def test_stale_stages_are_marked(tmp_path):
    run = _write_run(tmp_path)
    rows = hl.read_headline(run, list(SUMMARIES), stale=["control"]).rows
    assert all(("stale" in r.source) == (r.stage == "control") for r in rows)


def test_report_opens_with_the_headline_then_assumptions_and_warnings(tmp_path):
    run = _write_run(tmp_path)
    text = write_report(run).read_text()
    first_stage = text.index("\n## model")
    head = text[:first_stage]
    assert text.startswith("# Run `arm-quick`") and "## Headline" in head
    assert head.index("## Headline") < head.index("**Assumptions still in force**") < head.index("**Warnings**")
    assert "* payload 0 kg assumed" in head and "* moving mass 12 kg is light" in head
    assert "| calibration | held-out TCP error RMS / noise |" in head


def test_console_table_shows_every_row_and_the_warnings(tmp_path):
    headline = hl.read_headline(_write_run(tmp_path), list(SUMMARIES))
    console = Console(record=True, width=400, color_system=None)
    hl.print_headline(headline, console)
    text = console.export_text()
    assert all(r.figure in text and r.verdict in text for r in headline.rows)
    assert "warning: moving mass 12 kg is light" in text and "payload 0 kg assumed" in text


@pytest.fixture
def model_like_stage(monkeypatch, fake_stages):
    """The fake registry plus a stage "model" whose summary carries a warning and an assumption."""
    def run(ctx):
        return StageResult(summary=dict(SUMMARIES["model"]))

    stage = SimpleNamespace(NAME="model", DEPENDS=(), Config=type(fake_stages.make("x").Config()), run=run,
                            __file__=None)
    monkeypatch.setattr(stage_registry, "STAGES", {"model": stage, **stage_registry.STAGES})
    return stage


def test_run_prints_the_headline_before_the_report_path(model_like_stage, tmp_path, capsys):
    assert cli.main(["run", "--out", str(tmp_path), "--set", "name=r"]) == 0
    out = capsys.readouterr().out
    report = tmp_path / "r" / "report.md"
    assert out.rstrip().splitlines()[-1] == str(report)
    assert "Run r: headline" in out and "robot arm" in out and "warning: moving mass 12 kg is light" in out
    assert "## Headline" in report.read_text().split("\n## model")[0]


def test_recorded_calibration_stands_on_its_cross_validation(tmp_path):
    summary = {"cross_validation": {"folds": 5, "rms_position_error_m": 40e-6}, "tracker_noise_sigma_m": 20e-6,
               "measurement_source": "/data/tracker_readings.csv", "heldout_rms_position_error_after_m": None}
    (row,) = hr.stage_rows("calibration", summary)
    assert row.figure.startswith("5-fold cross-validated") and row.ratio == hr.ratio(2.0)
    assert row.source == "recorded (tracker_readings.csv)"


def test_calibration_row_judges_against_the_total_noise_not_the_sensor_alone():
    summary = {"heldout_rms_position_error_after_m": 60e-6, "tracker_noise_sigma_m": 10e-6,
               "noise_total_sigma_m": 30e-6, "validation_source": "simulated tracker (held-out)"}
    (row, *_) = hr.stage_rows("calibration", summary)
    assert row.ratio == hr.ratio(2.0)


def test_cross_validated_error_is_compared_with_the_cross_validated_prediction():
    summary = {"cross_validation": {"folds": 5, "rms_position_error_m": 3e-3, "predicted_rms_position_error_m": 3e-3},
               "predicted_rms_position_error_m": 40e-3, "measurement_source": "/data/mocap.csv",
               "heldout_rms_position_error_after_m": None}
    (row,) = [r for r in hr.stage_rows("calibration", summary) if "actual / predicted" in r.figure]
    assert row.ratio == hr.ratio(1.0)


def test_actual_over_predicted_takes_its_gate_and_warns_when_pessimistic():
    def row(ratio_: float):
        check = {"name": "actual_over_predicted", "passed": ratio_ <= 2.0, "value": ratio_, "op": "<=",
                 "threshold": 2.0}
        summary = {"heldout_rms_position_error_after_m": ratio_ * 10e-6, "predicted_rms_position_error_m": 10e-6,
                   "quality_gates": {"passed": check["passed"], "checks": [check]}}
        (out,) = [r for r in hr.stage_rows("calibration", summary) if "actual / predicted" in r.figure]
        return out.verdict

    assert (row(1.2), row(0.3), row(2.5)) == (hr.PASS, hr.WARN, hr.FAIL)


def test_the_pessimistic_warning_takes_the_held_out_tests_lower_bound():
    """Few held-out poses: the test's lower bound (the spread of an RMS over them) replaces 1 / gate."""
    def verdict(ratio_: float, lower: float | None) -> str:
        check = {"name": "actual_over_predicted", "passed": True, "value": ratio_, "op": "<=", "threshold": 2.4}
        test = None if lower is None else {"threshold": 2.4, "lower_threshold": lower}
        summary = {"heldout_rms_position_error_after_m": ratio_ * 10e-6, "predicted_rms_position_error_m": 10e-6,
                   "actual_over_predicted": ratio_, "actual_over_predicted_test": test,
                   "quality_gates": {"passed": True, "checks": [check]}}
        (out,) = [r for r in hr.stage_rows("calibration", summary) if "actual / predicted" in r.figure]
        return out.verdict

    assert verdict(0.35, None) == hr.WARN            # below 1 / 2.4
    assert verdict(0.35, 0.316) == hr.PASS           # within the test's spread
    assert verdict(0.30, 0.316) == hr.WARN


def test_a_ratio_a_verdict_turns_on_shows_the_digit_it_turns_on():
    assert hr.ratio(1.0045) == "×1.004" and hr.ratio(0.9952) == "×0.9952"
    assert hr.ratio(32.31) == "×32.3" and hr.ratio(0.888) == "×0.888"


def test_a_toppra_profile_over_a_limit_is_judged_as_made_to_keep_its_limits(tmp_path):
    over = {**SUMMARIES["trajectory"], "cp_duration_s": 0.538, "cp_toppra_duration_s": 0.535,
            "cp_toppra_within_limits": False, "cp_toppra_feasible_duration_s": 0.542, "cp_n_grid": 150,
            "cp_toppra_feasible_n_grid": 1200, "cp_toppra_feasible_time_scale": 1.0127}
    headline = hl.read_headline(_write_run(tmp_path, {"trajectory": over}), ["trajectory"])
    (row,) = _rows(headline, "trajectory", "CP duration")
    assert row.against == "toppra on 1200 intervals, slowed ×1.013 0.542 s (as planned 0.535 s, over a limit)"
    assert row.ratio == hr.ratio(0.538 / 0.542) and row.verdict == hr.PASS
    never = {**over, "cp_toppra_feasible_duration_s": None}
    headline = hl.read_headline(_write_run(tmp_path / "b", {"trajectory": never}), ["trajectory"])
    (row,) = _rows(headline, "trajectory", "CP duration")
    assert "over a limit on the fine grid at any speed" in row.against and row.verdict == ""


def test_a_stage_simulated_on_a_recorded_model_says_its_arm_is_robot_yamls(tmp_path):
    recorded = Provenance("recorded", "/data/my_arm_record.csv").to_dict()
    simulated = Provenance("simulated", "servo loop on the hidden robot", ("identification",)).to_dict()
    summaries = {**SUMMARIES, "identification": {**SUMMARIES["identification"], "provenance": recorded},
                 "control": {**SUMMARIES["control"], "provenance": simulated}}
    headline = hl.read_headline(_write_run(tmp_path, summaries), list(summaries))
    (line,) = [x for x in headline.inputs if "robot.yaml arm" in x]
    assert line.startswith("control:") and "recorded (my_arm_record.csv)" in line
    summaries["identification"] = {**summaries["identification"], "provenance": Provenance(
        "simulated", "joint torques of the hidden robot").to_dict()}
    headline = hl.read_headline(_write_run(tmp_path / "sim", summaries), list(summaries))
    assert not [x for x in headline.inputs if "robot.yaml arm" in x]   # the model and the arm are the run's
