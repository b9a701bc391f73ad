"""An arm whose excitation cannot bring the base regressor under the condition-number bound is
identified on what it can excite (:func:`pipeline.identification.experiment.shrink_base_set`), not
refused: here the UR3 against a bound below what its best excitation reaches."""

from __future__ import annotations

import json

import pytest

from pipeline.core.config import CONFIGS_DIR
from pipeline.robot.example_robots import example_arm_urdf
from tests.anyarm.corpus_run import run_cli

#: below the UR3's best excitation in the corpus profile (cond about 55), below its random median / 10
BOUND = 40.0


@pytest.mark.slow
def test_excitation_over_the_bound_drops_base_parameters_and_runs(tmp_path):
    urdf = example_arm_urdf("ur3")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    code, lines = run_cli(["robot", "init", str(urdf), "--out", str(tmp_path / "arm" / "robot.yaml")])
    assert code == 0, lines
    code, lines = run_cli(["run", "--config", str(CONFIGS_DIR / "corpus.yaml"), "--set", f"robot={tmp_path / 'arm'}",
                           "--set", "name=ur3", "--set", f"identification.max_cond_base_regressor_data={BOUND}",
                           "--stages", "model,calibration,identification", "--out", str(tmp_path / "runs"),
                           "--accept-poor"])
    assert code == 0, lines
    summary = json.loads((tmp_path / "runs" / "ur3" / "identification" / "summary.json").read_text())
    dropped = summary["design_dropped_base_parameters"]
    assert dropped and summary["design_dropped_cond_full_set"] > BOUND
    assert summary["n_base_parameters"] == summary["n_base_parameters_structural"] < 58
    assert summary["cond_base_regressor_data"] <= BOUND
    assert any("left out of the design" in w for w in summary.get("warnings", []))
    report = (tmp_path / "runs" / "ur3" / "identification" / "report.md").read_text()
    assert "left out of the design and the fits" in report
