"""IK along a path: a joint leaving its limits is named, with the path point and time."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.core.errors import InfeasibleError
from pipeline.robot.paths import ik_track
from pipeline.robot.reference import track


def _line(robot, q0, n=20, length_m=0.05):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q0)
    start = data.oMf[robot.model.getFrameId("tcp")]
    return [pin.SE3(start.rotation, start.translation + np.array([s, 0.0, 0.0])) for s in np.linspace(0, length_m, n)]


def _narrowed(rx130l, q0, j):
    """A copy whose joint ``j`` may not move more than 1 mrad from ``q0``."""
    robot = rx130l.copy()
    robot.model.lowerPositionLimit[j] = q0[j] - 1e-3
    robot.model.upperPositionLimit[j] = q0[j] + 1e-3
    return robot


def test_ik_track_names_the_first_point_outside_the_limits(rx130l):
    q0 = np.array([0.3, -0.4, 1.2, 0.1, 0.6, 0.2])
    poses = _line(rx130l, q0)
    assert ik_track(rx130l, poses, q0).shape == (20, 6)
    with pytest.raises(InfeasibleError, match=r"TCP point \[.*\] m at t = 0\.\d+ s needs joint 1 = "):
        ik_track(_narrowed(rx130l, q0, 0), poses, q0, times_s=np.linspace(0, 1, 20))


def test_reference_track_names_the_joint_outside_the_limits(rx130l):
    q0 = np.array([0.3, -0.4, 1.2, 0.1, 0.6, 0.2])
    poses = _line(rx130l, q0)
    P = np.array([T.translation for T in poses])
    t_s = np.linspace(0, 1, len(P))
    Pd = np.gradient(P, t_s, axis=0)
    Pdd = np.gradient(Pd, t_s, axis=0)
    q, _, _ = track(rx130l, poses[0].rotation, P, Pd, Pdd, q0, "tcp", t_s)
    assert np.all(np.isfinite(q))
    with pytest.raises(InfeasibleError, match=r"TCP point \[.*\] m at t = .* s needs joint 1 = "):
        track(_narrowed(rx130l, q0, 0), poses[0].rotation, P, Pd, Pdd, q0, "tcp", t_s)
