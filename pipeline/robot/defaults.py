"""Defaults derived from the robot model (used where a run config leaves a field ``None``).

No number here belongs to one robot: every default is computed from the model's limits,
kinematics and capsules with a fixed-seed search (same robot -> same defaults).

* ``ready_pose_rad``: among random configurations inside the limits (seed 0) that are free of
  self- and floor-collision with the flange above the base, the one with the best-conditioned
  position Jacobian, penalised by the distance from mid-range (limits) — a "ready" pose for pictures.
* ``ik_seeds_rad``: the best few of that ranking (distinct by > 30°), ready pose first.
* ``ptp_move_rad``: ready pose -/+ a fraction of each joint's range (40 %, else smaller), both ends and
  the joint-space midpoint collision-free; else the pair of well-ranked poses with the largest
  smallest joint motion (no joint beyond ``MAX_MOVE_RAD``) whose midpoint is collision-free. Either way
  the arm must hold itself along the move: the static (gravity) torques on the straight joint-space
  line, sampled every 1/``HOLD_SAMPLES``, at most ``GRAVITY_TORQUE_SHARE`` of the torque limits, as on
  the ISO cube's path (an arm with a weak wrist cannot hold it out level: that move is skipped).
* ``iso_cube``: EN ISO 9283 (DESIGN.md): the largest cube, with its diagonal plane, whose whole path
  is reachable from the stages' IK branch, away from limits and singularities and within the joint
  speeds at the path speed, found by a search over the workspace (:mod:`pipeline.robot.iso_search`,
  which states the thresholds), with the tool held in a constant orientation: pointing down, else
  normal to the path's plane, else as at the ready pose (an arm whose wrist cannot point the tool
  down, e.g. a small arm with ±80° wrist joints). Capsule self-collision is not part of this search (fitted capsules are
  conservative); the stages check it where they need it.
"""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from pipeline.core.errors import InfeasibleError
from pipeline.robot.iso9283 import TOOL_ORIENTATIONS, IsoPathConfig, ToolOrientation, tool_rotation
from pipeline.robot.iso_search import (
    GRAVITY_TORQUE_SHARE,
    MIN_EDGE_REACH,
    SEARCH_DIRECTIONS,
    VELOCITY_SHARE,
    search_cube,
    verified_edge,
)
from pipeline.robot.model import RobotModel

N_SAMPLES = 3000
SLOW_SHARE = 0.8              # lowered ISO speed: this share of the highest speed a small cube allows
MAX_MOVE_RAD = np.pi / 2      # the searched PtP move turns no joint by more than this
HOLD_SAMPLES = 20             # static-torque samples along the default PtP move


@dataclass
class IsoCube:
    """A cube for the ISO 9283 path: centre and edge in the base frame, the plane, how it was found."""

    centre_m: np.ndarray
    edge_m: float
    plane: str
    speed_m_s: float
    note: str
    q_start_rad: np.ndarray | None = None      # the IK branch the search validated (path start)
    orientation: str = "down"                   # of TOOL_ORIENTATIONS
    rotation: np.ndarray | None = None          # the constant TCP orientation of the path (base frame)


#: rankings of :func:`_ranked_poses` by :func:`_ranking_key` (a pure function of the model: the ISO cube
#: search, its fallbacks and the stages ask for the same robot's ranking many times)
_RANKED: dict[tuple[str, str], np.ndarray] = {}


def _ranking_key(robot: RobotModel) -> tuple[str, str] | None:
    """The robot's name and the SHA-256 of everything the ranking reads: the Pinocchio model (kinematics,
    limits, frames; its full-precision serialisation), the flange frame, the capsules and the checked
    pairs and floor height; None with a residual map (the flange positions then depend on it)."""
    if robot.residual_map is not None:
        return None
    parts = [robot.model.saveToString().encode(), robot.frame_flange.encode(),
             repr((robot.self_collision_pairs, robot.floor_capsules)).encode(),
             np.float64(robot.spec.collision.floor_z_m).tobytes(),
             *(c.frame.encode() + np.concatenate([c.p0, c.p1, [c.radius_m]]).astype(float).tobytes()
               for c in robot.capsules)]
    return robot.name, hashlib.sha256(b"|".join(parts)).hexdigest()


def _ranked_poses(robot: RobotModel) -> np.ndarray:
    """Collision-free configurations (flange above the base) ranked best first (module docstring);
    computed once per model (:data:`_RANKED`)."""
    key = _ranking_key(robot)
    if key is None:
        return _ranking(robot)
    if key not in _RANKED:
        _RANKED[key] = _ranking(robot)
    return _RANKED[key].copy()


def _ranking(robot: RobotModel) -> np.ndarray:
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


def ready_pose_rad(robot: RobotModel) -> np.ndarray:
    """A well-conditioned, collision-free pose near mid-range with the flange above the base."""
    return _ranked_poses(robot)[0].copy()


def ik_seeds_rad(robot: RobotModel, count: int = 4) -> np.ndarray:
    """``(count, nq)`` distinct IK seeds: the best-ranked poses, more than 30° apart."""
    seeds: list[np.ndarray] = []
    for q in _ranked_poses(robot):
        if all(np.max(np.abs(q - s)) > np.deg2rad(30.0) for s in seeds):
            seeds.append(q)
        if len(seeds) == count:
            break
    return np.array(seeds)


def holds_itself(robot: RobotModel, start: np.ndarray, goal: np.ndarray) -> bool:
    """Whether the gravity torques on the straight joint-space line from ``start`` to ``goal`` stay
    within ``GRAVITY_TORQUE_SHARE`` of every torque limit (module docstring)."""
    return all(np.all(np.abs(robot.gravity_torque(start + t * (goal - start)))
                      <= GRAVITY_TORQUE_SHARE * robot.limits.effort_Nm)
               for t in np.linspace(0.0, 1.0, HOLD_SAMPLES + 1))


def ptp_move_rad(robot: RobotModel, fractions: tuple[float, ...] = (0.4, 0.3, 0.2, 0.1)) -> tuple[np.ndarray,
                 np.ndarray]:
    """(start, goal): mid-range -/+ ``fraction`` of each range, the first fraction collision-free on
    which the arm holds itself; else the searched pair (module docstring)."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    mid = ready_pose_rad(robot)
    for f in fractions:
        half = 0.5 * f * np.minimum(hi - lo, 2 * np.pi)
        start, goal = np.clip(mid - half, lo, hi), np.clip(mid + half, lo, hi)
        ends = [start, goal, 0.5 * (start + goal)]
        if (not robot.capsules or not any(robot.in_collision(q, 0.0) for q in ends)) and holds_itself(robot, start,
                                                                                                        goal):
            return start, goal
    # else the largest move between two well-ranked poses whose midpoint is collision-free too
    ranked = _ranked_poses(robot)[:60]
    best, pair = 0.0, None
    for i, a in enumerate(ranked):
        for b in ranked[i + 1:]:
            size = float(np.min(np.abs(b - a)))
            if (size > best and np.max(np.abs(b - a)) <= MAX_MOVE_RAD and not robot.in_collision(0.5 * (a + b), 0.0)
                    and holds_itself(robot, a, b)):
                best, pair = size, (a.copy(), b.copy())
    if pair is None:
        raise InfeasibleError(None, "trajectory.ptp_start_deg", "no collision-free default move on which the arm "
                              f"holds itself (static torques <= {GRAVITY_TORQUE_SHARE:.0%} of the limits) found: set "
                              "trajectory.ptp_start_deg and ptp_goal_deg")
    return pair


_CUBES: dict[tuple[object, ...], IsoCube] = {}
#: searches that found no cube (the problem stated), so that a fallback to another tool orientation or
#: direction does not search the failing one again on every call
_NO_CUBES: dict[tuple[object, ...], str] = {}


def iso_rotation(robot: RobotModel, plane: str, orientation: str) -> np.ndarray:
    """The path's constant TCP orientation: ``down`` (z axis down), ``plane`` (z normal to the
    measuring plane, away from the base) or ``ready`` (as at :func:`ready_pose_rad`)."""
    if orientation == "ready":
        return robot.poses(ready_pose_rad(robot), robot.frame_tcp)[1][0]
    if orientation not in TOOL_ORIENTATIONS:
        raise ValueError(f"unknown ISO tool orientation {orientation!r} (one of {', '.join(TOOL_ORIENTATIONS)})")
    return tool_rotation(plane, orientation == "down")


def _cache_key(robot: RobotModel, seeds: np.ndarray, plane: str, orientation: str, speed_m_s: float,
               frame: str) -> tuple[object, ...]:
    """The robot's name plus everything of the model the search reads (the search is a pure function):
    kinematics, limits, and the inertias and torque limits of its gravity check."""
    placements = np.array([robot.model.jointPlacements[i].homogeneous for i in range(1, robot.model.njoints)])
    frame_placement = robot.model.frames[robot.frame_id(frame)].placement.homogeneous
    inertias = np.array([robot.model.inertias[i].toDynamicParameters() for i in range(1, robot.model.njoints)])
    lim = robot.limits
    model_bytes = b"".join(np.ascontiguousarray(a, float).tobytes() for a in (
        placements, frame_placement, lim.lower_rad, lim.upper_rad, lim.velocity_rad_s, lim.effort_Nm, seeds,
        inertias, robot.model.gravity.linear, [robot.spec.collision.floor_z_m]))
    return (robot.name, hash(model_bytes), plane, orientation, float(speed_m_s), frame)


def iso_cube(robot: RobotModel, plane: str = "diagonal_x", orientation: str | None = None, speed_m_s: float = 1.0,
             frame: str | None = None, direction: tuple[float, float, float] | None = None) -> IsoCube:
    """The largest ISO 9283 cube whose whole path is feasible, found by a search over the workspace
    (:mod:`pipeline.robot.iso_search`; the IK branch starts from :func:`ik_seeds_rad`, as the stages do),
    with the tool in ``orientation`` (:func:`iso_rotation`); ``None``: the first of
    :data:`~pipeline.robot.iso9283.TOOL_ORIENTATIONS` that has a cube.

    If no cube is feasible at ``speed_m_s`` (the joint speeds of a small or slow arm), the speed is lowered
    to ``SLOW_SHARE`` of the highest speed a small cube allows, and the largest cube at that speed returned.
    Results are cached per robot model (same model -> same cube), and so is the finding that a tool
    orientation and direction have no cube (the fallbacks below do not search it again).

    ``direction``: the searched half-plane (:data:`~pipeline.robot.iso_search.SEARCH_DIRECTIONS`);
    ``None``: in front of the base, else (no orientation nor speed has a cube there) beside it, else
    behind it.
    """
    if direction is None:
        front = None
        for candidate_direction in SEARCH_DIRECTIONS:
            try:
                return iso_cube(robot, plane, orientation, speed_m_s, frame, candidate_direction)
            except InfeasibleError as exc:
                front = exc.problem if front is None else front
        raise InfeasibleError(None, "control.iso", f"{front} (nor beside or behind the base)")
    if orientation is None:
        failures = []
        for candidate in TOOL_ORIENTATIONS:
            try:
                return iso_cube(robot, plane, candidate, speed_m_s, frame, direction)
            except InfeasibleError as exc:
                failures.append(f"tool {candidate}: {exc.problem}")
        raise InfeasibleError(None, "control.iso", "; ".join(failures))
    frame = frame or robot.frame_reflector
    seeds = ik_seeds_rad(robot)
    key = (*_cache_key(robot, seeds, plane, orientation, speed_m_s, frame), direction)
    if key in _CUBES:
        return copy.deepcopy(_CUBES[key])
    if key in _NO_CUBES:
        raise InfeasibleError(None, "control.iso", _NO_CUBES[key])
    rotation = iso_rotation(robot, plane, orientation)
    reach = cast(float, robot.summary()["reach_m"])
    memo: dict[tuple[float, ...], float] = {}
    best = search_cube(robot, seeds, plane, rotation, speed_m_s, frame, memo=memo, direction=direction)
    speed, how = speed_m_s, "largest feasible cube found by search"
    if best is None:
        slowest = search_cube(robot, seeds, plane, rotation, speed_m_s, frame, ignore_speed=True, memo=memo,
                              direction=direction)
        if slowest is not None:       # SLOW_SHARE of the highest speed a small cube allows, then the largest cube
            speed = float(np.floor(100 * SLOW_SHARE * speed_m_s / slowest[2]) / 100)
            how = f"no cube is feasible at {speed_m_s:g} m/s (joint speeds); largest cube at {speed:g} m/s"
            best = (search_cube(robot, seeds, plane, rotation, speed, frame, memo=memo, direction=direction)
                    if speed > 0 else None)
    found = None if best is None or speed <= 0 else verified_edge(robot, best[0], best[1], plane, rotation, seeds,
                                                                  frame, speed)
    if found is None or best is None:
        _NO_CUBES[key] = (f"no ISO 9283 cube of edge >= {MIN_EDGE_REACH * reach:.3f} m is feasible for "
                          f"{robot.name} with the tool {orientation}: set control.iso.centre_m and edge_m")
        raise InfeasibleError(None, "control.iso", _NO_CUBES[key])
    edge, q_start = found
    centre = best[1]
    cube = IsoCube(centre, edge, plane, speed, f"{how}: edge {edge:.3f} m ({edge / reach:.2f} x reach "
                   f"{reach:.3f} m), centre {np.round(centre, 3).tolist()} m, tool {orientation}, joint speeds "
                   f"within {VELOCITY_SHARE:.0%} of their limits", q_start, orientation, rotation)
    _CUBES[key] = cube
    return copy.deepcopy(cube)


def ik_seeds_or_derived_rad(robot: RobotModel, seeds_deg: Sequence[Sequence[float]] | None) -> np.ndarray:
    """``(k, nq)`` IK seeds: the configured ones (deg) or, when ``None``, :func:`ik_seeds_rad` after the
    start configuration of the default derived cube (:func:`iso_cube`, cached), so that a derived ISO path
    starts on the IK branch the search validated."""
    if seeds_deg is None:
        seeds = ik_seeds_rad(robot)
        try:
            start = iso_cube(robot).q_start_rad
        except InfeasibleError:
            return seeds
        return seeds if start is None else np.vstack([start, seeds])
    return np.radians(np.atleast_2d(np.asarray(seeds_deg, float)))


def iso_or_derived(robot: RobotModel, iso: IsoPathConfig) -> IsoPathConfig:
    """A copy of the ISO path settings with ``centre_m`` / ``edge_m`` / ``speed_m_s`` /
    ``tool_orientation`` left ``None`` filled from :func:`iso_cube` (the search runs only when the cube
    is missing; a given cube keeps the tool down unless told otherwise)."""
    if iso.centre_m is not None and iso.edge_m is not None and iso.speed_m_s is not None:
        if iso.tool_orientation is not None:
            return iso
        out = copy.copy(iso)
        out.tool_orientation = "down"
        return out
    out = copy.copy(iso)
    cube = iso_cube(robot, iso.plane, iso.tool_orientation, 1.0 if iso.speed_m_s is None else iso.speed_m_s)
    out.tool_orientation = cast(ToolOrientation, cube.orientation)     # one of TOOL_ORIENTATIONS
    if iso.centre_m is None or iso.edge_m is None:
        out.centre_m, out.edge_m = [float(v) for v in cube.centre_m], float(cube.edge_m)
    if iso.speed_m_s is None or ((iso.centre_m is None or iso.edge_m is None) and cube.speed_m_s < iso.speed_m_s):
        out.speed_m_s = cube.speed_m_s       # a derived cube that no joint speeds allow at the configured speed
    return out
