"""The CasADi capsule clearances equal the numpy ones of RobotModel, for both robots."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.robot.collision import segment_distances
from pipeline.robot.collision_sx import capsule_clearance_function, segment_distance_sx
from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot


def test_segment_distance_matches_numpy_including_parallel_and_degenerate_segments() -> None:
    rng = np.random.default_rng(0)
    cases = [rng.normal(size=(4, 3)) for _ in range(100)]
    a0, a1 = np.zeros(3), np.array([1.0, 0, 0])
    cases += [np.array([a0, a1, [0, 1, 0], [1, 1, 0]]),  # parallel
              np.array([a0, a0, [0, 1, 0], [1, 1, 0]]),  # a point
              np.array([a0, a1, [2, 0, 0], [3, 0, 0]])]  # collinear, apart
    for p0, p1, q0, q1 in cases:
        ours = float(segment_distance_sx(*(np.asarray(x, float) for x in (p0, p1, q0, q1))))
        assert ours == pytest.approx(float(segment_distances(p0, p1, q0, q1)), abs=1e-6)


@pytest.mark.parametrize("name", ["rx130l", "staubli_tx40"])
def test_symbolic_capsule_clearances_match_the_model(name: str) -> None:
    robot = RobotModel.load(name)
    clearance = capsule_clearance_function(robot, SymbolicRobot(robot))
    rng = np.random.default_rng(4)
    for _ in range(30):
        q = rng.uniform(robot.limits.lower_rad, robot.limits.upper_rad)
        pair, floor = (np.asarray(x).ravel() for x in clearance(q))
        pair_numpy, floor_numpy = robot.capsule_clearances(robot.capsule_segments(q))
        np.testing.assert_allclose(pair, pair_numpy[0], atol=1e-6)
        assert floor.min() == pytest.approx(floor_numpy[0].min(), abs=1e-9)
