"""Plausibility warnings: silent for real arms, loud for placeholder masses and limits."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline import cli
from pipeline.core.config import REPO_ROOT
from pipeline.robot import plausibility as pl
from pipeline.robot.example_robots import EXAMPLE_ARMS, example_arm_urdf
from pipeline.robot.mdh import JointSpec, LinkSpec, MDHRobotSpec, MDHRow, cylinder_inertia, urdf_from_mdh
from pipeline.robot.model import RobotModel

BUILT_IN = sorted(d.name for d in (REPO_ROOT / "robots").iterdir() if (d / "robot.yaml").is_file())

# a 1.66 m arm (axis 1 to flange) of the RX130L's geometry (DESIGN.md, "The robot")
ROWS = [MDHRow(0.0, 0.0, 0.0, 0.550), MDHRow(-np.pi / 2, 0.0, -np.pi / 2, 0.0),
        MDHRow(0.0, 0.625, -np.pi / 2, 0.0), MDHRow(-np.pi / 2, 0.0, 0.0, 0.925),
        MDHRow(np.pi / 2, 0.0, 0.0, 0.0), MDHRow(-np.pi / 2, 0.0, np.pi, 0.110)]
REAL_EFFORT_NM = [550.0, 700.0, 350.0, 55.0, 40.0, 30.0]
REAL_SPEED_RAD_S = list(np.deg2rad([200.0, 200.0, 255.0, 315.0, 360.0, 870.0]))
REAL_MASS_KG = [45.0, 35.0, 20.0, 22.0, 2.0, 0.3]


def _urdf(tmp_path, masses_kg, effort_Nm, speed_rad_s, name="arm"):
    links = [LinkSpec(m, [0.0, 0.0, 0.05], list(cylinder_inertia(m, 0.05, 0.2, 2)), [0, 0, 0], [0, 0, 0.1], 0.05)
             for m in masses_kg]
    joints = [JointSpec(-2.5, 2.5, v, e) for v, e in zip(speed_rad_s, effort_Nm, strict=True)]
    path = tmp_path / f"{name}.urdf"
    path.write_text(urdf_from_mdh(MDHRobotSpec(name, ROWS, links, joints)))
    return RobotModel.load(path)


def _data_sheet_figures(arm: pl.DataSheetArm) -> pl.ArmFigures:
    """A data-sheet arm as the checks see it: its torque on the shoulder, smaller wrist torques."""
    torque = arm.max_torque_Nm or 1.2 * pl.holding_torque_Nm(arm.reach_m, arm.payload_kg, arm.mass_kg)
    return pl.ArmFigures(arm.reach_m, arm.mass_kg, arm.payload_kg, torque * np.array([1.0, 1.0, 0.5, 0.1, 0.1, 0.05]),
                         np.full(6, np.deg2rad(arm.axis1_speed_deg_s)), np.array([5.0, 4.0, 3.0, 1.0, 0.5, 0.2]))


@pytest.mark.parametrize("arm", pl.DATA_SHEET_ARMS, ids=lambda a: a.name)
def test_the_data_sheets_behind_the_bands_pass_their_own_checks(arm):
    assert pl.plausibility_warnings(_data_sheet_figures(arm)) == []


@pytest.mark.parametrize("name", BUILT_IN)
def test_built_in_robots_are_plausible(name):
    assert pl.robot_warnings(RobotModel.load(name)) == []


@pytest.mark.parametrize("name", sorted(EXAMPLE_ARMS))
def test_example_robot_data_arms_are_plausible(name):
    urdf = example_arm_urdf(name)
    if urdf is None:
        pytest.skip("example-robot-data is not installed")
    assert pl.robot_warnings(RobotModel.load(urdf)) == []


def test_a_real_size_urdf_passes_and_two_kilogram_links_are_flagged(tmp_path):
    real = _urdf(tmp_path, REAL_MASS_KG, REAL_EFFORT_NM, REAL_SPEED_RAD_S, "real")
    assert pl.robot_warnings(real) == []
    light = _urdf(tmp_path, [2.0] * 6, REAL_EFFORT_NM, REAL_SPEED_RAD_S, "light")
    warnings = pl.robot_warnings(light)
    assert any("implausibly light for a 1.6" in w for w in warnings), warnings
    assert any("every moving link weighs 2 kg" in w for w in warnings), warnings


def test_placeholder_limits_identical_on_every_joint_are_flagged(tmp_path):
    """One torque limit on every joint that holds the arm stays (and is warned about); one that cannot
    hold it is a placeholder (:mod:`pipeline.robot.vendor_urdf`), replaced and labelled."""
    robot = _urdf(tmp_path, REAL_MASS_KG, [1000.0] * 6, [10.0] * 6, "same")
    warnings = pl.robot_warnings(robot)
    assert any("every joint has the same torque limit 1000 N·m and the same speed limit 10 rad/s" in w
               for w in warnings), warnings
    weak = _urdf(tmp_path, REAL_MASS_KG, [300.0] * 6, [10.0] * 6, "same_weak")
    assert any(a.startswith("PLACEHOLDER effort limits") and "one value on every joint" in a
               for a in weak.assumptions)
    assert len(set(weak.limits.effort_Nm)) > 1


def test_the_same_speed_on_every_joint_alone_is_no_warning(tmp_path):
    robot = _urdf(tmp_path, REAL_MASS_KG, REAL_EFFORT_NM, [np.pi] * 6, "same_speed")
    assert pl.robot_warnings(robot) == []


def test_light_arm_for_its_payload_is_flagged():
    # the RX130L's figures with a sixteenth of its mass against a 16 kg payload
    arm = _data_sheet_figures(pl.DataSheetArm("x", 1.611, 16.0, 235.0, 200.0))
    light = dataclasses.replace(arm, moving_mass_kg=12.0)
    assert any("light for a 16 kg payload" in w for w in pl.plausibility_warnings(light))
    assert not any("payload" in w for w in pl.plausibility_warnings(arm))


@pytest.mark.parametrize(("scale_effort", "scale_speed", "words"), [
    (100.0, 1.0, "far above"), (1e-3, 1.0, "far below"), (1.0, 10.0, "implausibly fast"),
    (1.0, 0.05, "implausibly slow"), (1.0, 1.0, None)])
def test_efforts_and_speeds_far_from_the_arms_size_are_flagged(scale_effort, scale_speed, words):
    arm = _data_sheet_figures(pl.DATA_SHEET_ARMS[1])
    scaled = dataclasses.replace(arm, effort_Nm=arm.effort_Nm * scale_effort,
                                 velocity_rad_s=arm.velocity_rad_s * scale_speed)
    warnings = pl.plausibility_warnings(scaled)
    assert (words is None and warnings == []) or (words is not None and any(words in w for w in warnings)), warnings


def test_grams_instead_of_kilograms_are_flagged():
    arm = _data_sheet_figures(pl.DATA_SHEET_ARMS[0])
    assert any("implausibly heavy" in w for w in pl.plausibility_warnings(
        dataclasses.replace(arm, moving_mass_kg=1000 * arm.moving_mass_kg, effort_Nm=1000 * arm.effort_Nm)))


def test_placeholder_warnings_reach_check_the_console_and_the_headline(tmp_path, capsys):
    """A URDF alone with 2 kg links and 300 N·m / 10 rad/s on every joint: `check` and the model
    stage's run name the placeholders; the report's headline lists them."""
    _urdf(tmp_path, [2.0] * 6, [300.0] * 6, [10.0] * 6, "placeholder")
    urdf, out = tmp_path / "placeholder.urdf", tmp_path / "runs"
    assert cli.main(["check", "--stages", "model", "--set", f"robot={urdf}", "--out", str(out)]) == 0
    checked = capsys.readouterr().out
    assert "warning: robot placeholder: moving mass 12 kg is implausibly light" in checked
    assert "every joint has the same torque limit 300 N·m" in checked
    assert cli.main(["run", "--stages", "model", "--set", f"robot={urdf}", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    head = (out / "placeholder" / "report.md").read_text().split("\n## model")[0]
    for text in (printed, head):
        assert "moving mass 12 kg is implausibly light" in text and "same torque limit 300 N·m" in text
    assert "3 warning(s)" in printed and "**Assumptions still in force**:" in head
