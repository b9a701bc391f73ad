"""Excitation clearance per capsule pair: pairs close by construction keep a share of their typical
clearance, every other pair the configured margin."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identification.fourier import CLOSE_PAIR_SHARE, pair_clearances_m
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel


def test_a_robot_with_room_between_its_capsules_keeps_the_margin():
    robot = RobotModel.load("rx130l")
    assert np.all(robot.typical_pair_clearances_m() >= 0.02)
    np.testing.assert_array_equal(pair_clearances_m(robot, 0.02), 0.02)


def test_capsules_close_by_construction_are_held_at_a_share_of_their_typical_clearance():
    urdf = example_arm_urdf("z1")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    robot = RobotModel.load(urdf)
    typical = robot.typical_pair_clearances_m()
    required = pair_clearances_m(robot, 0.02)
    close = typical < 0.02
    assert close.any() and not close.all()        # the compact wrist, not the whole arm
    np.testing.assert_allclose(required[close], CLOSE_PAIR_SHARE * np.maximum(typical[close], 0.0))
    assert np.all(required[~close] == 0.02) and np.all(required <= 0.02)
