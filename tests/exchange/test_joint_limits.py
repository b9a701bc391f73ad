"""joint_limits.yaml written and read back; the handed-on URDF keeps the source's continuous joints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from pipeline.exchange.joint_limits import (
    JointLimitTable,
    handed_on_urdf,
    read_joint_limits_yaml,
    source_joint_types,
    write_joint_limits_yaml,
)
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel


def test_joint_limits_yaml_round_trip(tmp_path: Path, rx130l: RobotModel) -> None:
    table = JointLimitTable.of_model(rx130l)
    path = write_joint_limits_yaml(tmp_path / "joint_limits.yaml", table, "a note")
    back = read_joint_limits_yaml(path)
    assert back.joint_names == table.joint_names
    for field in ("lower_rad", "upper_rad", "velocity_rad_s", "acceleration_rad_s2", "effort_Nm"):
        np.testing.assert_array_equal(getattr(back, field), getattr(table, field))
    reordered = read_joint_limits_yaml(path, list(reversed(table.joint_names)))
    np.testing.assert_array_equal(reordered.effort_Nm, table.effort_Nm[::-1])


def test_continuous_joints_stay_continuous_and_yourdfpy_loads_the_urdf(tmp_path: Path) -> None:
    source = example_arm_urdf("kinova_description/robots/kinova.urdf")
    if source is None:
        pytest.skip("example-robot-data is not installed")
    robot = RobotModel.load(source)
    continuous = [name for name, kind in source_joint_types(source).items() if kind == "continuous"]
    assert continuous, "the source URDF has continuous joints"
    path = tmp_path / "arm.urdf"
    path.write_text(handed_on_urdf(robot))
    assert {n for n, kind in source_joint_types(path).items() if kind == "continuous"} == set(continuous)
    urdf = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False)
    for joint in continuous:
        assert urdf.joint_map[joint].type == "continuous"
    revolute = [n for n in robot.model.names[1:] if n not in continuous]
    for joint in revolute:
        k = list(robot.model.names[1:]).index(joint)
        assert urdf.joint_map[joint].limit.lower == pytest.approx(robot.limits.lower_rad[k])
