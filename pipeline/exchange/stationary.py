"""Stationary windows of a recording: where the joints stood still, the tracker's readings averaged.

A sample is stationary when every joint's speed is at most ``speed_rad_s``: the logged velocities
(or central differences of the positions when the log has none) averaged over ``SPEED_WINDOW_S``
about the sample (a drive's velocity estimate is noisy at rest; its mean over the window is the
displacement over the window). A window is a run of stationary
samples lasting at least ``min_duration_s``; its first ``settle_s`` are skipped (the arm settling),
and the tracker readings inside the rest are averaged, their scatter (RMS distance from the mean)
kept (NaN for a single reading). Readings up to half a joint-state interval plus half the speed
window after the window's last sample count (a reading taken as the dwell ends). A window with
fewer than ``min_readings`` readings is found but not used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from pipeline.core.errors import DataFileError
from pipeline.exchange.motion import JointStates, TrackerPoints


@dataclass(frozen=True)
class StationaryWindows:
    """The used windows: mean joint positions (W, n) rad, mean reading (W, 3) m, scatter (W,) m."""

    q_rad: np.ndarray
    xyz_m: np.ndarray
    scatter_m: np.ndarray
    n_readings: np.ndarray
    t_start_s: np.ndarray
    t_end_s: np.ndarray
    n_found: int

    @property
    def n_used(self) -> int:
        return int(self.q_rad.shape[0])


#: the joint velocities are averaged over this window (s) before the speed threshold
SPEED_WINDOW_S = 0.1


def joint_speeds(states: JointStates, window_s: float = SPEED_WINDOW_S) -> np.ndarray:
    """(N, n) joint speeds: the logged velocities, or differences of the positions where they are NaN,
    averaged over ``window_s`` (centred moving mean), absolute."""
    velocity = np.asarray(states.qd_rad_s, float)
    if states.n_samples > 1 and not np.all(np.isfinite(velocity)):
        numeric = np.gradient(states.q_rad, states.t_s, axis=0)
        velocity = np.where(np.isfinite(velocity), velocity, numeric)
    if states.n_samples > 2:
        width = max(int(round(window_s * states.sample_rate_hz)), 1)
        velocity = uniform_filter1d(velocity, width, axis=0, mode="nearest")
    return np.abs(velocity)


def stationary_windows(states: JointStates, points: TrackerPoints, speed_rad_s: float = 2e-3,
                       min_duration_s: float = 0.5, settle_s: float = 0.1, min_readings: int = 1,
                       source: str | None = None) -> StationaryWindows:
    """The windows where the arm stood still and the tracker readings of each (module docstring)."""
    still = np.all(joint_speeds(states) <= speed_rad_s, axis=1)
    edges = np.diff(np.concatenate([[0], still.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    runs = [(a, b) for a, b in zip(starts, ends, strict=True)
            if states.t_s[b] - states.t_s[a] >= min_duration_s]
    rows: list[tuple[np.ndarray, np.ndarray, float, int, float, float]] = []
    half_interval = 0.5 * float(np.median(np.diff(states.t_s))) if states.n_samples > 1 else 0.0
    # the moving mean of the speeds ends a window up to half its width before the arm moves again
    late = half_interval + 0.5 * SPEED_WINDOW_S
    for a, b in runs:
        t0, t1 = states.t_s[a] + settle_s, states.t_s[b] + late
        inside = (points.t_s >= t0) & (points.t_s <= t1)
        if int(inside.sum()) < min_readings:
            continue
        q_in = states.q_rad[a:b + 1][states.t_s[a:b + 1] >= t0 - half_interval]
        xyz = points.xyz_m[inside]
        mean = xyz.mean(axis=0)
        scatter = float(np.sqrt(np.mean(np.sum((xyz - mean) ** 2, axis=1)))) if len(xyz) > 1 else float("nan")
        rows.append((q_in.mean(axis=0), mean, scatter, int(inside.sum()), float(t0), float(t1)))
    if not rows:
        raise DataFileError(source, "stationary windows",
                            f"{len(runs)} windows of at least {min_duration_s:g} s with every joint slower than "
                            f"{speed_rad_s:g} rad/s found, none with {min_readings} tracker readings after "
                            f"{settle_s:g} s of settling")
    columns = [np.array(c) for c in zip(*rows, strict=True)]
    return StationaryWindows(columns[0].reshape(len(rows), -1), columns[1].reshape(len(rows), 3), columns[2],
                             columns[3], columns[4], columns[5], len(runs))
