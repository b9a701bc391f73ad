"""``robot init --joint-limits``: a MoveIt joint_limits.yaml as the arm's packages ship it (ur_description's
``!degrees`` tags, ``has_acceleration_limits: false``, joints it does not list) gives the accelerations a URDF
lacks, and the velocity limits where the URDF's are placeholders; what it leaves out stays ASSUMED."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.cli import main
from pipeline.exchange.joint_limits import read_joint_limits_yaml
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.robot.urdf_import import ACCELERATION_PER_VELOCITY_1_S

JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint")


def _ur5(tmp_path: Path, text_edit=None) -> Path:
    path = example_arm_urdf("ur5")
    if path is None:
        pytest.skip("example-robot-data not installed")
    text = path.read_text()
    folder = tmp_path / "ur5"
    folder.mkdir()
    (folder / "ur5.urdf").write_text(text if text_edit is None else text_edit(text))
    return folder / "ur5.urdf"


def _limits_file(tmp_path: Path, accelerations: dict[str, float], velocity_deg_s: float = 180.0) -> Path:
    lines = ["# as ur_description writes it", "joint_limits:"]
    for name in JOINTS[:-1]:                                   # wrist_3 not listed
        lines += [f"  {name}:", "    has_position_limits: true", "    max_position: !degrees  360.0",
                  "    min_position: !degrees -360.0", "    has_velocity_limits: true",
                  f"    max_velocity: !degrees  {velocity_deg_s}", "    has_effort_limits: true",
                  "    max_effort: 150.0"]
        if name in accelerations:
            lines += ["    has_acceleration_limits: true", f"    max_acceleration: {accelerations[name]}"]
        else:
            lines += ["    has_acceleration_limits: false", "    max_acceleration: 0"]
    path = tmp_path / "joint_limits.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_degrees_tags_and_absent_limits_read(tmp_path):
    table = read_joint_limits_yaml(_limits_file(tmp_path, {"elbow_joint": 8.0}), list(JOINTS), missing_ok=True)
    assert table.upper_rad[0] == pytest.approx(2 * np.pi) and table.velocity_rad_s[1] == pytest.approx(np.pi)
    assert table.acceleration_rad_s2[2] == 8.0 and np.isinf(table.acceleration_rad_s2[0])
    assert np.isinf(table.velocity_rad_s[5])                   # a joint the file does not list


def test_stated_accelerations_are_facts_and_the_rest_stays_assumed(tmp_path):
    urdf = _ur5(tmp_path)
    stated = {name: 3.0 + k for k, name in enumerate(JOINTS[:-1])}
    assert main(["robot", "init", str(urdf), "--joint-limits", str(_limits_file(tmp_path, stated))]) == 0
    text = (urdf.parent / "robot.yaml").read_text()
    data = yaml.safe_load(text)
    robot = RobotModel.load(urdf.parent)
    rule_value = ACCELERATION_PER_VELOCITY_1_S * robot.limits.velocity_rad_s[5]
    np.testing.assert_allclose(robot.limits.acceleration_rad_s2, [3, 4, 5, 6, 7, rule_value])
    rule = data["assumed"]["limits.acceleration_rad_s2"]["rule"]
    assert "['wrist_3_joint']" in rule and "joint_limits.yaml states the others" in rule
    # every joint stated: no assumption left on the accelerations
    (urdf.parent / "robot.yaml").unlink()
    stated[JOINTS[-1]] = 9.0
    full = _limits_file(tmp_path, stated)
    full.write_text(full.read_text() + "\n".join(["  wrist_3_joint:", "    has_acceleration_limits: true",
                                                  "    max_acceleration: 9.0"]) + "\n")
    assert main(["robot", "init", str(urdf), "--joint-limits", str(full)]) == 0
    data = yaml.safe_load((urdf.parent / "robot.yaml").read_text())
    assert "limits.acceleration_rad_s2" not in data["assumed"]
    np.testing.assert_allclose(RobotModel.load(urdf.parent).limits.acceleration_rad_s2, [3, 4, 5, 6, 7, 9])


def test_placeholder_velocities_come_from_the_file(tmp_path):
    urdf = _ur5(tmp_path, lambda text: re.sub(r'velocity="[^"]*"', 'velocity="0"', text))
    assert main(["robot", "init", str(urdf), "--joint-limits", str(_limits_file(tmp_path, {}, 90.0))]) == 0
    robot = RobotModel.load(urdf.parent)
    np.testing.assert_allclose(robot.limits.velocity_rad_s[:5], np.radians(90.0))
    data = yaml.safe_load((urdf.parent / "robot.yaml").read_text())
    assert "PLACEHOLDER" in data["assumed"]["limits.velocity_rad_s"]["rule"]      # wrist_3 still a placeholder
    # the accelerations' rule follows the file's velocities, not the placeholders'
    np.testing.assert_allclose(robot.limits.acceleration_rad_s2[:5], ACCELERATION_PER_VELOCITY_1_S * np.radians(90.0))
