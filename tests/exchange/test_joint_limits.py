"""joint_limits.yaml written and read back; the handed-on URDF keeps the source's continuous joints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from pipeline.core.errors import DataFileError
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


#: joint names a URDF may hold that a line-by-line YAML writer gets wrong: numbers, booleans of YAML 1.1 or
#: 1.2, null, indicators, separators, quotes, spaces, non-ASCII
ODD_JOINT_NAMES = ("1", "010", "1e3", "0x10", "1:30", "yes", "On", "Y", "true", "null", "~", "a: b", "#x", "-j",
                   "[j]", "j,k", "'q'", '"q"', "joint 1", "é")


def test_joint_limits_yaml_reads_back_any_joint_name(tmp_path: Path) -> None:
    """Read back by the project's YAML 1.2 reader and by PyYAML (YAML 1.1, as ROS 2 launch files load a
    MoveIt config): every name a string, the same names in the same order."""
    n = len(ODD_JOINT_NAMES)
    table = JointLimitTable(ODD_JOINT_NAMES, -0.1 * np.arange(1, n + 1), 0.1 * np.arange(1, n + 1), np.full(n, 2.0),
                            np.full(n, 5.0), np.full(n, 10.0))
    path = write_joint_limits_yaml(tmp_path / "joint_limits.yaml", table)
    back = read_joint_limits_yaml(path)
    assert back.joint_names == ODD_JOINT_NAMES
    np.testing.assert_array_equal(back.upper_rad, table.upper_rad)
    yaml = pytest.importorskip("yaml")
    assert tuple(yaml.safe_load(path.read_text())["joint_limits"]) == ODD_JOINT_NAMES


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


def test_an_absent_limit_round_trips_and_bad_values_are_named(tmp_path: Path) -> None:
    inf = np.inf
    table = JointLimitTable(("a", "1"), np.array([-1.0, -inf]), np.array([1.0, inf]), np.array([2.0, inf]),
                            np.array([5.0, 3.0]), np.array([10.0, inf]))
    back = read_joint_limits_yaml(write_joint_limits_yaml(tmp_path / "limits.yaml", table))
    for field in ("lower_rad", "upper_rad", "velocity_rad_s", "acceleration_rad_s2", "effort_Nm"):
        np.testing.assert_array_equal(getattr(back, field), getattr(table, field))
    path = tmp_path / "moveit.yaml"
    path.write_text("joint_limits:\n  1:\n    has_velocity_limits: no\n    max_velocity: 2.0\n")
    assert np.isinf(read_joint_limits_yaml(path, ["1"]).velocity_rad_s[0])     # yaml-cpp's "no", an int key
    for text, problem in (("has_velocity_limits: true\n    max_velocity: -2.0", "negative"),
                          ("has_velocity_limits: true\n    max_velocity: .nan", "not a finite number"),
                          ("has_position_limits: true\n    min_position: 2.0\n    max_position: 1.0", "above"),
                          ("has_velocity_limits: maybe\n    max_velocity: 1.0", "not true or false")):
        path.write_text(f"joint_limits:\n  a:\n    {text}\n")
        with pytest.raises(DataFileError, match=problem):
            read_joint_limits_yaml(path)
