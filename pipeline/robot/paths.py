"""Cartesian TCP paths parameterised by arc length ``s`` (metres).

Every path gives the position ``p(s)``, its derivatives ``p'(s)`` (unit tangent) and ``p''(s)``
(curvature vector) and a TCP orientation ``R(s)`` (constant here, as on the EN ISO 9283 test
path, DESIGN.md). With a speed profile ``s(t)`` the Cartesian velocity and acceleration are
``p_dot = p' s_dot`` and ``p_ddot = p'' s_dot^2 + p' s_ddot``.

Shapes: :class:`LinePath`, :class:`CirclePath`, :class:`PolylinePath` (its corners are stops:
:meth:`PolylinePath.segments`), :func:`rectangle`, :class:`SplinePath` (cubic spline through
points, re-parameterised by arc length numerically). A joint path follows with
:func:`joint_path` (IK at every sample, warm-started from the previous one).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from scipy.interpolate import CubicSpline

from pipeline.core.errors import ConfigError, InfeasibleError
from pipeline.robot.model import RobotModel


def _as3(x: npt.ArrayLike, name: str) -> np.ndarray:
    a = np.asarray(x, float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ConfigError(None, name, f"needs 3 finite numbers, got {x!r}")
    return a


def _as_rotation(R: npt.ArrayLike | None) -> np.ndarray:
    R = np.eye(3) if R is None else np.asarray(R, float)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise ConfigError(None, "rotation", "TCP rotation must be a proper 3x3 rotation matrix")
    return R


class CartesianPath(ABC):
    """A TCP path ``p(s)``, ``s`` in ``[0, length_m]``, with constant orientation ``rotation``."""

    length_m: float
    rotation: np.ndarray
    label: str = ""

    @abstractmethod
    def position(self, s_m: np.ndarray) -> np.ndarray:
        """(N, 3) positions at arc lengths ``s_m`` (N,)."""

    @abstractmethod
    def derivatives(self, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(p'(s), p''(s)), each (N, 3)."""

    def poses(self, s_m: np.ndarray) -> list[pin.SE3]:
        return [pin.SE3(self.rotation, p) for p in self.position(np.atleast_1d(s_m))]

    def sample(self, n: int) -> list[pin.SE3]:
        """``n`` poses equally spaced in arc length (ends included)."""
        if n < 2:
            raise ConfigError(None, "n", "sample needs n >= 2")
        return self.poses(np.linspace(0.0, self.length_m, n))

    def max_curvature_1_m(self) -> float:
        s = np.linspace(0.0, self.length_m, 201)
        return float(np.max(np.linalg.norm(self.derivatives(s)[1], axis=1)))

    def segments(self) -> list[CartesianPath]:
        """Pieces with continuous tangent (the path stops between them)."""
        return [self]


class LinePath(CartesianPath):
    def __init__(self, p0: npt.ArrayLike, p1: npt.ArrayLike, rotation: npt.ArrayLike | None = None,
                 label: str = "line") -> None:
        self.p0, self.p1 = _as3(p0, "line.p0"), _as3(p1, "line.p1")
        self.length_m = float(np.linalg.norm(self.p1 - self.p0))
        if self.length_m <= 0:
            raise ConfigError(None, "line", "start and end points coincide")
        self.direction = (self.p1 - self.p0) / self.length_m
        self.rotation = _as_rotation(rotation)
        self.label = label

    def position(self, s_m: npt.ArrayLike) -> np.ndarray:
        s = np.atleast_1d(np.asarray(s_m, float))
        return self.p0 + s[:, None] * self.direction

    def derivatives(self, s_m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        n = len(np.atleast_1d(s_m))
        return np.tile(self.direction, (n, 1)), np.zeros((n, 3))


class CirclePath(CartesianPath):
    """Circle (arc) of ``radius_m`` about ``centre`` in the plane with unit ``normal``, starting at
    ``centre + radius * start_direction`` and turning by ``angle_rad`` (right-handed about normal)."""

    def __init__(self, centre: npt.ArrayLike, normal: npt.ArrayLike, radius_m: float,
                 start_direction: npt.ArrayLike, angle_rad: float = 2 * np.pi,
                 rotation: npt.ArrayLike | None = None, label: str = "circle") -> None:
        self.centre = _as3(centre, "circle.centre")
        n = _as3(normal, "circle.normal")
        if radius_m <= 0 or angle_rad <= 0:
            raise ConfigError(None, "circle", "radius and angle must be > 0")
        self.normal = n / np.linalg.norm(n)
        e1 = _as3(start_direction, "circle.start_direction")
        e1 = e1 - self.normal * (e1 @ self.normal)
        if np.linalg.norm(e1) < 1e-9:
            raise ConfigError(None, "circle.start_direction", "parallel to the normal")
        self.e1 = e1 / np.linalg.norm(e1)
        self.e2 = np.cross(self.normal, self.e1)
        self.radius_m = float(radius_m)
        self.angle_rad = float(angle_rad)
        self.length_m = self.radius_m * self.angle_rad
        self.rotation = _as_rotation(rotation)
        self.label = label

    def position(self, s_m: npt.ArrayLike) -> np.ndarray:
        th = np.atleast_1d(np.asarray(s_m, float)) / self.radius_m
        return self.centre + self.radius_m * (np.cos(th)[:, None] * self.e1 + np.sin(th)[:, None] * self.e2)

    def derivatives(self, s_m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        th = np.atleast_1d(np.asarray(s_m, float)) / self.radius_m
        d1 = -np.sin(th)[:, None] * self.e1 + np.cos(th)[:, None] * self.e2
        d2 = (-np.cos(th)[:, None] * self.e1 - np.sin(th)[:, None] * self.e2) / self.radius_m
        return d1, d2


class PolylinePath(CartesianPath):
    """Straight lines through ``points`` (M, 3); the TCP stops at every corner."""

    def __init__(self, points: npt.ArrayLike, rotation: npt.ArrayLike | None = None, label: str = "polyline") -> None:
        pts = np.asarray(points, float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
            raise ConfigError(None, "polyline.points", "needs (M >= 2, 3) points")
        self.rotation = _as_rotation(rotation)
        self.lines = [LinePath(a, b, self.rotation, f"{label}[{i}]") for i, (a, b) in enumerate(zip(pts[:-1], pts[1:],
                                                                                                   strict=True))]
        self.breaks = np.concatenate([[0.0], np.cumsum([ln.length_m for ln in self.lines])])
        self.length_m = float(self.breaks[-1])
        self.label = label

    def _locate(self, s_m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        s = np.clip(np.atleast_1d(np.asarray(s_m, float)), 0.0, self.length_m)
        idx = np.clip(np.searchsorted(self.breaks, s, side="right") - 1, 0, len(self.lines) - 1)
        return s, idx

    def position(self, s_m: npt.ArrayLike) -> np.ndarray:
        s, idx = self._locate(s_m)
        out = np.empty((len(s), 3))
        for i, ln in enumerate(self.lines):
            m = idx == i
            out[m] = ln.position(s[m] - self.breaks[i])
        return out

    def derivatives(self, s_m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        s, idx = self._locate(s_m)
        d1 = np.array([self.lines[i].direction for i in idx]).reshape(-1, 3)
        return d1, np.zeros_like(d1)

    def segments(self) -> list[CartesianPath]:
        return list(self.lines)


def rectangle(corners: npt.ArrayLike, rotation: npt.ArrayLike | None = None, close: bool = True,
              label: str = "rectangle") -> PolylinePath:
    """Polyline through the corners (4, 3), closed back to the first one."""
    c = np.asarray(corners, float)
    if c.shape != (4, 3):
        raise ConfigError(None, "rectangle.corners", "needs 4 corners (4, 3)")
    return PolylinePath(np.vstack([c, c[:1]]) if close else c, rotation, label)


class SplinePath(CartesianPath):
    """Cubic spline through ``points`` (chord-length knots), re-parameterised by arc length."""

    def __init__(self, points: npt.ArrayLike, rotation: npt.ArrayLike | None = None, n_table: int = 2001,
                 label: str = "spline") -> None:
        pts = np.asarray(points, float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
            raise ConfigError(None, "spline.points", "needs (M >= 3, 3) points")
        chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        if np.any(np.diff(chord) <= 0):
            raise ConfigError(None, "spline.points", "consecutive points coincide")
        self._cs = CubicSpline(chord, pts, axis=0, bc_type="natural")
        u = np.linspace(0.0, chord[-1], n_table)
        speed = np.linalg.norm(self._cs(u, 1), axis=1)
        s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(u))])
        self._u_of_s = CubicSpline(s, u)
        self.length_m = float(s[-1])
        self.rotation = _as_rotation(rotation)
        self.label = label

    def position(self, s_m: npt.ArrayLike) -> np.ndarray:
        return self._cs(self._u_of_s(np.clip(np.atleast_1d(s_m), 0, self.length_m)))

    def derivatives(self, s_m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        s = np.clip(np.atleast_1d(np.asarray(s_m, float)), 0, self.length_m)
        u = self._u_of_s(s)
        du = self._cs(u, 1)
        ddu = self._cs(u, 2)
        sp = np.linalg.norm(du, axis=1)[:, None]
        t = du / sp
        # p'' = (I - t t^T) x_uu / |x_u|^2
        acc = (ddu - t * np.sum(t * ddu, axis=1, keepdims=True)) / sp**2
        return t, acc


def ik_track(robot: RobotModel, poses: list[pin.SE3], q0: np.ndarray, frame: str = "tcp", tolerance_m: float = 1e-9,
             max_iterations: int = 50, times_s: np.ndarray | None = None) -> np.ndarray:
    """IK at every pose, warm-started from the previous solution (damped least squares on Pinocchio).

    Newton step ``dq = J^T (J J^T + lambda^2 I)^-1 e`` with the 6D error ``e = [p* - p, log3(R* R^T)]``
    (LOCAL_WORLD_ALIGNED Jacobian). Raises InfeasibleError naming the time/index and point when a
    pose is not reached or a joint leaves its limits.
    """
    model = robot.model
    data = model.createData()
    fid = model.getFrameId(frame)
    q = np.array(q0, float)
    out = np.empty((len(poses), model.nq))
    lam2 = 1e-12
    for k, T in enumerate(poses):
        err_n = np.inf
        for _ in range(max_iterations):
            e, J = pose_error(robot, model, data, fid, frame, q, T)
            err_n = float(np.linalg.norm(e[:3]) + 0.1 * np.linalg.norm(e[3:]))
            if err_n < tolerance_m:
                break
            q = q + J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(6), e)
        if err_n >= max(tolerance_m * 100, 1e-7):
            where = f"t = {times_s[k]:.4f} s" if times_s is not None else f"sample {k}"
            p = np.array2string(T.translation, precision=4)
            raise InfeasibleError(None, "ik", f"TCP point {p} m at {where} not reached (error {err_n:.2e} m; "
                                  f"{limiting_joint(robot, q)})")
        out[k] = q
    out = wrap_into_limits(robot, out)
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    for k in np.nonzero(np.any((out < lo) | (out > hi), axis=1))[0][:1]:   # the first sample outside, if any
        where = f"t = {times_s[k]:.4f} s" if times_s is not None else f"sample {k}"
        point = np.array2string(poses[k].translation, precision=4)
        check_within_limits(robot, out[k], f"TCP point {point} m at {where}")
    return out


def pose_error(robot: RobotModel, model: pin.Model, data: pin.Data, fid: int, frame: str, q: np.ndarray,
               target: pin.SE3) -> tuple[np.ndarray, np.ndarray]:
    """``e = [p* - p, log3(R* R^T)]`` of ``frame`` at ``q`` and its LOCAL_WORLD_ALIGNED Jacobian ``(6, nq)``;
    a tool frame's position and linear rows include the calibration's residual map
    (:meth:`RobotModel.residual_map_of`). One kinematic pass: the Jacobian's, along the frame's support."""
    J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
    cur = pin.updateFramePlacement(model, data, fid)
    p = cur.translation
    rmap = robot.residual_map_of(frame)
    if rmap is not None:
        p = p + rmap.mean(q)
        J[:3] += rmap.jacobian(q)
    return np.concatenate([target.translation - p, pin.log3(target.rotation @ cur.rotation.T)]), J


def wrap_into_limits(robot: RobotModel, Q: np.ndarray) -> np.ndarray:
    """``Q`` (N, nq) with each revolute joint's whole column shifted by a whole turn where that brings
    every sample inside the joint's limits (``q`` and ``q ± 2π`` give the same pose): an IK track that
    starts a turn away from where a joint of range beyond ±180° has room, e.g. a wrist at -350.3° of
    [-350°, 350°], is the same motion at +9.7°. Columns already inside, or that no turn brings inside,
    are returned as they are."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    out = np.array(Q, float)
    for j in range(out.shape[1]):
        col = out[:, j]
        if np.all((col >= lo[j]) & (col <= hi[j])):
            continue
        for turns in (1, -1, 2, -2):
            shifted = col + 2.0 * np.pi * turns
            if np.all((shifted >= lo[j]) & (shifted <= hi[j])):
                out[:, j] = shifted
                break
    return out


def joint_path(robot: RobotModel, path: CartesianPath, n: int, q0: np.ndarray, frame: str = "tcp") -> np.ndarray:
    """(n, nq) joint positions along ``path`` sampled equally in arc length (IK warm-started)."""
    return ik_track(robot, path.sample(n), q0, frame)


def limiting_joint(robot: RobotModel, q: np.ndarray) -> str:
    """'joint i at x deg of [lo, hi] deg' for the joint closest to (or beyond) a limit, relative to its range."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    margin = np.minimum(q - lo, hi - q) / (hi - lo)
    j = int(np.argmin(margin))
    return (f"joint {j + 1} at {np.degrees(q[j]):.1f} deg of [{np.degrees(lo[j]):.1f}, "
            f"{np.degrees(hi[j]):.1f}] deg")


def check_within_limits(robot: RobotModel, q: np.ndarray, where: str) -> None:
    """Raise InfeasibleError naming ``where`` (the path point) and the first joint outside its limits."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    bad = np.nonzero((q < lo) | (q > hi))[0]
    if len(bad):
        j = int(bad[0])
        raise InfeasibleError(None, "ik", f"{where} needs joint {j + 1} = {np.degrees(q[j]):.1f} deg outside "
                              f"[{np.degrees(lo[j]):.1f}, {np.degrees(hi[j]):.1f}] deg")


def start_configuration(robot: RobotModel, pose: pin.SE3, seeds: npt.ArrayLike, frame: str = "tcp",
                        tolerance_m: float = 1e-10, n_random: int = 30) -> np.ndarray:
    """IK from a cold start: damped Newton with step limiting from each seed, then from ``n_random``
    random configurations within the limits (fixed-seed generator: deterministic); the first
    solution within the limits wins. Raises InfeasibleError naming the point if none converges.
    """
    lo_, hi_ = robot.limits.lower_rad, robot.limits.upper_rad
    extra = np.random.default_rng(9283).uniform(lo_, hi_, (n_random, robot.model.nq))
    seeds = np.vstack([np.atleast_2d(np.asarray(seeds, float)), extra]) if n_random else np.atleast_2d(
        np.asarray(seeds, float))
    model = robot.model
    data = model.createData()
    fid = model.getFrameId(frame)
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    for seed in np.atleast_2d(seeds):
        q = np.array(seed, float)
        for _ in range(500):
            e, J = pose_error(robot, model, data, fid, frame, q, pose)
            if np.linalg.norm(e) < tolerance_m:
                break
            dq = J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(6), e)
            q = q + dq * min(1.0, 0.3 / max(np.abs(dq).max(), 1e-12))
        if np.linalg.norm(e) < tolerance_m * 1e3 and np.all(q >= lo) and np.all(q <= hi):
            return q
    raise InfeasibleError(None, "ik", f"start point {np.array2string(pose.translation, precision=4)} m "
                          f"not reachable (IK from {len(np.atleast_2d(seeds))} seed configurations failed)")
