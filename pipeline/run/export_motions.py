"""Sampled motions of an export: joint-space moves, the excitation, re-sampled plans, the limit check.

- **moves** between two states: the quintic polynomial matching position, velocity and
  acceleration at both ends; rest to rest its peak speed is ``15/8 d/T`` and peak acceleration
  ``10/sqrt(3) d/T^2`` (d the joint's distance), so the duration starts at the smallest ``T``
  meeting ``MOVE_LIMIT_FRACTION`` of every velocity and acceleration limit and grows by 25 % until
  the samples keep that fraction, the position limits, and the same fraction of the torque that
  gravity leaves to each joint, ``|tau| <= |g| + f (tau_max - |g|)`` (the arm's torques differ from the
  model's: a move near a limit on the model saturates the drive of an arm a little heavier);
- **plans** (``t, q`` as the stages store them): q̇ and q̈ by finite differences on their own samples,
  all three interpolated linearly at the export rate (:func:`resample_plan`); a plan stored a hair
  over a velocity or acceleration limit is slowed uniformly by the factor that keeps both
  (:func:`time_scale_within`, the note says by how much);
- **torques** ``tau = M(q) q̈ + C(q, q̇) q̇ + g(q) + friction(q̇)`` of a model, row by row (RNEA);
- **check**: every sample against position, velocity, acceleration and torque limits.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import pinocchio as pin

from pipeline.core.errors import InfeasibleError
from pipeline.exchange.joint_limits import JointLimitTable
from pipeline.exchange.motion import SampledMotion
from pipeline.exchange.motion_csv import write_motion_csv
from pipeline.exchange.robot_program import ProgramFormat
from pipeline.exchange.ros2_bag import BagFormat, write_joint_trajectory
from pipeline.robot.model import RobotModel

#: joint-space moves of an export keep this fraction of every velocity and acceleration limit, and of the
#: torque that gravity leaves to each joint
MOVE_LIMIT_FRACTION = 0.5
#: durations tried for a move, each 25 % longer than the one before
MOVE_TRIES = 12
#: relative slack of the limit check on the samples (rounding of plans verified at the limit)
LIMIT_TOLERANCE = 1e-6


def model_torques(robot: RobotModel, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """(N, n) joint torques of ``robot`` on the samples: RNEA plus its friction (and load friction) model."""
    model, data = robot.model, robot.model.createData()
    tau = np.array([pin.rnea(model, data, qk, vk, ak) for qk, vk, ak in zip(q, qd, qdd, strict=True)])
    tau = tau.reshape(len(q), robot.nq) + robot.friction_torque(qd)
    if robot.spec.actuation.coulomb_load_coefficient is not None:
        tau = tau + robot.load_friction_torque(tau, qd)
    return tau


def quintic(start: Sequence[np.ndarray], end: Sequence[np.ndarray], duration_s: float,
            t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, q̇, q̈) at ``t_s`` in [0, T] of the quintic from ``start = (q0, v0, a0)`` to ``end``."""
    q0, v0, a0 = (np.asarray(x, float) for x in start)
    q1, v1, a1 = (np.asarray(x, float) for x in end)
    T = float(duration_s)
    # q(t) = c0 + c1 t + ... + c5 t^5 with the six boundary conditions (closed form)
    c0, c1, c2 = q0, v0, 0.5 * a0
    h = q1 - q0
    c3 = (20 * h - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T ** 2) / (2 * T ** 3)
    c4 = (-30 * h + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T ** 2) / (2 * T ** 4)
    c5 = (12 * h - 6 * (v1 + v0) * T - (a0 - a1) * T ** 2) / (2 * T ** 5)
    t = np.asarray(t_s, float)[:, None]
    q = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))))
    v = c1 + t * (2 * c2 + t * (3 * c3 + t * (4 * c4 + t * 5 * c5)))
    a = 2 * c2 + t * (6 * c3 + t * (12 * c4 + t * 20 * c5))
    return q, v, a


def _times(duration_s: float, rate_hz: float) -> np.ndarray:
    n = max(int(np.ceil(duration_s * rate_hz - 1e-9)), 1)
    t = np.arange(n + 1) / rate_hz
    t[-1] = duration_s
    return t if t.size < 2 or t[-1] > t[-2] else np.delete(t, -2)


def move(robot: RobotModel, limits: JointLimitTable, start: Sequence[np.ndarray], end: Sequence[np.ndarray],
         rate_hz: float, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, q, q̇, q̈) of the quintic move ``start -> end`` (states (q, v, a)) within ``MOVE_LIMIT_FRACTION``."""
    f = MOVE_LIMIT_FRACTION
    d = np.abs(np.asarray(end[0], float) - np.asarray(start[0], float))
    T = max(float(np.max(1.875 * d / (f * limits.velocity_rad_s))),
            float(np.max(np.sqrt(5.7735 * d / (f * limits.acceleration_rad_s2)))), 0.2)
    for _ in range(MOVE_TRIES):
        t = _times(T, rate_hz)
        q, v, a = quintic(start, end, T, t)
        if (np.all(np.abs(v) <= f * limits.velocity_rad_s + 1e-12)
                and np.all(np.abs(a) <= f * limits.acceleration_rad_s2 + 1e-12)
                and np.all(q >= limits.lower_rad) and np.all(q <= limits.upper_rad)):
            gravity = np.abs(model_torques(robot, q, np.zeros_like(v), np.zeros_like(a)))
            if np.all(np.abs(model_torques(robot, q, v, a)) <= gravity + f * (limits.effort_Nm - gravity)):
                return t, q, v, a
        T *= 1.25
    raise InfeasibleError(None, name, f"no move within {f:g} of the velocity and acceleration limits and of the "
                          f"torque gravity leaves, and within the position limits, found up to {T / 1.25:.3g} s "
                          "(the states at its ends are too fast or outside the limits, or gravity alone exceeds a "
                          "torque limit)")


def resample_plan(t_s: np.ndarray, q: np.ndarray, rate_hz: float) -> tuple[np.ndarray, ...]:
    """(t, q, q̇, q̈) of a stored plan at ``rate_hz``.

    q̇ and q̈ are second-order finite differences on the plan's own samples (``numpy.gradient``; a
    difference is a mean of the derivative over the neighbouring intervals, so a plan that keeps its
    limits keeps them here, where an interpolating spline overshoots at the acceleration switches of a
    time-optimal plan); all three are interpolated linearly onto the export's sample times.
    """
    t_s = np.asarray(t_s, float)
    keep = np.concatenate([[True], np.diff(t_s) > 1e-12])
    t_s, q = t_s[keep] - t_s[keep][0], np.asarray(q, float)[keep]
    order: Literal[1, 2] = 2 if len(t_s) > 2 else 1
    v = np.asarray(np.gradient(q, t_s, axis=0, edge_order=order))
    a = np.asarray(np.gradient(v, t_s, axis=0, edge_order=order))
    t = _times(float(t_s[-1]), rate_hz)

    def at(x: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, t_s, x[:, j]) for j in range(x.shape[1])])

    return t, at(q), at(v), at(a)


def time_scale_within(qd: np.ndarray, qdd: np.ndarray, limits: JointLimitTable) -> float:
    """The smallest factor >= 1 by which stretching time (q̇ / c, q̈ / c²) keeps the velocity and acceleration limits."""
    velocity = float(np.max(np.abs(qd) / limits.velocity_rad_s))
    acceleration = float(np.max(np.abs(qdd) / limits.acceleration_rad_s2))
    return max(1.0, velocity, np.sqrt(acceleration)) * (1.0 + 1e-9) if max(velocity, acceleration) > 1.0 else 1.0


def joined(robot: RobotModel, pieces: Sequence[tuple[np.ndarray, ...]], torque_robot: RobotModel) -> SampledMotion:
    """One motion of ``robot``'s joints from pieces ``(t from 0, q, q̇, q̈)`` end to end (the first sample
    of each later piece, its predecessor's last, dropped), with the torques of ``torque_robot``."""
    ts, qs, vs, accs = [], [], [], []
    offset = 0.0
    for k, (t, q, v, a) in enumerate(pieces):
        first = 0 if k == 0 else 1
        ts.append(t[first:] + offset)
        qs.append(q[first:])
        vs.append(v[first:])
        accs.append(a[first:])
        offset += float(t[-1])
    q, v, a = np.vstack(qs), np.vstack(vs), np.vstack(accs)
    return SampledMotion(tuple(str(n) for n in robot.model.names[1:]), np.concatenate(ts), q, v, a,
                         model_torques(torque_robot, q, v, a))


def check_limits(motion: SampledMotion, limits: JointLimitTable, name: str,
                 tolerance: float = LIMIT_TOLERANCE) -> None:
    """Every sample of ``motion`` within position, velocity, acceleration and torque limits, else
    :class:`InfeasibleError` naming the motion, the quantity, the joint and the time."""
    span = limits.upper_rad - limits.lower_rad
    checks = (
        ("q_rad", motion.q_rad - limits.upper_rad - tolerance * span, "above its upper position limit"),
        ("q_rad", limits.lower_rad - motion.q_rad - tolerance * span, "below its lower position limit"),
        ("qd_rad_s", np.abs(motion.qd_rad_s) - limits.velocity_rad_s * (1 + tolerance), "over its velocity limit"),
        ("qdd_rad_s2", np.abs(motion.qdd_rad_s2) - limits.acceleration_rad_s2 * (1 + tolerance),
         "over its acceleration limit"),
        ("tau_ff_Nm", np.abs(motion.tau_ff_Nm) - limits.effort_Nm * (1 + tolerance), "over its torque limit"),
    )
    for quantity, excess, what in checks:
        if not np.all(np.isfinite(getattr(motion, quantity))):
            raise InfeasibleError(None, name, f"{quantity} holds NaN or inf")
        if np.any(excess > 0):
            k, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
            value = getattr(motion, quantity)[k, j]
            raise InfeasibleError(None, name, f"{quantity} of joint {motion.joint_names[j]} is {value:.6g} at "
                                  f"t = {motion.t_s[k]:.4f} s, {what}; the motion is not exported")


def collision_free(robot: RobotModel, q: np.ndarray, margin_m: float = 0.0, stride: int = 1) -> np.ndarray:
    """(N,) bool: every ``stride``-th row of ``q`` clear of self and floor collision (the stages' capsules)."""
    rows = np.asarray(q, float)[::stride]
    segments = robot.capsule_segments(rows)
    pair, floor = robot.capsule_clearances(segments)
    ok = np.ones(len(rows), bool)
    if pair.size:
        ok &= np.min(pair.reshape(len(rows), -1), axis=1) > margin_m
    if floor.size:
        ok &= np.min(floor.reshape(len(rows), -1), axis=1) > margin_m
    return ok


@dataclass
class ExportContext:
    """What every part of an export shares."""

    run_dir: Path
    staging: Path
    nominal: RobotModel
    handed_on: RobotModel
    limits: JointLimitTable
    start_rad: np.ndarray
    rate_hz: float
    bag_format: BagFormat
    topic: str
    #: controller program formats of the calibration tour (:mod:`pipeline.exchange.robot_program`)
    programs: tuple[ProgramFormat, ...] = ()
    written: list[str] = field(default_factory=list)
    #: what the export changed or assumed, printed after the list of files
    notes: list[str] = field(default_factory=list)

    def write_motion(self, name: str, motion: SampledMotion) -> None:
        """``<name>.csv`` and the bag ``<name>/`` after the limit check on every sample."""
        check_limits(motion, self.limits, name)
        write_motion_csv(self.staging / f"{name}.csv", motion)
        write_joint_trajectory(self.staging / name, motion, self.topic, self.bag_format)
        self.written += [f"{name}.csv", f"{name}/"]
