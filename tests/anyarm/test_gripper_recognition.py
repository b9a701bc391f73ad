"""Grippers and end effectors are recognised and locked by `robot init`: a two-finger gripper whose
joints follow one driver (`<mimic>`, as a Robotiq 2F-85's knuckles), or whose joints are named as
a gripper's, is not taken for two more arm chains."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.grippers import gripper_joints
from pipeline.robot.model import RobotModel

FINGER = """
  <link name="{side}_pad"><inertial><mass value="0.05"/><origin xyz="0 0 0.02"/>
    <inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial></link>
  <joint name="{joint}" type="revolute"><parent link="tool0"/><child link="{side}_pad"/>
    <origin xyz="0 {y} 0.05"/><axis xyz="1 0 0"/><limit lower="0" upper="0.8" effort="10" velocity="2"/>{mimic}
  </joint>"""


def _ur5_with_gripper(tmp_path: Path, left: str, right: str, mimic: bool) -> Path:
    urdf = example_arm_urdf("ur5")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    tag = f'<mimic joint="{left}" multiplier="-1"/>' if mimic else ""
    fingers = (FINGER.format(side="left", joint=left, y=0.02, mimic="")
               + FINGER.format(side="right", joint=right, y=-0.02, mimic=tag))
    text = urdf.read_text().replace("</robot>", fingers + "\n</robot>")
    target = tmp_path / "ur5_gripper.urdf"
    target.write_text(text)
    return target


@pytest.mark.parametrize(("left", "right", "mimic"), [("left_outer", "right_outer", True),
                                                      ("left_knuckle_joint", "right_knuckle_joint", False)])
def test_a_two_finger_gripper_is_locked_and_the_arm_ends_at_the_flange(tmp_path, left, right, mimic):
    urdf = _ur5_with_gripper(tmp_path, left, right, mimic)
    assert gripper_joints(ET.parse(urdf).getroot()) == {left, right}
    robot = RobotModel.load(urdf)
    assert robot.nq == 6 and robot.spec.flange_frame == "tool0"
    assert left not in list(robot.model.names) and any(left in a and right in a for a in robot.assumptions)


def test_a_last_axis_named_after_the_palm_it_turns_is_the_arms(tmp_path):
    """A Barrett WAM's seventh joint is ``palm_yaw_joint``: an arm axis, not a gripper's."""
    urdf = example_arm_urdf("ur5")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    target = tmp_path / "arm.urdf"
    target.write_text(urdf.read_text().replace('"wrist_3_joint"', '"palm_yaw_joint"'))
    assert gripper_joints(ET.parse(target).getroot()) == set()
    robot = RobotModel.load(target)
    assert robot.nq == 6 and list(robot.model.names)[-1] == "palm_yaw_joint"
