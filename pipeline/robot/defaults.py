"""Defaults derived from the robot model (used where a run config leaves a field ``None``).

No number here belongs to one robot: every default is computed from the model's limits,
kinematics and capsules with a fixed-seed search (same robot -> same defaults).

* ``ready_pose_rad``: among random configurations inside the limits (seed 0) that are free of
  self- and floor-collision with the flange above the base, the one with the best-conditioned
  position Jacobian, penalised by the distance from mid-range (limits) — a "ready" pose for pictures.
* ``ik_seeds_rad``: the best few of that ranking (distinct by > 30°), ready pose first.
* ``ptp_move_rad``: ready pose -/+ a fraction of each joint's range (40 %, else smaller), both ends and
  the joint-space midpoint collision-free; else the pair of well-ranked poses with the largest
  smallest joint motion (no joint beyond ``MAX_MOVE_RAD``) whose midpoint is collision-free.
* ``iso_cube``: EN ISO 9283 (DESIGN.md): the largest cube, with its diagonal plane, whose whole path
  (sampled) is reachable from one IK branch with ``cond(J) <= MAX_CONDITION`` (away from
  singularities), every joint at least ``LIMIT_MARGIN_RAD`` inside its limits and the joint speeds
  for ``speed_m_s`` along the path tangent at most ``VELOCITY_SHARE`` of their limits; searched over centres in front of
  the base at fractions of the reach, edges from large to small. Capsule self-collision is not part
  of this search (fitted capsules are conservative); the stages check it where they need it.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.control.iso9283 import iso9283_path, tool_rotation
from pipeline.errors import InfeasibleError

MAX_CONDITION = 300.0
LIMIT_MARGIN_RAD = np.deg2rad(5.0)
VELOCITY_SHARE = 0.9
N_SAMPLES = 3000
MAX_MOVE_RAD = np.pi / 2      # the searched PtP move turns no joint by more than this


@dataclass
class IsoCube:
    """A cube for the ISO 9283 path: centre and edge in the base frame, the plane, how it was found."""

    centre_m: np.ndarray
    edge_m: float
    plane: str
    speed_m_s: float
    note: str


def _ranked_poses(robot) -> np.ndarray:
    """Collision-free configurations (flange above the base) ranked best first (module docstring)."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    Q = np.random.default_rng(0).uniform(lo, hi, size=(N_SAMPLES, robot.nq))
    Q = np.vstack([np.clip(0.5 * (lo + hi), lo, hi), np.clip(np.zeros(robot.nq), lo, hi), Q])
    if robot.capsules:
        pair, floor = robot.capsule_clearances(robot.capsule_segments(Q))
        ok = (pair.min(axis=1, initial=np.inf) > 0.01) & (floor.min(axis=1, initial=np.inf) > 0.02)
    else:
        ok = np.ones(len(Q), bool)
    base_z = robot.model.jointPlacements[1].translation[2]
    flange = robot.positions(Q, robot.frame_flange)
    ok &= flange[:, 2] > base_z
    Q = Q[ok]
    if not len(Q):
        raise InfeasibleError(None, "robot", "no collision-free configuration found among random samples: check "
                              "the capsules and floor_z_m")
    span = np.minimum(hi - lo, np.pi)      # a +-360 deg joint is not penalised 4x less than a +-90 deg one
    score = np.empty(len(Q))
    for k, q in enumerate(Q):
        s = np.linalg.svd(robot.jacobian(q, robot.frame_flange)[:3], compute_uv=False)
        mid = np.linalg.norm((q - 0.5 * (lo + hi)) / span) / np.sqrt(robot.nq)
        score[k] = s[-1] / max(s[0], 1e-12) - mid
    return Q[np.argsort(-score)]


def ready_pose_rad(robot) -> np.ndarray:
    """A well-conditioned, collision-free pose near mid-range with the flange above the base."""
    return _ranked_poses(robot)[0].copy()


def ik_seeds_rad(robot, count: int = 4) -> np.ndarray:
    """``(count, nq)`` distinct IK seeds: the best-ranked poses, more than 30° apart."""
    seeds: list[np.ndarray] = []
    for q in _ranked_poses(robot):
        if all(np.max(np.abs(q - s)) > np.deg2rad(30.0) for s in seeds):
            seeds.append(q)
        if len(seeds) == count:
            break
    return np.array(seeds)


def ptp_move_rad(robot, fractions: tuple[float, ...] = (0.4, 0.3, 0.2, 0.1)) -> tuple[np.ndarray, np.ndarray]:
    """(start, goal): mid-range -/+ ``fraction`` of each range, the first fraction collision-free."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    mid = ready_pose_rad(robot)
    for f in fractions:
        half = 0.5 * f * np.minimum(hi - lo, 2 * np.pi)
        start, goal = np.clip(mid - half, lo, hi), np.clip(mid + half, lo, hi)
        ends = [start, goal, 0.5 * (start + goal)]
        if not robot.capsules or not any(robot.in_collision(q, 0.0) for q in ends):
            return start, goal
    # else the largest move between two well-ranked poses whose midpoint is collision-free too
    ranked = _ranked_poses(robot)[:60]
    best, pair = 0.0, None
    for i, a in enumerate(ranked):
        for b in ranked[i + 1:]:
            size = float(np.min(np.abs(b - a)))
            if size > best and np.max(np.abs(b - a)) <= MAX_MOVE_RAD and not robot.in_collision(0.5 * (a + b), 0.0):
                best, pair = size, (a.copy(), b.copy())
    if pair is None:
        raise InfeasibleError(None, "trajectory.ptp_start_deg", "no collision-free default move found: set "
                              "trajectory.ptp_start_deg and ptp_goal_deg")
    return pair


def _speed_ratio(robot, path, seeds: np.ndarray, frame: str, speed_m_s: float, n: int = 48) -> float:
    """Smallest over the seeds' IK branches of the largest ``|v_joint| / (VELOCITY_SHARE v_max)`` along the
    sampled ``path`` at ``speed_m_s``; ``inf`` when no branch reaches it within the margins."""
    model, data = robot.model, robot.new_data()
    fid = robot.frame_id(frame)
    lo, hi = robot.limits.lower_rad + LIMIT_MARGIN_RAD, robot.limits.upper_rad - LIMIT_MARGIN_RAD
    vmax = VELOCITY_SHARE * robot.limits.velocity_rad_s
    poses = path.sample(n)
    points = np.array([T.translation for T in poses])
    tangents = np.gradient(points, axis=0)
    tangents /= np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-12)
    best = np.inf
    for seed in seeds:
        q, worst = seed.copy(), 0.0
        for T, tangent in zip(poses, tangents, strict=True):
            for _ in range(60):
                pin.framesForwardKinematics(model, data, q)
                cur = data.oMf[fid]
                e = np.concatenate([T.translation - cur.translation, pin.log3(T.rotation @ cur.rotation.T)])
                if np.linalg.norm(e) < 1e-8:
                    break
                J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
                dq = J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(6), e)
                q = q + dq * min(1.0, 0.3 / max(np.abs(dq).max(), 1e-12))
            J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
            if (np.linalg.norm(e) > 1e-6 or np.any(q < lo) or np.any(q > hi)
                    or np.linalg.cond(J) > MAX_CONDITION):
                worst = np.inf
                break
            v = J.T @ np.linalg.solve(J @ J.T, np.r_[speed_m_s * tangent, 0, 0, 0])
            worst = max(worst, float(np.max(np.abs(v) / vmax)))
        best = min(best, worst)
    return best


def iso_cube(robot, plane: str = "diagonal_x", tool_down: bool = True, speed_m_s: float = 1.0,
             frame: str | None = None) -> IsoCube:
    """The largest ISO 9283 cube whose whole path is feasible (module docstring), found by a search.

    If no cube is feasible at ``speed_m_s`` (a small arm's joint speeds), the cube of at least 0.2
    reaches with the lowest speed demand is returned with ``speed_m_s`` lowered to what its joints allow.
    """
    frame = frame or robot.frame_reflector
    reach = float(robot.summary()["reach_m"])
    base = robot.model.jointPlacements[1].translation
    rotation = tool_rotation(plane, tool_down)
    seeds = ik_seeds_rad(robot, 6)
    fallback: tuple[float, np.ndarray, float] | None = None
    for edge_fraction in (0.4, 0.33, 0.27, 0.22, 0.18, 0.14, 0.1):
        edge = edge_fraction * reach
        for radial in (0.55, 0.45, 0.65, 0.35):
            for height in (0.0, 0.2, -0.15, 0.4):
                centre = base + np.array([radial * reach, 0.0, height * reach])
                if centre[2] - 0.5 * edge * np.sqrt(2) < robot.spec.collision.floor_z_m + 0.05 * reach:
                    continue
                path = iso9283_path(robot, edge, centre, plane, rotation)
                ratio = _speed_ratio(robot, path, seeds, frame, speed_m_s)
                if ratio <= 1.0:
                    return IsoCube(centre, edge, plane, speed_m_s, f"largest feasible cube found by search: edge "
                                   f"{edge:.3f} m ({edge_fraction:g} x reach {reach:.3f} m), centre "
                                   f"{np.round(centre, 3).tolist()} m")
                if np.isfinite(ratio) and edge_fraction >= 0.2 and (fallback is None or ratio < fallback[0]):
                    fallback = (ratio, centre, edge)
    if fallback is not None:
        ratio, centre, edge = fallback
        slower = float(np.floor(100 * speed_m_s / ratio) / 100)
        return IsoCube(centre, edge, plane, slower, f"no cube is feasible at {speed_m_s:g} m/s (joint speeds): "
                       f"edge {edge:.3f} m, centre {np.round(centre, 3).tolist()} m at {slower:g} m/s")
    raise InfeasibleError(None, "control.iso", f"no ISO 9283 cube of edge >= {0.1 * reach:.3f} m is feasible for "
                          f"{robot.name}: set control.iso.centre_m and edge_m")


def ik_seeds_or_derived_rad(robot, seeds_deg: list | None) -> np.ndarray:
    """``(k, nq)`` IK seeds: the configured ones (deg) or, when ``None``, :func:`ik_seeds_rad`."""
    if seeds_deg is None:
        return ik_seeds_rad(robot)
    return np.radians(np.atleast_2d(np.asarray(seeds_deg, float)))


def iso_or_derived(robot, iso):  # noqa: ANN001, ANN201 - IsoPathConfig in, a copy out (control layer type)
    """A copy of the ISO path settings with ``centre_m`` / ``edge_m`` / ``speed_m_s`` left ``None``
    filled from :func:`iso_cube` (the search runs only when something is missing)."""
    if iso.centre_m is not None and iso.edge_m is not None and iso.speed_m_s is not None:
        return iso
    out = copy.copy(iso)
    cube = iso_cube(robot, iso.plane, iso.tool_down, 1.0 if iso.speed_m_s is None else iso.speed_m_s)
    if iso.centre_m is None or iso.edge_m is None:
        out.centre_m, out.edge_m = [float(v) for v in cube.centre_m], float(cube.edge_m)
    if iso.speed_m_s is None or ((iso.centre_m is None or iso.edge_m is None) and cube.speed_m_s < iso.speed_m_s):
        out.speed_m_s = cube.speed_m_s       # a derived cube that no joint speeds allow at the configured speed
    return out
