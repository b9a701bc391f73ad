"""The validation path is the run's EN ISO 9283 path (``control.iso``, robot run_defaults
included), its settings enter the identification inputs hash, and a fallback is reported."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.control.config import ControlConfig
from pipeline.core.config import RunConfig, load_config, resolve_robot_dir
from pipeline.identification import report, stage
from pipeline.identification import validate as val_mod
from pipeline.identification.outcome import ValidationTrajectory
from pipeline.robot.model import RobotModel
from pipeline.run.runner import stage_inputs_hashes
from pipeline.run.stage_plan import plan_stages


def _identification_hash(values: dict | None = None) -> str:
    cfg = load_config(values=values, stages="identification")
    plans = plan_stages(cfg)
    return stage_inputs_hashes(cfg, plans, resolve_robot_dir(cfg))["identification"]


def test_stage_declares_that_it_reads_control_iso():
    assert "control.iso" in stage.CONFIG_READS


def test_inputs_hash_follows_control_iso_only():
    base = _identification_hash()
    assert _identification_hash() == base
    assert _identification_hash({"control.iso.edge_m": 0.4}) != base
    assert _identification_hash({"control.iso.centre_m": [1.0, 0.1, 0.6]}) != base
    assert _identification_hash({"control.ik_seeds_deg": [[0, 20, 80, 0, 70, 0]]}) != base   # the IK seeds
    assert _identification_hash({"control.settle_time_s": 0.5}) == base       # not read by identification
    assert _identification_hash({"control.variants": ["none", "full"]}) == base


def _no_fallback():
    raise AssertionError("fell back to the Fourier trajectory")


@pytest.fixture(scope="module")
def tx40():
    return RobotModel.load("staubli_tx40")


def test_tx40_validates_on_the_iso_path_of_its_run_defaults(tx40):
    run = load_config(values={"robot": "staubli_tx40"})
    iso = val_mod.run_iso_config(run)
    assert iso is run.control.iso and iso.edge_m == pytest.approx(0.2)      # robot.yaml run_defaults
    vt = val_mod.validation_trajectory(tx40, 4e-3, _no_fallback, control=run.control)
    assert vt.label == "iso9283" and "edge 0.2 m" in vt.note
    assert np.all(vt.q >= tx40.limits.lower_rad) and np.all(vt.q <= tx40.limits.upper_rad)


def test_rx130l_sized_path_falls_back_on_the_tx40(tx40):
    fallback = ValidationTrajectory(np.zeros(2), np.zeros((2, 6)), np.zeros((2, 6)), np.zeros((2, 6)),
                                            "fourier", "a random feasible Fourier trajectory")
    # a TX40 run (its robot.yaml IK seeds) given the RX130L's cube, out of the TX40's reach
    rx130l_cube = load_config(values={"robot": "staubli_tx40", "control.iso.centre_m": [1.0, 0.0, 0.6],
                                      "control.iso.edge_m": 0.5}).control
    assert rx130l_cube.ik_seeds_deg
    vt = val_mod.validation_trajectory(tx40, 4e-3, lambda: fallback, control=rx130l_cube)
    assert vt.label == "fourier" and "ISO 9283 path" in vt.note
    md = report.validation_markdown(stage.Config(), vt, rx130l_cube.iso, tx40)
    assert "Warning" in md and "control.iso.centre_m" in md and "control.iso.edge_m" in md
    assert "fell back" in md


def test_iso_path_markdown_names_the_path(tx40):
    run = load_config(values={"robot": "staubli_tx40"})
    vt = val_mod.validation_trajectory(tx40, 4e-3, _no_fallback, control=run.control)
    md = report.validation_markdown(stage.Config(), vt, run.control.iso, tx40)
    assert "EN ISO 9283 path" in md and "Warning" not in md


def test_missing_control_section_uses_the_built_in_path():
    bare = RunConfig(sections={"control": {}})
    assert val_mod.run_iso_config(bare) == ControlConfig().iso
    assert val_mod.run_iso_config(RunConfig()) == ControlConfig().iso
    run = load_config(values={"control.iso.edge_m": 0.3})
    assert val_mod.run_iso_config(run).edge_m == pytest.approx(0.3)


def test_ik_seeds_come_from_the_run(tx40, monkeypatch):
    """The ISO path starts from the run's control.ik_seeds_deg, not the built-in ControlConfig()."""
    seen = []
    original = val_mod.start_configuration

    def spy(robot, pose, seeds, *args, **kwargs):
        seen.append(np.array(seeds))
        return original(robot, pose, seeds, *args, **kwargs)

    monkeypatch.setattr(val_mod, "start_configuration", spy)
    run = load_config(values={"robot": "staubli_tx40", "control.ik_seeds_deg": [[5, 10, 90, 0, 60, 0]]})
    control = val_mod.run_control_config(run)
    assert control is run.control
    val_mod.validation_trajectory(tx40, 4e-3, _no_fallback, control=control)
    np.testing.assert_allclose(seen[0], np.radians([[5, 10, 90, 0, 60, 0]]))


def test_wrong_seed_length_is_the_stated_reason(tx40):
    fallback = ValidationTrajectory(np.zeros(2), np.zeros((2, 6)), np.zeros((2, 6)), np.zeros((2, 6)),
                                            "fourier", "a random feasible Fourier trajectory")
    control = load_config(values={"robot": "staubli_tx40", "control.ik_seeds_deg": [[0.0] * 7]}).control
    vt = val_mod.validation_trajectory(tx40, 4e-3, lambda: fallback, control=control)
    assert vt.label == "fourier" and "control.ik_seeds_deg[0]" in vt.note and "7 values" in vt.note
    md = report.validation_markdown(stage.Config(), vt, control.iso, tx40)
    assert "control.ik_seeds_deg" in md and "7 values, the robot has 6 joints" in md
