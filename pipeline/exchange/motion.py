"""Sampled motions, recorded joint states and tracker points: what the exchange formats carry.

One set of dataclasses for every format (CSV, ROS 2 bags): SI units throughout, time in seconds
from the first sample, joint arrays of shape (N, n) in the order of ``joint_names``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.core.errors import DataFileError


def _as_matrix(name: str, values: np.ndarray, n_samples: int, n_joints: int) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.shape != (n_samples, n_joints):
        raise DataFileError(None, name, f"shape {array.shape}, expected ({n_samples}, {n_joints})")
    return array


def _as_times(t_s: np.ndarray) -> np.ndarray:
    times = np.asarray(t_s, dtype=float).reshape(-1)
    if times.size and not np.all(np.isfinite(times)):
        raise DataFileError(None, "t_s", "times must be finite")
    if times.size > 1 and np.any(np.diff(times) <= 0.0):
        raise DataFileError(None, "t_s", "times must increase strictly")
    return times


@dataclass(frozen=True)
class SampledMotion:
    """A joint motion sampled for a controller: q, q̇, q̈ and the feedforward torque per sample.

    ``t_s`` (N,) s from the start; ``q_rad``, ``qd_rad_s``, ``qdd_rad_s2``, ``tau_ff_Nm`` (N, n) in the
    order of ``joint_names`` (rad, rad/s, rad/s², N·m).
    """

    joint_names: tuple[str, ...]
    t_s: np.ndarray
    q_rad: np.ndarray
    qd_rad_s: np.ndarray
    qdd_rad_s2: np.ndarray
    tau_ff_Nm: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "joint_names", tuple(str(n) for n in self.joint_names))
        times = _as_times(self.t_s)
        object.__setattr__(self, "t_s", times)
        n_samples, n_joints = times.size, len(self.joint_names)
        for field in ("q_rad", "qd_rad_s", "qdd_rad_s2", "tau_ff_Nm"):
            object.__setattr__(self, field, _as_matrix(field, getattr(self, field), n_samples, n_joints))

    @property
    def n_samples(self) -> int:
        return int(self.t_s.size)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0]) if self.t_s.size else 0.0


@dataclass(frozen=True)
class JointStates:
    """Recorded joint states (``sensor_msgs/JointState`` as arrays): position, velocity, effort.

    ``t_s`` (N,) s from the first sample; ``q_rad``, ``qd_rad_s``, ``effort_Nm`` (N, n) in the order
    of ``joint_names``. A quantity a recording lacks is all NaN.
    """

    joint_names: tuple[str, ...]
    t_s: np.ndarray
    q_rad: np.ndarray
    qd_rad_s: np.ndarray
    effort_Nm: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "joint_names", tuple(str(n) for n in self.joint_names))
        times = _as_times(self.t_s)
        object.__setattr__(self, "t_s", times)
        n_samples, n_joints = times.size, len(self.joint_names)
        for field in ("q_rad", "qd_rad_s", "effort_Nm"):
            object.__setattr__(self, field, _as_matrix(field, getattr(self, field), n_samples, n_joints))

    @property
    def n_samples(self) -> int:
        return int(self.t_s.size)

    @property
    def sample_rate_hz(self) -> float:
        """The median sample rate (1 / median interval)."""
        if self.t_s.size < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.t_s)))

    def select(self, joint_names: Sequence[str]) -> JointStates:
        """These states restricted to (and ordered as) ``joint_names``."""
        index = [self.joint_names.index(name) for name in joint_names]
        return JointStates(tuple(joint_names), self.t_s, self.q_rad[:, index], self.qd_rad_s[:, index],
                           self.effort_Nm[:, index])


@dataclass(frozen=True)
class TrackerPoints:
    """Positions read by a tracker: ``t_s`` (N,) s, ``xyz_m`` (N, 3) m in the frame ``frame_id``; for 6-D
    readings (motion capture, a 6-DOF probe) ``rotvec_rad`` (N, 3), the rotation vector (axis x angle) of
    the marker frame in that frame, else None."""

    t_s: np.ndarray
    xyz_m: np.ndarray
    frame_id: str = ""
    rotvec_rad: np.ndarray | None = None

    def __post_init__(self) -> None:
        times = _as_times(self.t_s)
        object.__setattr__(self, "t_s", times)
        object.__setattr__(self, "xyz_m", _as_matrix("xyz_m", self.xyz_m, times.size, 3))
        if self.rotvec_rad is not None:
            object.__setattr__(self, "rotvec_rad", _as_matrix("rotvec_rad", self.rotvec_rad, times.size, 3))

    @property
    def n_samples(self) -> int:
        return int(self.t_s.size)
