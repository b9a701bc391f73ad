"""Search of the workspace for the largest feasible EN ISO 9283 cube (DESIGN.md "EN ISO 9283 test path").

A cube (edge ``L``, centre ``c``) is *feasible* when its whole test path (every segment the control
stage runs: line, rectangle, transitions, both circles; :func:`pipeline.robot.iso9283.iso9283_path`),
sampled every ``SAMPLE_SPACING_EDGES`` edges of arc length, is reachable at the constant tool
orientation by one IK branch followed by continuation, with, at every sample,

* every joint at least ``LIMIT_MARGIN_RAD`` inside its limits,
* ``cond(J) <= MAX_CONDITION`` for the 6 x n frame Jacobian (away from singularities; ``J`` in the
  base-aligned frame, metres and radians), and
* the static (gravity) joint torques at most ``GRAVITY_TORQUE_SHARE`` of the torque limits (the rest
  is for the path's accelerations and the servo; an arm that its own weight loads near its limits,
  e.g. a humanoid's arm held out sideways, saturates there), and
* the joint speeds ``J^+ [speed t; 0]`` for the path speed along the unit tangent ``t`` at most
  ``VELOCITY_SHARE`` of their limits (paper 004 §2.3.3: 1 m/s; the accelerations of 5 m/s² are
  reached by the reference generator and not part of this test).

The branch: IK from each seed to the path's first pose (inside the limits), the branch with the lowest
joint-speed demand wins; its start configuration is returned so that the stages start on it
(:func:`pipeline.robot.defaults.ik_seeds_or_derived_rad` puts it first).

Search: candidate centres on a grid of the vertical half-plane in front of the first joint (radial
distance 0.2..0.85 of the reach from the first joint's axis, height from the floor clearance to 0.8 reach
above the shoulder, the second joint's height); centres whose path cannot fit the reach sphere about the
shoulder or lies under the floor are discarded by geometry. The half-plane is in front of the base
(+x); :func:`pipeline.robot.defaults.iso_cube` turns to the sides (+y, -y) and behind (-x) in turn when
no tool orientation has a cube in front (an arm whose first joint does not turn about the vertical,
e.g. a humanoid's arm raised sideways, works to a side). Each
remaining centre is tried with a small cube (``MIN_EDGE_REACH`` of the reach); the feasible ones, largest
geometric room first, get a bisection on the edge (``BISECTION_STEPS`` steps) up to their geometric
bound; the largest edge wins (ties: the centre tried first). The winner is then checked with the control
stage's own reference generator (:func:`pipeline.robot.reference.cartesian_reference`: jerk-limited
profile at the speed, 5 m/s², minimum-norm redundancy resolution, joint limits and speeds) every
``VERIFY_SAMPLE_TIME_S``; while it fails the edge shrinks by ``SHRINK``. Deterministic: no random
numbers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import numpy as np
import pinocchio as pin

from pipeline.core.errors import InfeasibleError
from pipeline.robot.iso9283 import PLANES, iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.reference import cartesian_reference

#: axes needed to hold a 6-D tool pose (position and orientation) along a Cartesian path
POSE_AXES = 6
MAX_CONDITION = 300.0
LIMIT_MARGIN_RAD = np.deg2rad(5.0)
VELOCITY_SHARE = 0.9
GRAVITY_TORQUE_SHARE = 0.7
SAMPLE_SPACING_EDGES = 0.125       # path sample spacing, in cube edges of arc length
MIN_EDGE_REACH = 0.1              # the smallest cube tried, as a fraction of the reach
MAX_EDGE_REACH = 0.6              # the largest cube tried, as a fraction of the reach
BISECTION_STEPS = 5
BISECTED_CENTRES = 6              # centres (feasible with the small cube) refined by bisection
RADIAL_REACH = np.linspace(0.2, 0.85, 7)
HEIGHT_REACH = np.linspace(-0.7, 0.8, 7)
FLOOR_CLEARANCE_REACH = 0.05
VERIFY_SAMPLE_TIME_S = 4e-3      # the final check runs the control stage's reference at this step
SHRINK = 0.9                      # edge factor when the final check fails
#: horizontal directions of the searched half-planes, in the order tried (module docstring)
SEARCH_DIRECTIONS = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0), (-1.0, 0.0, 0.0))
_DAMPING = 1e-6 * np.eye(6)       # of the damped least squares steps
_NO_TURN = np.zeros(3)            # the path's angular velocity (constant tool orientation)


@dataclass
class CubeCheck:
    """Outcome of :func:`check_cube`: the worst joint-speed ratio (``inf`` when infeasible) and why."""

    speed_ratio: float
    reason: str
    q_start: np.ndarray | None


def _dls(model: pin.Model, data: pin.Data, fid: int, q: np.ndarray, target: pin.SE3, iterations: int,
         tolerance: float) -> tuple[np.ndarray, float]:
    """Damped least squares on ``[p_err; log3(R R^T)]`` (as paths.start_configuration), step ≤ 0.3 rad."""
    err = np.inf
    position, rotation = target.translation, target.rotation
    for _ in range(iterations):
        pin.framesForwardKinematics(model, data, q)
        cur = data.oMf[fid]
        e = np.concatenate([position - cur.translation, pin.log3(rotation @ cur.rotation.T)])
        err = math.sqrt(e.dot(e))            # np.linalg.norm(e), without its dispatch
        if err < tolerance:
            break
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
        dq = J.T @ np.linalg.solve(J @ J.T + _DAMPING, e)
        q = q + dq * min(1.0, 0.3 / max(float(np.abs(dq).max()), 1e-12))
    return q, err


def check_cube(robot: RobotModel, edge_m: float, centre_m: np.ndarray, plane: str, rotation: np.ndarray,
               seeds: np.ndarray,
               frame: str, speed_m_s: float) -> CubeCheck:
    """Feasibility of one cube's whole ISO path (module docstring); ``speed_ratio <= 1`` = feasible."""
    model, data = robot.model, robot.new_data()
    fid = robot.frame_id(frame)
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    lo_m, hi_m = lo + LIMIT_MARGIN_RAD, hi - LIMIT_MARGIN_RAD
    vmax = VELOCITY_SHARE * robot.limits.velocity_rad_s
    tau_max = GRAVITY_TORQUE_SHARE * robot.limits.effort_Nm
    path = iso9283_path(robot, edge_m, centre_m, plane, rotation)
    n = max(int(np.ceil(path.length_m / (SAMPLE_SPACING_EDGES * edge_m))), 2)
    s = np.linspace(0.0, path.length_m, n)
    poses = path.poses(s)
    tangents = path.derivatives(s)[0]
    tangents /= np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-12)
    best = CubeCheck(np.inf, "start pose not reached from the IK seeds", None)
    starts: list[np.ndarray] = []
    for seed in np.atleast_2d(seeds):
        q, err = _dls(model, data, fid, np.array(seed, float), poses[0], 150, 1e-10)
        if err < 1e-7 and np.all(q >= lo) and np.all(q <= hi) and all(np.abs(q - p).max() > 1e-3 for p in starts):
            starts.append(q)
            check = _follow(model, data, fid, q, poses, tangents, speed_m_s, lo_m, hi_m, vmax, tau_max)
            if check.speed_ratio < best.speed_ratio or best.q_start is None:
                best = check
    return best


def _follow(model: pin.Model, data: pin.Data, fid: int, q_start: np.ndarray, poses: list[pin.SE3],
            tangents: np.ndarray, speed_m_s: float, lo_m: np.ndarray, hi_m: np.ndarray,
            vmax: np.ndarray, tau_max: np.ndarray) -> CubeCheck:
    """Continuation along the sampled path from ``q_start`` with the checks of the module docstring."""
    n = len(poses)
    q, worst = q_start.copy(), 0.0
    for k, (T, tangent) in enumerate(zip(poses, tangents, strict=True)):
        q, err = _dls(model, data, fid, q, T, 60, 1e-9)
        if err > 1e-6:
            return CubeCheck(np.inf, f"IK lost at sample {k}/{n}", q_start)
        if (q < lo_m).any() or (q > hi_m).any():
            return CubeCheck(np.inf, f"joint limit margin at sample {k}/{n}", q_start)
        if (np.abs(pin.computeGeneralizedGravity(model, data, q)) > tau_max).any():
            return CubeCheck(np.inf, f"gravity torque at sample {k}/{n}", q_start)
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
        sv = np.linalg.svd(J, compute_uv=False)
        if sv[0] > MAX_CONDITION * sv[-1]:
            return CubeCheck(np.inf, f"near a singularity at sample {k}/{n}", q_start)
        v = np.linalg.pinv(J) @ np.concatenate([speed_m_s * tangent, _NO_TURN])
        worst = max(worst, float(np.max(np.abs(v) / vmax)))
    return CubeCheck(worst, "ok" if worst <= 1.0 else "joint speed", q_start)


def _geometric_edge_bound(centre: np.ndarray, shoulder: np.ndarray, reach: float, floor_z: float,
                          plane: str) -> float:
    """Largest edge whose plane rectangle stays in the reach sphere about the shoulder and above the floor
    (a necessary condition, no kinematics): corners at ``c ± L/2 u ± L/sqrt2 w``."""
    corners_unit = np.array([[a * 0.5, b * (np.sqrt(0.5) if plane != "horizontal" else 0.5)]
                             for a in (-1, 1) for b in (-1, 1)])
    u, w = PLANES[plane]
    best = 0.0
    for edge in np.linspace(MAX_EDGE_REACH * reach, 0.0, 61):
        pts = centre + edge * (corners_unit[:, :1] * u + corners_unit[:, 1:] * w)
        if (np.all(np.linalg.norm(pts - shoulder, axis=1) <= 0.97 * reach)
                and np.all(pts[:, 2] >= floor_z + FLOOR_CLEARANCE_REACH * reach)):
            best = float(edge)
            break
    return best


def search_cube(robot: RobotModel, seeds: np.ndarray, plane: str, rotation: np.ndarray, speed_m_s: float, frame: str,
                ignore_speed: bool = False, memo: dict[tuple[float, ...], float] | None = None,
                direction: tuple[float, float, float] = SEARCH_DIRECTIONS[0]) -> tuple[float, np.ndarray, float] | None:
    """(edge, centre, speed ratio) of the largest feasible cube (module docstring) on the vertical
    half-plane from the first joint along ``direction`` (one of :data:`SEARCH_DIRECTIONS`), or ``None``.

    ``memo``: a dict shared by calls with the same robot, seeds, plane, tool and frame (checks are reused).
    ``ignore_speed``: any finite speed ratio counts as feasible, and the small cube at the centre with the
    lowest speed demand is returned (to find the speed the arm allows, for the lowered-speed fallback)."""
    memo = {} if memo is None else memo      # (edge, centre) -> speed ratio per m/s (linear in the speed)
    return _search_half_plane(robot, seeds, plane, rotation, speed_m_s, frame, ignore_speed, memo,
                              np.asarray(direction, float))


def _search_half_plane(robot: RobotModel, seeds: np.ndarray, plane: str, rotation: np.ndarray, speed_m_s: float,
                       frame: str,
                       ignore_speed: bool, memo: dict[tuple[float, ...], float],
                       direction: np.ndarray) -> tuple[float, np.ndarray, float] | None:
    """:func:`search_cube` on the vertical half-plane from the first joint along ``direction``."""
    reach = cast(float, robot.summary()["reach_m"])
    base = robot.model.jointPlacements[1].translation
    shoulder = robot.model.jointPlacements[2].translation + base if robot.nq > 1 else base
    floor_z = float(robot.spec.collision.floor_z_m)
    limit = 1e3 if ignore_speed else 1.0

    def ok(edge: float, centre: np.ndarray) -> float | None:
        key = (round(edge, 9), *np.round(centre, 9))
        if key not in memo:
            memo[key] = check_cube(robot, edge, centre, plane, rotation, seeds, frame, 1.0).speed_ratio
        ratio = memo[key] * speed_m_s
        return ratio if ratio <= limit else None

    small = MIN_EDGE_REACH * reach
    candidates = []
    for radial in RADIAL_REACH:
        for height in HEIGHT_REACH:
            centre = np.array([base[0], base[1], shoulder[2] + height * reach]) + radial * reach * direction
            bound = _geometric_edge_bound(centre, shoulder, reach, floor_z, plane)
            if bound >= small:
                candidates.append((bound, centre))
    candidates.sort(key=lambda bc: -bc[0])
    feasible = []
    for bound, centre in candidates:
        ratio = ok(small, centre)
        if ratio is not None:
            feasible.append((bound, centre, ratio))
    if not feasible:
        return None
    if ignore_speed:                      # the centre with the lowest speed demand, at the small cube
        bound, centre, ratio = min(feasible, key=lambda f: f[2])
        return small, centre, ratio
    by_ratio = sorted(range(len(feasible)), key=lambda i: feasible[i][2])[:BISECTED_CENTRES // 2]
    chosen = sorted(set(range(min(BISECTED_CENTRES, len(feasible)))) | set(by_ratio))
    best: tuple[float, np.ndarray, float] | None = None
    for i in chosen:
        bound, centre, ratio = feasible[i]
        if best is None or bound > best[0]:
            edge, ratio = _bisect(ok, centre, small, bound, ratio)
            if best is None or edge > best[0]:
                best = (edge, centre, ratio)
    assert best is not None
    # pattern search: neighbours of the best centre at half, then a quarter of the grid spacing
    radial_step = (RADIAL_REACH[1] - RADIAL_REACH[0]) * reach * direction
    height_step = np.array([0.0, 0.0, (HEIGHT_REACH[1] - HEIGHT_REACH[0]) * reach])
    for scale in (0.5, 0.25):
        for step in (radial_step, -radial_step, height_step, -height_step):
            centre = best[1] + scale * step
            bound = _geometric_edge_bound(centre, shoulder, reach, floor_z, plane)
            edge = best[0] * 1.05
            if bound < edge:
                continue
            ratio = ok(edge, centre)
            if ratio is not None:
                edge, ratio = _bisect(ok, centre, edge, bound, ratio, steps=3)
                best = (edge, centre, ratio)
    return best


def _bisect(ok: Callable[[float, np.ndarray], float | None], centre: np.ndarray, lo_edge: float,
            hi_edge: float, lo_ratio: float, steps: int = BISECTION_STEPS) -> tuple[float, float]:
    """Largest feasible edge in ``[lo_edge, hi_edge]`` (``lo_edge`` feasible) by bisection."""
    top = ok(hi_edge, centre)
    if top is not None:
        return hi_edge, top
    for _ in range(steps):
        mid = 0.5 * (lo_edge + hi_edge)
        r = ok(mid, centre)
        if r is None:
            hi_edge = mid
        else:
            lo_edge, lo_ratio = mid, r
    return lo_edge, lo_ratio


def verified_edge(robot: RobotModel, edge_m: float, centre_m: np.ndarray, plane: str, rotation: np.ndarray,
                  seeds: np.ndarray,
                  frame: str, speed_m_s: float, acceleration_m_s2: float = 5.0, jerk_m_s3: float = 50.0,
                  attempts: int = 8) -> tuple[float, np.ndarray] | None:
    """(edge, start configuration) for which the control stage's reference runs on the cube (module
    docstring), shrinking ``edge_m`` by ``SHRINK`` up to ``attempts`` times; ``None`` if none does.
    Acceleration 5 m/s² (paper 004 §2.3.3) and jerk as the control stage's defaults."""
    for _ in range(attempts):
        check = check_cube(robot, edge_m, centre_m, plane, rotation, seeds, frame, speed_m_s)
        if check.q_start is not None and np.isfinite(check.speed_ratio):
            path = iso9283_path(robot, edge_m, centre_m, plane, rotation)
            try:
                cartesian_reference(robot, path, VERIFY_SAMPLE_TIME_S, speed_m_s, acceleration_m_s2, jerk_m_s3,
                                    check.q_start, frame, 1e-9)
            except InfeasibleError:
                pass
            else:
                return edge_m, check.q_start
        edge_m *= SHRINK
    return None
