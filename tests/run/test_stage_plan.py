"""The stage plan: which stages a selection pulls in, and what a stage module must declare."""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace
from typing import Annotated

import pytest

from pipeline.core.config import CONFIGS_DIR, load_config, resolve_robot_dir
from pipeline.core.errors import PipelineError
from pipeline.core.typed_config import FileInput
from pipeline.run import stages as stage_registry
from pipeline.run.inputs import stage_inputs_hashes
from pipeline.run.stage_plan import check_stage_module, plan_stages, unavailable_stages


def _plans(rx130l, *settings: str, stages: str = "trajectory"):
    cfg = load_config(CONFIGS_DIR / "quick.yaml", list(settings), stages=stages)
    return cfg, plan_stages(cfg, unavailable_stages(rx130l))


def test_trajectory_alone_plans_no_control_stage(rx130l):
    """The trajectory stage reads the run's control section (its servo design), not the control stage."""
    _, plans = _plans(rx130l)
    assert [p.name for p in plans] == ["model", "calibration", "identification", "trajectory"]
    (trajectory,) = [p for p in plans if p.name == "trajectory"]
    assert "control" not in trajectory.closure


def test_control_settings_enter_the_trajectory_hash_only_where_read(rx130l):
    cfg, plans = _plans(rx130l)
    before = stage_inputs_hashes(cfg, plans, resolve_robot_dir(cfg))
    cfg2, plans2 = _plans(rx130l, "control.velocity_bandwidth_hz=31")
    after = stage_inputs_hashes(cfg2, plans2, resolve_robot_dir(cfg2))
    assert after["trajectory"] != before["trajectory"]           # the servo design it simulates in
    assert {s: after[s] for s in after if s != "trajectory"} == {s: before[s] for s in before if s != "trajectory"}


@dataclass
class _Recorded:
    records_csv: Annotated[str | None, FileInput] = None
    label: str = ""


def _stage(**names: object) -> SimpleNamespace:
    return SimpleNamespace(NAME="r", DEPENDS=(), Config=_Recorded, run=lambda ctx: None, __file__=None, **names)


def test_recorded_input_must_name_a_file_input_field():
    check_stage_module("r", _stage(RECORDED_INPUT="records_csv"))
    with pytest.raises(PipelineError, match="RECORDED_INPUT.*'records_csv_renamed' is not a field"):
        check_stage_module("r", _stage(RECORDED_INPUT="records_csv_renamed"))
    with pytest.raises(PipelineError, match="RECORDED_INPUT.*'label' is not a field"):   # not a FileInput
        check_stage_module("r", _stage(RECORDED_INPUT="label"))


def test_every_registered_stage_keeps_its_contract():
    for name in stage_registry.stage_names():
        check_stage_module(name, stage_registry.load_stage_module(name))
