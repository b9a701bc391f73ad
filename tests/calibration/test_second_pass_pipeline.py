"""The second calibration pass end to end (slow, about 3 min per case): a run up to the
identification, then a calibration run whose ``calibration.gravity_model`` is that run's identified
robot. On the default (elastic) hidden robot of an arm whose own weight deflects it by tenths of a
millimetre (the RX130L with the generic joint stiffness, and the TX40) the held-out error then reaches
the tracker noise plus the stated unmodelled remainder, the predicted error is honest and every
identified joint stiffness is within 3 of its standard deviations of the hidden one."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.robot.model import RobotModel
from pipeline.run.run_check import check_run
from pipeline.run.runner import run_pipeline
from pipeline.run.second_pass import GRAVITY_SHARE_FOR_SECOND_PASS
from pipeline.sim.truth import RealRobot, TruthConfig

#: 3 sigma of the tracker plus the unmodelled remainder (3 µrad cyclic gear error at ~1.5 m: < 0.5 sigma)
HELDOUT_OVER_SIGMA_MAX = 3.5


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "seed"), [("rx130l_generic", 0), ("rx130l_generic", 2), ("staubli_tx40", 0)])
def test_second_pass_with_the_identified_gravity_model(tmp_path, robot, seed, rx130l_generic_stiffness_dir):
    robot = str(rx130l_generic_stiffness_dir) if robot == "rx130l_generic" else robot
    quiet = {"out_root": tmp_path, "log": lambda m: None}
    run_pipeline(load_config(None, [f"robot={robot}", f"seed={seed}", "name=first", "calibration.second_pass=never"],
                             "identification"), **quiet)
    identified = tmp_path / "first" / "identification" / "robot"
    run_pipeline(load_config(None, [f"robot={robot}", f"seed={seed}", "name=second",
                                    f"calibration.gravity_model={identified}"], "calibration"), **quiet)
    first = json.loads((tmp_path / "first" / "calibration" / "summary.json").read_text())
    second = json.loads((tmp_path / "second" / "calibration" / "summary.json").read_text())
    assert second["rms_after_over_sigma"] <= HELDOUT_OVER_SIGMA_MAX
    assert 1 / 1.5 <= second["actual_over_predicted"] <= 1.5
    assert second["gravity_model_share"] < first["gravity_model_share"]
    assert second["gravity_pass"]["gravity_model"] == str(identified)
    results = np.load(tmp_path / "second" / "calibration" / "results.npz")
    identified_joints = results["joint_stiffness_identified"].astype(bool)
    assert identified_joints.sum() >= 2
    hidden = RealRobot.create(RobotModel.load(robot), seed, TruthConfig()).joint_stiffness_Nm_rad
    compliance = 1.0 / np.asarray(second["joint_stiffness_Nm_rad"])
    z = (compliance - 1.0 / hidden)[identified_joints] / results["joint_compliance_std"][identified_joints]
    assert np.all(np.abs(z) <= 3.0), z


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
