"""Every summary key another module reads has one definition: a field of a summary record
(:mod:`pipeline.summaries`). The run layer reads no key by hand, and each key a record names is
written by its stage (a key renamed on either side fails here, not as a silent empty headline row).
Reads the source (ast), runs nothing."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from pipeline import summaries
from pipeline.summaries import CrossValidationSummary, StageSummary, TrajectorySummary

PACKAGE = Path(summaries.__file__).resolve().parent
#: where each record's keys are written
WRITERS = {
    "model": ("model", "robot"),               # RobotModel.summary and the model stage
    "calibration": ("calibration",),
    "identification": ("identification",),
    "control": ("control",),
    "trajectory": ("trajectory",),
}
#: the entries every stage has: the quality gates (quality.py), the runner's provenance, the stages' warnings
COMMON_WRITERS = ("quality.py", "run/stage_run.py", "calibration", "identification", "control", "trajectory")


def _all_keys() -> set[str]:
    return {k for r in (StageSummary, CrossValidationSummary, *summaries.RECORDS.values()) for k in r.keys()}


def _string_constants(paths) -> set[str]:
    out: set[str] = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                out.add(node.value)
    return out


def _sources(*parts: str) -> list[Path]:
    out: list[Path] = []
    for part in parts:
        target = PACKAGE / part
        out += [target] if target.suffix == ".py" else sorted(target.rglob("*.py"))
    return out


def _reads_by_hand(path: Path, keys: set[str]) -> list[str]:
    """``x.get("key")`` and ``x["key"]`` (not a store) of a record's key in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        key = None
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
                and node.args and isinstance(node.args[0], ast.Constant)):
            key = node.args[0].value
        elif (isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load)
              and isinstance(node.slice, ast.Constant)):
            key = node.slice.value
        if isinstance(key, str) and key in keys:
            found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {key!r}")
    return found


def test_the_run_layer_reads_summary_keys_only_through_the_records():
    keys = _all_keys()
    hand = [hit for path in _sources("run") for hit in _reads_by_hand(path, keys)]
    assert not hand, "summary keys read by hand (read them through pipeline.summaries):\n" + "\n".join(hand)


@pytest.mark.parametrize("stage", list(summaries.RECORDS))
def test_every_key_a_record_reads_is_written_by_its_stage(stage):
    record = summaries.RECORDS[stage]
    written = _string_constants(_sources(*WRITERS[stage]))
    composed = set(getattr(record, "COMPOSED", ()))
    missing = [k for k in record.keys() if k not in written and k not in composed]
    assert not missing, f"{record.__name__} reads keys that pipeline/{stage} does not write: {missing}"
    if stage == "calibration":
        assert not [k for k in CrossValidationSummary.keys() if k not in written]


def test_composed_trajectory_keys_are_named_by_their_record():
    """The move-and-settle keys the trajectory stage composes from a plan name and a figure."""
    assert set(TrajectorySummary.COMPOSED) <= set(TrajectorySummary.keys())
    for plan in ("ptp", "ptp_smooth", "ptp_ruckig"):
        for elastic in (False, True):
            assert TrajectorySummary().move_and_settle_s(plan, elastic) is None
    written = _string_constants(_sources("trajectory/settling.py"))
    assert "move_and_settle_s" in written          # the figure the composed keys end with


def test_the_entries_every_stage_has_are_written():
    written = _string_constants(_sources(*COMMON_WRITERS))
    assert set(StageSummary.keys()) <= written


def test_a_record_reads_leniently():
    record = summaries.CalibrationSummary.read({"heldout_rms_position_error_after_m": float("nan"),
                                                "predicted_rms_position_error_m": "x",
                                                "cross_validation": {"folds": 5, "rms_position_error_m": 1e-4}})
    assert record.heldout_rms_position_error_after_m is None and record.predicted_rms_position_error_m is None
    assert record.cross_validation == CrossValidationSummary(folds=5, rms_position_error_m=1e-4)
    gates = StageSummary.read({"quality_gates": {"passed": False, "checks": [
        {"name": "g", "passed": False, "value": 2.0, "op": "<=", "threshold": 1.0, "message": "g = 2"}, "junk"]}})
    (check,) = gates.gate_checks()
    assert gates.gate("g") == check and check.threshold == 1.0 and gates.gate("other") is None
