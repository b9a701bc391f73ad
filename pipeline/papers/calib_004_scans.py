"""Literal readings of paper 004's baseline, "a linear scan of the workspace" (§3.4).

The paper compares its optimal 32 configurations with "a linear scan of the workspace" and does not
say how that scan was laid out. Each reading below is a function returning joint configurations in
scan order; which of them the tracker can see is decided by the caller (a configuration it cannot
see is never measured, so it adds nothing to the information matrix):

- ``grid_order``: every (N/n)-th configuration of the visible grid in grid order (axis 1 slowest);
  :func:`pipeline.calibration.design.linear_scan_design`;
- :func:`joint_line`: ``n`` equally spaced poses on the straight joint-space line through the whole
  range, ``q(s) = lower + s (upper - lower)``, ``s`` at the midpoints of ``n`` equal intervals;
  :func:`joint_line_visible` the same line sampled densely, ``n`` equally spaced among its visible
  points;
- :func:`joint_sweeps`: each joint in turn swept through its range (midpoints of equal intervals),
  the others at a home pose, ``n / nq`` poses per joint;
  (:func:`joint_sweeps_visible`: equally spaced among the visible poses of each sweep);
- :func:`cartesian_raster`: a raster of a box of the workspace traversed line by line (x fastest,
  direction reversed on every other line), the probe held at one orientation facing the cameras,
  joint angles by inverse kinematics seeded from the previous raster point (optionally tilted by a
  cycle of small rotations, a deviation that makes the orientation parameters observable).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pipeline.robot.model import RobotModel


def _midpoints(n: int) -> np.ndarray:
    return (np.arange(n) + 0.5) / n


def joint_line(robot: RobotModel, n: int) -> np.ndarray:
    """``n`` equally spaced poses on the joint-space diagonal lower -> upper."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    return lo + _midpoints(n)[:, None] * (hi - lo)


def joint_line_visible(robot: RobotModel, n: int, visible, samples: int = 4000) -> np.ndarray:
    """``n`` equally spaced (in scan order) among the visible points of the densely sampled diagonal."""
    Q = joint_line(robot, samples)
    Q = Q[visible(Q)]
    if len(Q) <= n:
        return Q
    return Q[np.linspace(0, len(Q) - 1, n).round().astype(int)]


def joint_sweeps(robot: RobotModel, home: np.ndarray, n: int) -> np.ndarray:
    """Each joint swept through its range from ``home`` (``ceil(n / nq)`` poses per joint, first ``n``)."""
    nq = robot.nq
    per = -(-n // nq)
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    rows = []
    for j in range(nq):
        for s in _midpoints(per):
            q = np.array(home, float)
            q[j] = lo[j] + s * (hi[j] - lo[j])
            rows.append(q)
    return np.array(rows[:n])


def joint_sweeps_visible(robot: RobotModel, home: np.ndarray, n: int, visible, samples: int = 400) -> np.ndarray:
    """Each joint swept in turn from ``home``: ``ceil(n / nq)`` poses equally spaced among the visible
    points of its densely sampled range (first ``n``)."""
    nq = robot.nq
    per = -(-n // nq)
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    rows = []
    for j in range(nq):
        Q = np.repeat(np.asarray(home, float)[None], samples, axis=0)
        Q[:, j] = lo[j] + _midpoints(samples) * (hi[j] - lo[j])
        Q = Q[visible(Q)]
        rows += list(Q if len(Q) <= per else Q[np.linspace(0, len(Q) - 1, per).round().astype(int)])
    return np.array(rows[:n]) if rows else np.zeros((0, nq))


def raster_points(box_lo: np.ndarray, box_hi: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """Box points at the midpoints of ``shape`` cells, line by line (boustrophedon: x fastest,
    reversed on every other line, y reversed on every other layer)."""
    nx, ny, nz = shape
    xs, ys, zs = (box_lo[k] + _midpoints(m) * (box_hi[k] - box_lo[k]) for k, m in enumerate((nx, ny, nz)))
    pts = []
    line = 0
    for kz, z in enumerate(zs):
        for y in (ys if kz % 2 == 0 else ys[::-1]):
            for x in (xs if line % 2 == 0 else xs[::-1]):
                pts.append((x, y, z))
            line += 1
    return np.array(pts)


def facing_rotation(axis_flange: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """A flange rotation whose ``axis_flange`` (flange frame) points along ``towards`` (base frame)."""
    z = towards / np.linalg.norm(towards)
    a = np.asarray(axis_flange, float) / np.linalg.norm(axis_flange)
    R_align = pin.exp3(np.cross(a, z) / max(np.linalg.norm(np.cross(a, z)), 1e-12)
                       * np.arccos(np.clip(a @ z, -1.0, 1.0)))
    return R_align


def cartesian_raster(robot: RobotModel, box_lo: np.ndarray, box_hi: np.ndarray, shape: tuple[int, int, int],
                     rotation: np.ndarray, seed: np.ndarray, tilts_rad: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Raster of the box (``raster_points``) with the flange at ``rotation`` (times ``exp(tilts_rad[k])``
    cycled over the points, when given); returns the joint configurations of the points IK reached
    (scan order) and a mask of which points it reached."""
    pts = raster_points(box_lo, box_hi, shape)
    q_prev = np.asarray(seed, float)
    out, ok = [], np.zeros(len(pts), bool)
    for k, p in enumerate(pts):
        R = rotation if tilts_rad is None else rotation @ pin.exp3(tilts_rad[k % len(tilts_rad)])
        target = pin.SE3(R, p)
        for q0 in (q_prev, np.asarray(seed, float)):
            res = robot.ik(target, q0, frame=robot.frame_flange)
            if res.success and robot.within_limits(res.q):
                out.append(res.q)
                ok[k] = True
                q_prev = res.q
                break
    return (np.array(out) if out else np.zeros((0, robot.nq))), ok
