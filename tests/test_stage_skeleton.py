"""Every stage package has the same skeleton (docs/ARCHITECTURE.md "Stage skeleton"), and its
stage.py only sequences named steps: short functions, no long run function. Reads the source
(ast), runs nothing."""

from __future__ import annotations

import ast
import dataclasses
import importlib
from pathlib import Path

import pytest

from pipeline.run.stage_plan import check_stage_module
from pipeline.stage_api import StageModule

PACKAGE = Path(__file__).resolve().parents[1] / "pipeline"
STAGES = ("calibration", "identification", "control", "trajectory")
#: every stage package holds these modules, and one of estimate.py / solve.py
SKELETON = ("config.py", "design.py", "measure.py", "validate.py", "report.py", "stage.py")
#: longest function of a stage.py (lines of its definition, docstring included)
MAX_STEP_LINES = 40


def _functions(stage: str) -> dict[str, int]:
    """Top-level functions of ``pipeline/<stage>/stage.py`` and their length in lines."""
    tree = ast.parse((PACKAGE / stage / "stage.py").read_text(encoding="utf-8"))
    return {node.name: node.end_lineno - node.lineno + 1 for node in tree.body
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.end_lineno is not None}


@pytest.mark.parametrize("stage", STAGES)
def test_stage_package_has_the_skeleton_modules(stage):
    files = {f.name for f in (PACKAGE / stage).glob("*.py")}
    missing = [name for name in SKELETON if name not in files]
    assert not missing, f"pipeline/{stage}/ lacks {missing}"
    assert {"estimate.py", "solve.py"} & files, f"pipeline/{stage}/ has neither estimate.py nor solve.py"


@pytest.mark.parametrize("stage", STAGES)
def test_stage_module_names_its_config_class_config(stage):
    """``Config`` of the stage module (StageModule) is the one dataclass of its config.py, which
    holds it under one name only."""
    module = importlib.import_module(f"pipeline.{stage}.stage")
    config = importlib.import_module(f"pipeline.{stage}.config")
    assert dataclasses.is_dataclass(module.Config) and module.Config.__module__ == config.__name__
    names = [name for name, value in vars(config).items() if value is module.Config]
    assert len(names) == 1, f"pipeline/{stage}/config.py names its section's dataclass {names}"
    assert callable(module.run) and module.NAME == stage


@pytest.mark.parametrize("stage", ("model", *STAGES))
def test_stage_module_defines_every_name_of_the_contract(stage):
    """Every name of :class:`pipeline.stage_api.StageModule` is defined by each stage module, with its type."""
    module = importlib.import_module(f"pipeline.{stage}.stage")
    contract = [name for name in vars(StageModule) if not name.startswith("_")]
    assert {"NAME", "DEPENDS", "Config", "run", "check", "warm_up", "CONFIG_READS", "RECORDED_INPUT",
            "SIMULATES"} <= set(contract)
    missing = [name for name in contract if not hasattr(module, name)]
    assert not missing, f"pipeline/{stage}/stage.py does not define {missing}"
    check_stage_module(stage, module)


@pytest.mark.parametrize("stage", STAGES)
def test_stage_py_is_a_sequence_of_short_steps(stage):
    lengths = _functions(stage)
    assert "run" in lengths
    too_long = {name: n for name, n in lengths.items() if n > MAX_STEP_LINES}
    assert not too_long, (f"pipeline/{stage}/stage.py: {too_long} longer than {MAX_STEP_LINES} lines; "
                          "split into named steps, move the work to design/measure/estimate/validate/report")

