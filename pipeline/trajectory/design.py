"""What to plan: joint paths from Cartesian paths (IK) and point-to-point moves.

A continuous-path (CP) task is a Cartesian path of the TCP; it is sampled at ``n`` evenly
spaced path parameters ``s in [0, 1]``, each pose is solved by the robot's IK warm-started
from the previous solution, and a quintic interpolating spline ``q(s)`` through the IK
solutions gives ``q', q'', q'''`` (paper 004, section 5.1: the path is geometric, only its
time law is optimised).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin
from scipy.interpolate import make_interp_spline

from pipeline.errors import InfeasibleError


class JointPath:
    """Joint path ``q(s)``, ``s in [0, 1]``, a C^4 quintic spline through samples."""

    def __init__(self, s: np.ndarray, q: np.ndarray, name: str = "path") -> None:
        s = np.asarray(s, float)
        q = np.asarray(q, float)
        if s.ndim != 1 or q.shape[0] != s.size or s.size < 6:
            raise InfeasibleError(None, name, f"need >= 6 path samples, got {s.size}")
        if np.any(np.diff(s) <= 0):
            raise InfeasibleError(None, name, "path parameters must increase strictly")
        self.name = name
        self.s_knots = s
        self.q_knots = q
        self.spline = make_interp_spline(s, q, k=5)
        self.nq = q.shape[1]

    def __call__(self, s: np.ndarray | float, order: int = 0) -> np.ndarray:
        s = np.clip(np.asarray(s, float), self.s_knots[0], self.s_knots[-1])
        return self.spline(s, nu=order) if order else self.spline(s)

    def derivatives(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q', q'' at s (each (N, nq)); q' below QPRIME_ZERO set to 0 (Coulomb sign noise)."""
        q, dq, ddq = self(s), self(s, 1), self(s, 2)
        dq = np.where(np.abs(dq) < 1e-9, 0.0, dq)
        return q, dq, ddq


@dataclass
class PoseSequencePath:
    """A Cartesian path given as a list of TCP poses at evenly spaced path parameters."""

    poses: list[pin.SE3]
    name: str = "poses"

    def sample(self, n: int) -> list[pin.SE3]:
        """Interpolate the poses (piecewise geodesic on SE(3)) at ``n`` even parameters."""
        k = len(self.poses) - 1
        out = []
        for u in np.linspace(0.0, k, n):
            i = min(int(np.floor(u)), k - 1)
            frac = u - i
            out.append(self.poses[i] * pin.exp6(frac * pin.log6(self.poses[i].actInv(self.poses[i + 1]))))
        return out

    @property
    def length_m(self) -> float:
        return float(sum(np.linalg.norm(b.translation - a.translation)
                         for a, b in zip(self.poses[:-1], self.poses[1:])))


def line_path(start: pin.SE3, end: pin.SE3) -> PoseSequencePath:
    """Straight line of the TCP with geodesic orientation change."""
    return PoseSequencePath([start, end], name="line")


def joint_path_from_cartesian(robot: Any, path: Any, q_start: np.ndarray, n_points: int = 120,
                              frame: str = "tcp", max_step_rad: float = 0.25,
                              name: str = "path") -> JointPath:
    """IK of ``path.sample(n_points)`` (or a list of poses) into a :class:`JointPath`.

    Raises :class:`InfeasibleError` naming the first unreachable sample (IK failure, joint
    limit) or a configuration jump larger than ``max_step_rad`` between neighbours.
    """
    poses = path.sample(n_points) if hasattr(path, "sample") else list(path)
    n = len(poses)
    s = np.linspace(0.0, 1.0, n)
    q = np.asarray(q_start, float).copy()
    Q = np.empty((n, robot.nq))
    for k, pose in enumerate(poses):
        res = robot.ik(pose, q, frame=frame)
        p = pose.translation
        where = f"{name} point {k} of {n} (s={s[k]:.3f}, xyz=[{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] m)"
        if not res.success:
            raise InfeasibleError(None, where, f"unreachable: IK failed ({res.message}, "
                                  f"position error {res.position_error_m:.2e} m)")
        qk = np.asarray(res.q, float)
        if not robot.within_limits(qk):
            raise InfeasibleError(None, where, "IK solution outside the joint limits")
        if k > 0 and np.max(np.abs(qk - Q[k - 1])) > max_step_rad:
            j = int(np.argmax(np.abs(qk - Q[k - 1])))
            raise InfeasibleError(None, where, f"joint {j + 1} jumps "
                                  f"{np.degrees(abs(qk[j] - Q[k - 1][j])):.1f} deg between path "
                                  "samples (singularity or branch change)")
        Q[k] = qk
        q = qk
    return JointPath(s, Q, name=name)


def ptp_move_from_degrees(start_deg: Sequence[float], goal_deg: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal joint vectors (rad) from degrees."""
    return np.radians(np.asarray(start_deg, float)), np.radians(np.asarray(goal_deg, float))
