"""A robot from its URDF alone (no robot.yaml): chain, locked joints, assumptions, save/load, n-DOF reference."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.core.errors import RobotFileError
from pipeline.robot import defaults
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.robot.reference import resolved_rate
from pipeline.robot.yaml_init import write_robot_yaml


def _erd(name: str) -> Path:
    path = example_arm_urdf(name)
    if path is None:
        pytest.skip("example-robot-data not installed")
    return path


ARMS = {"ur5": ("ur_description/urdf/ur5_robot.urdf", 6), "ur10": ("ur_description/urdf/ur10_robot.urdf", 6),
        "panda": ("panda_description/urdf/panda.urdf", 7), "xarm7": ("xarm_description/urdf/xarm7.urdf", 7),
        "z1": ("z1_description/urdf/z1.urdf", 6)}


@pytest.mark.parametrize("name", sorted(ARMS))
def test_urdf_alone_loads_with_stated_assumptions_and_survives_save(name, tmp_path):
    rel, dof = ARMS[name]
    robot = RobotModel.load(_erd(rel))
    assert robot.nq == dof                     # fingers / gripper joints locked, world root accepted
    assert any("gear ratio" in a for a in robot.assumptions)
    assert any("tracker" in a for a in robot.assumptions)
    assert robot.has_tracker and robot.capsules
    again = RobotModel.load(robot.save(tmp_path / name))
    q = np.random.default_rng(3).uniform(robot.limits.lower_rad, robot.limits.upper_rad)
    assert np.allclose(robot.fk(q).homogeneous, again.fk(q).homogeneous, atol=1e-12)
    assert np.allclose(robot.inverse_dynamics(q, q, q), again.inverse_dynamics(q, q, q), rtol=1e-9, atol=1e-9)
    assert again.assumptions == robot.assumptions


def test_panda_fingers_locked_and_listed():
    robot = RobotModel.load(_erd("panda_description/urdf/panda.urdf"))
    assert "panda_finger_joint1" not in list(robot.model.names)
    assert any("panda_finger_joint1" in a for a in robot.assumptions)


def test_bad_tip_and_base_name_the_field():
    urdf = _erd("ur_description/urdf/ur5_robot.urdf")
    with pytest.raises(RobotFileError, match="tip"):
        RobotModel.load(urdf, tip="no_such_link")
    with pytest.raises(RobotFileError, match="base"):
        RobotModel.load(urdf, base="wrist_3_link")


def test_mimic_on_the_chain_is_rejected(tmp_path):
    text = _erd("ur_description/urdf/ur5_robot.urdf").read_text()
    text = text.replace('<joint name="elbow_joint" type="revolute">',
                        '<joint name="elbow_joint" type="revolute"><mimic joint="shoulder_lift_joint"/>')
    urdf = tmp_path / "ur5.urdf"
    urdf.write_text(text)
    with pytest.raises(RobotFileError, match="mimic"):
        RobotModel.load(urdf)


def test_redundant_resolved_rate_is_the_minimum_norm_solution():
    robot = RobotModel.load(_erd("panda_description/urdf/panda.urdf"))
    q = defaults.ready_pose_rad(robot)
    J = robot.jacobian(q)
    x = np.arange(6.0)
    dq = resolved_rate(J, x)
    assert np.allclose(J @ dq, x)
    assert np.allclose(dq, np.linalg.pinv(J) @ x)


def test_ready_pose_and_move_are_collision_free_and_inside_limits():
    robot = RobotModel.load(_erd("ur_description/urdf/ur5_robot.urdf"))
    q = defaults.ready_pose_rad(robot)
    assert robot.within_limits(q) and not robot.in_collision(q)
    assert robot.fk(q, robot.frame_flange).translation[2] > robot.model.jointPlacements[1].translation[2]
    start, goal = defaults.ptp_move_rad(robot)
    assert robot.within_limits(start) and robot.within_limits(goal) and np.max(np.abs(goal - start)) > 0.1
    seeds = defaults.ik_seeds_rad(robot)
    assert seeds.shape[1] == robot.nq and len(seeds) >= 2


def test_robot_init_writes_an_editable_yaml_that_loads_back(tmp_path):
    source = _erd("ur_description/urdf/ur5_robot.urdf")
    urdf = tmp_path / "ur5.urdf"
    shutil.copy(source, urdf)
    assumed = RobotModel.load(urdf)
    written = write_robot_yaml(urdf)
    text = written.read_text()
    assert text.startswith("# robot.yaml written by") and "gear ratio" in text
    with pytest.raises(RobotFileError, match="already exists"):
        write_robot_yaml(urdf)
    loaded = RobotModel.load(urdf)                        # now read from the yaml, not assumed
    assert loaded.spec.path == written
    assert np.allclose(loaded.actuation.gear_ratio, assumed.actuation.gear_ratio)
    assert [c.name for c in loaded.capsules] == [c.name for c in assumed.capsules]
    q = defaults.ready_pose_rad(assumed)
    assert np.allclose(loaded.fk(q, "reflector").translation, assumed.fk(q, "reflector").translation)


def test_two_arm_urdf_asks_for_a_tip_and_says_how(tmp_path):
    """A URDF with two equally deep arms (a dual-arm robot) names both ends and the command that picks one."""
    text = _erd("ur_description/urdf/ur5_robot.urdf").read_text()
    second = text.split("<robot", 1)[1].split(">", 1)[1].rsplit("</robot>", 1)[0]
    renamed = second.replace('name="', 'name="b_').replace('link="', 'link="b_')   # a second UR5, b_*
    urdf = tmp_path / "two_ur5.urdf"
    urdf.write_text(text.rsplit("</robot>", 1)[0] + renamed
                    + '<joint name="mount_b" type="fixed"><parent link="world"/><child link="b_world"/>'
                    '<origin xyz="1 0 0"/></joint></robot>')
    with pytest.raises(RobotFileError, match="robot init .* --tip LINK"):
        RobotModel.load(urdf)
    assert RobotModel.load(urdf, tip="b_wrist_3_link").nq == 6
