"""What to plan: joint paths from Cartesian paths (IK) and point-to-point moves.

A continuous-path (CP) task is a Cartesian path of the TCP; it is sampled at ``n`` evenly
spaced path parameters ``s in [0, 1]``, each pose is solved by the robot's IK warm-started
from the previous solution, and a quintic interpolating spline ``q(s)`` through the IK
solutions gives ``q', q'', q'''`` (paper 004, section 5.1: the path is geometric, only its
time law is optimised).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
import pinocchio as pin
from scipy.interpolate import make_interp_spline

from pipeline.core.errors import InfeasibleError
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import ik_track, start_configuration


class SampledPath(Protocol):
    """A Cartesian path the IK follows: ``n`` poses along it (:class:`pipeline.robot.paths.CartesianPath`)."""

    def sample(self, n: int) -> list[pin.SE3]: ...


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


def joint_path_from_cartesian(robot: RobotModel, path: SampledPath, n_points: int, q_seed: np.ndarray,
                              frame: str | None = None, max_step_rad: float = np.radians(15.0),
                              name: str = "path") -> JointPath:
    """IK of a Cartesian path (``pipeline.robot.paths.CartesianPath``: line, circle, spline, ISO
    9283 piece; or any object with ``sample(n) -> list[SE3]``) into a :class:`JointPath`.

    The first pose is solved from ``q_seed`` (plus deterministic random restarts), the others
    warm-started from their neighbour (stage 3's ``ik_track``). Raises :class:`InfeasibleError`
    naming the unreachable point, or a joint jump larger than ``max_step_rad`` between neighbours
    (singularity or branch change).
    """
    frame = frame or robot.frame_tcp
    poses = path.sample(n_points)
    q0 = start_configuration(robot, poses[0], np.atleast_2d(q_seed), frame)
    Q = ik_track(robot, poses, q0, frame)
    step = np.max(np.abs(np.diff(Q, axis=0)), axis=1)
    k = int(np.argmax(step))
    if step[k] > max_step_rad:
        p = poses[k + 1].translation
        j = int(np.argmax(np.abs(Q[k + 1] - Q[k])))
        raise InfeasibleError(None, f"{name} point {k + 1} of {n_points} ([{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] m)",
                              f"joint {j + 1} jumps {np.degrees(step[k]):.1f} deg from the previous IK "
                              "sample (singularity or branch change)")
    return JointPath(np.linspace(0.0, 1.0, len(Q)), Q, name=name)


def ptp_move_from_degrees(start_deg: Sequence[float], goal_deg: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal joint vectors (rad) from degrees."""
    return np.radians(np.asarray(start_deg, float)), np.radians(np.asarray(goal_deg, float))
