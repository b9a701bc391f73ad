"""The calibration's residual map in the robot's kinematics: tool-frame FK, Jacobian, IK and the
joint reference all see the calibrated model plus the map; the map travels with a handed-on robot."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration.residual_map import fit_residual_map
from pipeline.robot.exact import load_exact_robot, robots_equal, save_exact_robot
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import ik_track, start_configuration
from pipeline.robot.reference import track
from pipeline.robot.residual_map import ResidualMap


@pytest.fixture(scope="module")
def q_ready() -> np.ndarray:
    return np.radians([10.0, -30.0, 80.0, 5.0, 40.0, 20.0])


@pytest.fixture(scope="module")
def rmap(q_ready) -> ResidualMap:
    """A smooth millimetre field over joint space fitted around ``q_ready`` (the map of a calibration)."""
    rng = np.random.default_rng(0)
    Q = q_ready + rng.uniform(-0.6, 0.6, (40, 6))
    field = 1e-3 * np.column_stack([np.sin(Q[:, 0] + Q[:, 1]), np.cos(Q[:, 2]), np.sin(Q[:, 1] - Q[:, 4])])
    return fit_residual_map(Q, field + 1e-6 * rng.standard_normal(field.shape), rng)


@pytest.fixture(scope="module")
def mapped(rx130l, rmap) -> RobotModel:
    robot = rx130l.copy()
    robot.residual_map = rmap
    return robot


def test_map_derivatives_match_finite_differences(rmap, q_ready):
    h = 1e-6
    J = rmap.jacobian(q_ready)
    fd = np.column_stack([(rmap.mean(q_ready + h * e) - rmap.mean(q_ready - h * e)) / (2 * h) for e in np.eye(6)])
    assert np.abs(J).max() > 1e-4 and np.allclose(J, fd, atol=1e-9)
    v = np.array([0.3, -0.2, 0.5, 0.1, -0.4, 0.2])
    second = (rmap.mean(q_ready + 1e-4 * v) - 2 * rmap.mean(q_ready) + rmap.mean(q_ready - 1e-4 * v)) / 1e-8
    assert np.allclose(rmap.drift(q_ready, v), second, atol=1e-7)


def test_tool_frames_carry_the_map_and_other_frames_do_not(rx130l, mapped, rmap, q_ready):
    shift = rmap.mean(q_ready)
    assert np.linalg.norm(shift) > 1e-4
    for frame in (mapped.frame_tcp, mapped.frame_reflector, mapped.frame_flange):
        rigid = rx130l.fk(q_ready, frame)
        assert np.allclose(mapped.fk(q_ready, frame).translation, rigid.translation + shift, atol=1e-15)
        assert np.allclose(mapped.fk(q_ready, frame).rotation, rigid.rotation)
        assert np.allclose(mapped.positions(q_ready[None], frame)[0], rigid.translation + shift, atol=1e-15)
        assert np.allclose(mapped.poses(q_ready[None], frame)[0][0], rigid.translation + shift, atol=1e-15)
    other = rx130l.model.frames[rx130l.model.getFrameId(mapped.frame_flange) - 3].name
    assert np.array_equal(mapped.fk(q_ready, other).translation, rx130l.fk(q_ready, other).translation)
    # the Jacobian's linear rows are the derivative of the corrected position
    h = 1e-6
    fd = np.column_stack([(mapped.fk(q_ready + h * e).translation - mapped.fk(q_ready - h * e).translation) / (2 * h)
                          for e in np.eye(6)])
    assert np.allclose(mapped.jacobian(q_ready)[:3], fd, atol=1e-8)


def test_the_map_travels_with_copies_and_the_saved_robot(rx130l, mapped, tmp_path):
    assert mapped.copy().residual_map is mapped.residual_map
    assert mapped.with_model(mapped.model.copy()).residual_map is mapped.residual_map
    loaded = load_exact_robot(save_exact_robot(mapped, tmp_path / "robot"))
    assert loaded.residual_map is not None and robots_equal(loaded, mapped)
    assert not robots_equal(loaded, rx130l)
    # a robot without a map saved over the folder leaves none behind
    assert load_exact_robot(save_exact_robot(rx130l, tmp_path / "robot")).residual_map is None


def test_ik_reaches_targets_of_the_corrected_model(rx130l, mapped, rmap, q_ready):
    target = mapped.fk(q_ready)
    seed = q_ready + 0.05
    for q in (start_configuration(mapped, target, seed, n_random=0), mapped.ik(target, seed).q,
              ik_track(mapped, [target], seed)[0]):
        assert np.linalg.norm(mapped.fk(q).translation - target.translation) < 1e-8
        # the rigid model alone misses the target by the map's correction there
        assert np.linalg.norm(rx130l.fk(q).translation - target.translation) == pytest.approx(
            np.linalg.norm(rmap.mean(q)), rel=1e-3)


def test_joint_reference_follows_the_corrected_path(mapped, q_ready):
    """The ISO-path reference (pipeline.robot.reference.track): corrected positions on the path and
    ``J v = p_dot`` with the map's Jacobian rows."""
    start = mapped.fk(q_ready)
    t = np.linspace(0.0, 0.5, 51)
    s = 0.05 * (10 * (t / 0.5) ** 3 - 15 * (t / 0.5) ** 4 + 6 * (t / 0.5) ** 5)
    sd = 0.05 * (30 * t ** 2 / 0.5 ** 3 - 60 * t ** 3 / 0.5 ** 4 + 30 * t ** 4 / 0.5 ** 5)
    sdd = 0.05 * (60 * t / 0.5 ** 3 - 180 * t ** 2 / 0.5 ** 4 + 120 * t ** 3 / 0.5 ** 5)
    direction = np.array([1.0, 0.0, 0.0])
    P = start.translation + s[:, None] * direction
    q, v, a = track(mapped, start.rotation, P, sd[:, None] * direction, sdd[:, None] * direction, q_ready,
                    mapped.frame_tcp, t)
    assert np.abs(mapped.positions(q) - P).max() < 1e-8
    for k in (10, 25, 40):
        assert np.allclose(mapped.jacobian(q[k])[:3] @ v[k], sd[k] * direction, atol=1e-9)
    # accelerations: finite differences of the velocities
    assert np.abs(np.gradient(v, t, axis=0)[5:-5] - a[5:-5]).max() < 0.05 * np.abs(a).max()
