"""Stationary windows of a recording: where the joints stood still, the tracker's readings averaged.

A sample is stationary when every joint's speed is at most ``speed_rad_s``: the displacement of the
logged position over ``SPEED_WINDOW_S`` centred on the sample, divided by its duration,
``|q(t + w/2) - q(t - w/2)| / w`` (the mean velocity over the window, whatever the log rate: a drive's
velocity estimate is noisy at rest, and a few logged samples of it average to far more than the
encoder's noise over the window, ``sqrt(2) sigma_enc / w``). A window is a run of stationary
samples lasting at least ``min_duration_s``; its first ``settle_s`` are skipped (the arm settling),
and the tracker readings inside the rest are averaged, their scatter (RMS distance from the mean)
kept (NaN for a single reading); 6-D readings' orientations are averaged too (the chordal L2 mean of
the rotations, scipy's ``Rotation.mean``: Markley, Cheng, Crassidis & Oshman 2007, "Averaging
quaternions", J. Guidance, Control, and Dynamics 30(4)). Readings up to half a joint-state interval
plus half the speed window after the window's last sample count (a reading taken as the dwell ends).
A window with fewer than ``min_readings`` readings is found but not used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.core.errors import DataFileError
from pipeline.exchange.motion import JointStates, TrackerPoints


@dataclass(frozen=True)
class StationaryWindows:
    """The used windows: mean joint positions (W, n) rad, mean reading (W, 3) m, scatter (W,) m; for 6-D
    readings the mean orientation (W, 3), a rotation vector, else None."""

    q_rad: np.ndarray
    xyz_m: np.ndarray
    scatter_m: np.ndarray
    n_readings: np.ndarray
    t_start_s: np.ndarray
    t_end_s: np.ndarray
    n_found: int
    rotvec_rad: np.ndarray | None = None

    @property
    def n_used(self) -> int:
        return int(self.q_rad.shape[0])


#: the joint velocities are averaged over this window (s) before the speed threshold
SPEED_WINDOW_S = 0.1


def joint_speeds(states: JointStates, window_s: float = SPEED_WINDOW_S) -> np.ndarray:
    """(N, n) joint speeds: ``|q[k + h] - q[k - h]| / (t[k + h] - t[k - h])`` with ``h`` half the window in
    samples (at least 1; indices clipped to the record), the mean speed over ``window_s`` about each sample."""
    q, t = np.asarray(states.q_rad, float), np.asarray(states.t_s, float)
    n = len(t)
    if n < 2:
        return np.zeros_like(q)
    half = max(int(round(0.5 * window_s * states.sample_rate_hz)), 1)
    k = np.arange(n)
    hi, lo = np.minimum(k + half, n - 1), np.maximum(k - half, 0)
    return np.abs(q[hi] - q[lo]) / (t[hi] - t[lo])[:, None]


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
    orientations: list[np.ndarray] = []
    half_interval = 0.5 * float(np.median(np.diff(states.t_s))) if states.n_samples > 1 else 0.0
    # the speed over the window ends a window up to half its width before the arm moves again
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
        if points.rotvec_rad is not None:
            orientations.append(Rotation.from_rotvec(points.rotvec_rad[inside]).mean().as_rotvec())
    if not rows:
        raise DataFileError(source, "stationary windows",
                            f"{len(runs)} windows of at least {min_duration_s:g} s with every joint slower than "
                            f"{speed_rad_s:g} rad/s found, none with {min_readings} tracker readings after "
                            f"{settle_s:g} s of settling")
    columns = [np.array(c) for c in zip(*rows, strict=True)]
    return StationaryWindows(columns[0].reshape(len(rows), -1), columns[1].reshape(len(rows), 3), columns[2],
                             columns[3], columns[4], columns[5], len(runs),
                             np.array(orientations).reshape(len(rows), 3) if points.rotvec_rad is not None else None)
