"""Every stage package has the same skeleton (docs/ARCHITECTURE.md "Stage skeleton"), and its
stage.py only sequences named steps: short functions, no long run function. Reads the source
(ast), runs nothing."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

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
    module = importlib.import_module(f"pipeline.{stage}.stage")
    config = importlib.import_module(f"pipeline.{stage}.config")
    assert isinstance(config.Config, type) and module.Config is config.Config
    assert callable(module.run) and module.NAME == stage


@pytest.mark.parametrize("stage", STAGES)
def test_stage_py_is_a_sequence_of_short_steps(stage):
    lengths = _functions(stage)
    assert "run" in lengths
    too_long = {name: n for name, n in lengths.items() if n > MAX_STEP_LINES}
    assert not too_long, (f"pipeline/{stage}/stage.py: {too_long} longer than {MAX_STEP_LINES} lines; "
                          "split into named steps, move the work to design/measure/estimate/validate/report")

