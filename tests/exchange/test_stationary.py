"""Stationary windows of a recording: found from the joint speeds, readings averaged, scatter kept."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.core.errors import DataFileError
from pipeline.exchange.motion import JointStates, TrackerPoints
from pipeline.exchange.stationary import stationary_windows


def _recording(rate_hz: float = 100.0, dwell_s: float = 1.0, velocities: bool = True):
    """Three poses joined by 0.5 s half-cosine moves, a dwell at each; tracker readings at 20 Hz."""
    poses = np.array([[0.0, 0.0], [0.5, -0.2], [0.1, 0.4]])
    t_parts, q_parts = [], []
    clock = 0.0
    for k, pose in enumerate(poses):
        if k:
            t = np.arange(1, int(0.5 * rate_hz) + 1) / rate_hz
            s = 0.5 - 0.5 * np.cos(np.pi * t / 0.5)
            t_parts.append(clock + t)
            q_parts.append(poses[k - 1] + s[:, None] * (pose - poses[k - 1]))
            clock += 0.5
        t = np.arange(1, int(dwell_s * rate_hz) + 1) / rate_hz
        t_parts.append(clock + t)
        q_parts.append(np.tile(pose, (len(t), 1)))
        clock += dwell_s
    t, q = np.concatenate(t_parts), np.vstack(q_parts)
    qd = np.gradient(q, t, axis=0) if velocities else np.full_like(q, np.nan)
    states = JointStates(("a", "b"), t, q, qd, np.zeros_like(q))
    rng = np.random.default_rng(0)
    tp = np.arange(0.0, t[-1], 0.05)
    xyz = np.interp(tp, t, q[:, 0])[:, None] * np.ones(3) + 1e-4 * rng.normal(size=(len(tp), 3))
    return poses, states, TrackerPoints(tp, xyz, "tracker")


@pytest.mark.parametrize("velocities", [True, False])
def test_each_dwell_is_one_window_with_its_mean_and_scatter(velocities):
    poses, states, points = _recording(velocities=velocities)
    windows = stationary_windows(states, points, speed_rad_s=1e-3, min_duration_s=0.5, settle_s=0.1)
    assert windows.n_found == windows.n_used == 3
    np.testing.assert_allclose(windows.q_rad, poses, atol=1e-12)
    np.testing.assert_allclose(windows.xyz_m, poses[:, [0, 0, 0]], atol=1e-4)
    assert np.all(windows.scatter_m > 0) and np.all(windows.scatter_m < 1e-3)
    assert np.all(windows.n_readings >= 15)


def test_windows_without_enough_readings_are_found_not_used():
    _, states, points = _recording()
    windows = stationary_windows(states, points, 1e-3, 0.5, 0.1, min_readings=1)
    sparse = TrackerPoints(points.t_s[:5], points.xyz_m[:5], "tracker")   # readings only during the first dwell
    few = stationary_windows(states, sparse, 1e-3, 0.5, 0.0, min_readings=1)
    assert (few.n_found, few.n_used) == (windows.n_found, 1)
    with pytest.raises(DataFileError, match="3 windows"):
        stationary_windows(states, sparse, 1e-3, 0.5, 0.0, min_readings=10)


def test_6d_readings_get_the_mean_orientation_of_each_window():
    """Orientations scattered by 1 mrad about a pose-dependent rotation near pi (where a naive mean of
    rotation vectors flips sign) average to that rotation within the scatter's standard error."""
    poses, states, points = _recording()
    rng = np.random.default_rng(1)
    nominal = [Rotation.from_rotvec([0.0, 0.0, np.pi - 0.02 + 0.02 * k]) for k in range(3)]
    pose_of = np.clip(np.searchsorted(np.array([0.0, 1.25, 2.75]), points.t_s) - 1, 0, 2)   # each reading's dwell
    scatter = Rotation.from_rotvec(1e-3 * rng.normal(size=(points.n_samples, 3)))
    rotvec = np.array([(scatter[i] * nominal[pose_of[i]]).as_rotvec() for i in range(points.n_samples)])
    six_d = TrackerPoints(points.t_s, points.xyz_m, "mocap", rotvec)
    windows = stationary_windows(states, six_d, speed_rad_s=1e-3, min_duration_s=0.5, settle_s=0.1)
    assert windows.rotvec_rad is not None and windows.rotvec_rad.shape == (3, 3)
    for k in range(3):
        error = (Rotation.from_rotvec(windows.rotvec_rad[k]) * nominal[k].inv()).magnitude()
        assert error < 5 * 1e-3 * np.sqrt(3 / windows.n_readings[k]), (k, error)
    assert stationary_windows(states, points, 1e-3, 0.5, 0.1).rotvec_rad is None
