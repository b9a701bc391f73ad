"""The ``robot`` setting of a test run on a built-in robot or on example-robot-data's arm of that name
(the test is skipped where that package is not installed)."""

from __future__ import annotations

import pytest

from pipeline.robot.example_robots import example_arm_urdf

#: the arms taken from example-robot-data rather than robots/
EXAMPLE_ROBOT_DATA_ARMS = frozenset({"panda"})


def robot_setting(name: str) -> str:
    """``name`` itself for a built-in robot, else the path of example-robot-data's URDF."""
    if name not in EXAMPLE_ROBOT_DATA_ARMS:
        return name
    urdf = example_arm_urdf(name)
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    return str(urdf)
