"""The default PtP move (:func:`pipeline.robot.defaults.ptp_move_rad`) is one the arm can hold itself
on: the static torques along it within ``GRAVITY_TORQUE_SHARE`` of the limits, as on the ISO path."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.errors import InfeasibleError
from pipeline.robot import defaults
from pipeline.robot.iso_search import GRAVITY_TORQUE_SHARE


def _mid_range_move(robot, fraction: float = 0.4):
    lo, hi, mid = robot.limits.lower_rad, robot.limits.upper_rad, defaults.ready_pose_rad(robot)
    half = 0.5 * fraction * np.minimum(hi - lo, 2 * np.pi)
    return np.clip(mid - half, lo, hi), np.clip(mid + half, lo, hi)


def _static_ratio(robot, start, goal) -> float:
    return max(float(np.max(np.abs(robot.gravity_torque(start + t * (goal - start))) / robot.limits.effort_Nm))
               for t in np.linspace(0, 1, 41))


def test_a_weak_wrist_gets_a_move_it_can_hold(rx130l):
    start, goal = defaults.ptp_move_rad(rx130l)
    assert np.array_equal(np.stack([start, goal]), np.stack(_mid_range_move(rx130l)))   # the arm as shipped
    weak = rx130l.copy()
    wrist = 4                                                    # axis 5 carries the tool
    weak.model.effortLimit[wrist] = 1.2 * np.max(np.abs([weak.gravity_torque(q)[wrist] for q in _mid_range_move(weak)]))
    assert _static_ratio(weak, *_mid_range_move(weak)) > GRAVITY_TORQUE_SHARE
    start, goal = defaults.ptp_move_rad(weak)
    assert defaults.holds_itself(weak, start, goal)
    assert _static_ratio(weak, start, goal) <= GRAVITY_TORQUE_SHARE * 1.02     # sampled 2x finer here
    assert np.max(np.abs(goal - start)) > 0.1


def test_an_arm_that_holds_itself_nowhere_names_the_fields_to_set(rx130l):
    weak = rx130l.copy()
    weak.model.effortLimit[1] = 1.0                      # the shoulder cannot carry the arm
    with pytest.raises(InfeasibleError, match="trajectory.ptp_start_deg.*holds itself"):
        defaults.ptp_move_rad(weak)
