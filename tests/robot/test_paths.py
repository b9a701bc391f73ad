"""Cartesian paths: arc-length parameterisation and shapes; the ISO 9283 geometry."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pipeline.control.validate import registered_error
from pipeline.core.errors import ConfigError
from pipeline.robot.iso9283 import iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import (
    CirclePath,
    LinePath,
    PolylinePath,
    SplinePath,
    joint_path,
    pose_error,
    rectangle,
    start_configuration,
)


@pytest.mark.parametrize("path", [
    LinePath([0, 0, 0], [0.3, 0.4, 0.0]),
    CirclePath([1, 0, 0.5], [0, 0, 1], 0.2, [1, 0, 0], np.pi),
    rectangle([[0, 0, 0], [0.4, 0, 0], [0.4, 0.2, 0], [0, 0.2, 0]]),
    SplinePath([[0, 0, 0], [0.2, 0.1, 0], [0.4, 0.0, 0.1], [0.6, 0.2, 0.1]]),
])
def test_arc_length_parameterisation(path):
    s = np.linspace(0, path.length_m, 4001)
    p = path.position(s)
    chord = np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1))
    assert chord == pytest.approx(path.length_m, rel=2e-4)
    d1, d2 = path.derivatives(s)
    np.testing.assert_allclose(np.linalg.norm(d1, axis=1), 1.0, atol=1e-3)
    fd = np.gradient(p, s, axis=0)
    inner = slice(5, -5)
    assert np.median(np.linalg.norm(fd[inner] - d1[inner], axis=1)) < 1e-3
    poses = path.sample(11)
    assert len(poses) == 11
    np.testing.assert_allclose(poses[-1].translation, path.position([path.length_m])[0], atol=1e-9)


def test_circle_radius_and_curvature():
    c = CirclePath([1, 0, 0.5], [0, 1, 1], 0.1, [1, 0, 0])
    p = c.position(np.linspace(0, c.length_m, 50))
    np.testing.assert_allclose(np.linalg.norm(p - c.centre, axis=1), 0.1)
    assert c.max_curvature_1_m() == pytest.approx(10.0)
    assert c.length_m == pytest.approx(2 * np.pi * 0.1)


def test_polyline_segments_and_bad_input():
    r = rectangle([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    assert len(r.segments()) == 4 and r.length_m == pytest.approx(4.0)
    with pytest.raises(ConfigError):
        LinePath([0, 0, 0], [0, 0, 0])
    with pytest.raises(ConfigError):
        PolylinePath([[0, 0, 0]])


@pytest.mark.parametrize("plane", ["diagonal_x", "diagonal_y"])
def test_iso9283_geometry(plane):
    L = 0.5
    c = np.array([0.9, 0.1, 0.4])
    path = iso9283_path(None, L, c, plane)
    P = path.points
    np.testing.assert_allclose(P["P1"], c)
    # corners C1..C4 are cube corners: each coordinate is centre +- L/2
    for k in ("C1", "C2", "C3", "C4"):
        np.testing.assert_allclose(np.abs(P[k] - c), L / 2, atol=1e-12)
    # P2..P5 on the diagonals, 10 % of the diagonal length from the corners
    for pk, ck, opp in (("P2", "C1", "C3"), ("P3", "C2", "C4"), ("P4", "C3", "C1"), ("P5", "C4", "C2")):
        diag = P[opp] - P[ck]
        np.testing.assert_allclose(P[pk], P[ck] + 0.1 * diag, atol=1e-12)
    # all points in one plane through the centre
    n = np.cross(P["C2"] - P["C1"], P["C4"] - P["C1"])
    for p in P.values():
        assert abs(np.dot(p - c, n)) < 1e-12
    labels = [s.label for s in path.segments()]
    assert labels[0] == "line P2-P4" and "circle_large" in labels and "circle_small" in labels
    circles = {s.label: s for s in path.segments() if s.label.startswith("circle")}
    assert 2 * circles["circle_large"].radius_m == pytest.approx(0.8 * L)
    assert 2 * circles["circle_small"].radius_m == pytest.approx(0.1 * L)
    # continuity: each piece starts where the previous one ended
    segs = path.segments()
    for a, b in zip(segs[:-1], segs[1:], strict=True):
        np.testing.assert_allclose(a.position([a.length_m])[0], b.position([0.0])[0], atol=1e-12)


def test_joint_path_follows_the_poses(rx130l):
    down = pin.utils.rotate("x", np.pi)
    line = LinePath([0.8, -0.2, 0.3], [1.0, 0.2, 0.5], rotation=down)
    q0 = start_configuration(rx130l, line.poses([0.0])[0], np.radians([[0.0, 17.0, 86.0, 0.0, 75.0, 0.0]]))
    Q = joint_path(rx130l, line, 41, q0)
    np.testing.assert_allclose(rx130l.positions(Q), line.position(np.linspace(0, line.length_m, 41)), atol=1e-8)
    assert np.abs(np.diff(Q, axis=0)).max() < 0.1  # warm start keeps one IK branch


def test_registered_error_removes_rigid_motion_only():
    rng = np.random.default_rng(0)
    P = rng.uniform(-0.3, 0.3, (200, 3))
    T = pin.exp6(np.array([0.01, -0.02, 0.005, 0.01, 0.02, -0.01]))
    moved = P @ T.rotation.T + T.translation
    assert registered_error(moved, P).max() < 1e-12
    bent = moved.copy()
    bent[:, 2] += 1e-3 * P[:, 0] ** 2 / 0.09  # a non-rigid deformation stays visible
    assert registered_error(bent, P).max() > 1e-4


@pytest.mark.parametrize("name", ["rx130l", "staubli_tx40", "kuka_kr15"])
def test_pose_error_kinematics_are_the_full_forward_kinematics(name):
    """The IK's pose error and Jacobian come from one kinematic pass (the Jacobian's, along the frame's
    support): number for number what full forward kinematics and the frame Jacobian give."""
    robot = RobotModel.load(name)
    model, data, ref = robot.model, robot.model.createData(), robot.model.createData()
    rng = np.random.default_rng(5)
    for frame in (robot.frame_tcp, robot.frame_reflector, robot.frame_flange):
        fid = model.getFrameId(frame)
        for _ in range(50):
            q = rng.uniform(robot.limits.lower_rad, robot.limits.upper_rad)
            target = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
            e, J = pose_error(robot, model, data, fid, frame, q, target)
            pin.framesForwardKinematics(model, ref, q)
            cur = ref.oMf[fid]
            assert np.array_equal(e, np.concatenate([target.translation - cur.translation,
                                                      pin.log3(target.rotation @ cur.rotation.T)]))
            assert np.array_equal(J, pin.computeFrameJacobian(model, ref, q, fid, pin.LOCAL_WORLD_ALIGNED))
