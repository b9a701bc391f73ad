"""The ISO 9283 cube search turns to the side where the arm works when nothing lies in front of it."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.robot import defaults
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.iso_search import MIN_EDGE_REACH
from pipeline.robot.model import RobotModel

PAN = '<limit effort="150.0" lower="-6.28318530718" upper="6.28318530718" velocity="3.15"/>'


def test_cube_found_beside_an_arm_that_cannot_turn_to_the_front(tmp_path):
    source = example_arm_urdf("ur5")
    if source is None:
        pytest.skip("example-robot-data not installed")
    text = source.read_text()
    assert PAN in text                                 # the shoulder pan joint's limits
    # pan held to +-0.3 rad about +90 deg: the arm works on the +y side only
    urdf = tmp_path / "ur5_side.urdf"
    urdf.write_text(text.replace(PAN, PAN.replace('lower="-6.28318530718" upper="6.28318530718"',
                                                  'lower="1.27" upper="1.87"'), 1))
    robot = RobotModel.load(urdf)
    cube = defaults.iso_cube(robot)
    reach = float(robot.summary()["reach_m"])
    base = robot.model.jointPlacements[1].translation
    assert cube.edge_m >= 0.4 * MIN_EDGE_REACH * reach    # the smallest tried, shrunk by the final check
    assert cube.centre_m[1] - base[1] > 0.15 * reach   # beside the base, where the arm can reach
    assert abs(cube.centre_m[0] - base[0]) < 1e-9
    q = cube.q_start_rad
    assert q is not None and robot.within_limits(q)
    assert np.linalg.norm(robot.fk(q, robot.frame_reflector).translation
                          - cube.centre_m) < np.sqrt(3) * cube.edge_m
