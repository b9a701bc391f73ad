"""The in-silico cell of paper 000 §3.2 and its robots: obstacles, tracker, working pose, baselines.

Paper 000 (``papers/000_bd0c20fcd494d4a1.txt``, §3.2 "Experimental setup", Figure 6): the arm is
mounted on a long object next to a wall; the laser tracker stands "in the left corner in the line of
sight of the manipulator"; a car directly in front is measured and is an obstacle ("modeled by two
capsules"); the wall behind the arm bounds every capsule in x; no capsule below the ground; the
laser beam is a thin capsule that must clear the arm and the car. Table 5 (the numbers) is not in
the extracted text, so the cell below is ours, scaled with the arm's reach ``R`` (flange reach of
``RobotModel.summary``, KR 15: 1.73 m; the car keeps its size):

- mount: a capsule of radius 0.4 m along y under the base (top at z = 0), length 4 R; the ground
  is 0.8 m below the base (``collision.floor_z_m = -0.8``);
- wall: the plane x = -0.6 R, as a capsule of radius 100 m whose vertical axis lies 100 m behind
  it (the surface deviates from the plane by y^2 / 200 m: 2 cm at |y| = 2 m, on the permissive side);
- car: body capsule along y at x = 0.45 R + 0.6 m, z = -0.2 m (ground + 0.6 m), radius 0.6 m,
  half-length 2 m; cabin capsule 0.6 m higher, radius 0.45 m, half-length 1 m;
- tracker: (0.3 R, 1.5 R, 0.5 m), to the left (+y) of the arm facing the car (+x);
- working configuration (the KPI, §3.1: one ``q_work``): the collision-free configuration whose
  TCP is nearest to a point 0.25 m in front of the car's side at cabin height.

Constraints with collision avoidance (CA): joint limits, incidence <= 30°, self collision, ground,
mount, wall, car and the beam clear of arm and obstacles (the existing capsule machinery,
:func:`pipeline.calibration.gradient_design.feasible_configurations`). Without CA: joint limits
and incidence only (paper §3.3.2 "without consideration of collision avoidance").

Baselines:
- :func:`random_design`: the paper's own "heuristic" (§3.2: "randomly and uniformly chosen from
  the motion range"), restricted to measurable collision-free configurations;
- :func:`spread_design`: what an experimenter would choose by hand: configurations spread over the
  joint ranges (farthest-point selection in joint space normalised by each range) and symmetric
  (each pose with its mirror about the range centres of axes 1, 4 and 6 when that is feasible),
  from the same feasible candidates, the same count.

Notional arms (§3.2): ``lambda`` (segment two, a2) in 650..1100 mm and ``mu`` (segment four, d4)
in 600..1000 mm on the KR 15 kinematics (:func:`notional_arm`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from pipeline.calibration import candidates as cd
from pipeline.calibration.gradient_design import feasible_configurations
from pipeline.core.errors import InfeasibleError
from pipeline.robot.collision import segment_distances
from pipeline.robot.mdh import MDHRow
from pipeline.robot.model import RobotModel

Obstacle = tuple[np.ndarray, np.ndarray, float]

MOUNT_RADIUS_M = 0.4
GROUND_Z_M = -2 * MOUNT_RADIUS_M
WALL_RADIUS_M = 100.0
CAR_BODY_RADIUS_M = 0.6
CAR_CABIN_RADIUS_M = 0.45
#: segment two and four lengths of the 90 notional arms (paper 000 §3.2)
LAMBDA_M = tuple(np.round(np.arange(0.65, 1.1001, 0.05), 3))
MU_M = tuple(np.round(np.arange(0.60, 1.0001, 0.05), 3))


@dataclass
class Scene:
    """The cell of one arm: obstacle capsules ``(p0, p1, radius_m)`` in the base frame."""

    reach_m: float
    obstacles: list[Obstacle]
    names: list[str]
    tracker: pin.SE3
    work_target_m: np.ndarray
    floor_z_m: float = GROUND_Z_M
    notes: dict = field(default_factory=dict)


def fms_scene(robot: RobotModel) -> Scene:
    """The flexible-measurement-system cell of paper 000 §3.2 for ``robot`` (module docstring)."""
    R = float(robot.summary()["reach_m"])
    xc = 0.45 * R + CAR_BODY_RADIUS_M
    zc = GROUND_Z_M + CAR_BODY_RADIUS_M
    xw = -0.6 * R
    obstacles: list[Obstacle] = [
        (np.array([0.0, -2 * R, -MOUNT_RADIUS_M]), np.array([0.0, 2 * R, -MOUNT_RADIUS_M]), MOUNT_RADIUS_M),
        (np.array([xw - WALL_RADIUS_M, 0.0, GROUND_Z_M - 1.0]), np.array([xw - WALL_RADIUS_M, 0.0, 3 * R]),
         WALL_RADIUS_M),
        (np.array([xc, -2.0, zc]), np.array([xc, 2.0, zc]), CAR_BODY_RADIUS_M),
        (np.array([xc, -1.0, zc + 0.6]), np.array([xc, 1.0, zc + 0.6]), CAR_CABIN_RADIUS_M),
    ]
    tracker = pin.SE3(np.eye(3), np.array([0.3 * R, 1.5 * R, 0.5]))
    target = np.array([xc - CAR_CABIN_RADIUS_M - 0.25, 0.0, zc + 0.6])
    return Scene(R, obstacles, ["mount", "wall", "car body", "car cabin"], tracker, target,
                 notes={"wall_x_m": xw, "car_x_m": xc, "tracker_m": tracker.translation.tolist()})


def scene_robot(robot: RobotModel, scene: Scene, collision_avoidance: bool = True) -> RobotModel:
    """``robot`` with the cell's tracker pose and ground; without CA its capsules are dropped (no
    self, ground or beam constraints)."""
    spec = copy.deepcopy(robot.spec)
    spec.tracker.transform_tracker_to_base = scene.tracker
    spec.collision.floor_z_m = scene.floor_z_m
    if not collision_avoidance:
        spec.capsules = []
    return robot.with_model(robot.model.copy(), spec)


def obstacles_of(scene: Scene, collision_avoidance: bool) -> list[Obstacle]:
    return scene.obstacles if collision_avoidance else []


def candidate_pool(robot: RobotModel, scene: Scene, n: int, rng: np.random.Generator,
                   collision_avoidance: bool = True) -> np.ndarray:
    """``n`` random configurations feasible in the cell (with CA: every rule; without: limits and
    incidence only), filtered with margins by the batched chain, then exactly."""
    arm = scene_robot(robot, scene, collision_avoidance)
    chain = cd.chain_from_robot(arm)
    out, have = [], 0
    for _ in range(20):
        Q, _ = cd.random_candidates(chain, int(1.6 * (n - have)) + 20, rng)
        if collision_avoidance:
            Q = Q[feasible_configurations(arm, Q, scene.tracker, scene.obstacles)]
        out.append(Q)
        have += len(Q)
        if have >= n:
            break
    return np.concatenate(out)[:n]


def working_configuration(robot: RobotModel, scene: Scene, rng: np.random.Generator, n: int = 1500) -> np.ndarray:
    """The collision-free configuration (no visibility needed) whose TCP is nearest to the cell's
    working point (paper 000 §3.1: one working configuration ``q_work``), the arm facing the car
    (|q1| <= 45°)."""
    arm = scene_robot(robot, scene, True)
    chain = copy.deepcopy(cd.chain_from_robot(arm))
    chain.lower[0], chain.upper[0] = max(chain.lower[0], -np.pi / 4), min(chain.upper[0], np.pi / 4)
    Q, _ = cd.random_candidates(chain, n, rng, visibility=False)
    seg = arm.capsule_segments(Q)
    ok = np.ones(len(Q), bool)
    for o0, o1, r_o in scene.obstacles:
        for c, cap in enumerate(arm.capsules):
            if arm.model.frames[arm.frame_id(cap.frame)].parentJoint >= 1:
                d = segment_distances(seg[:, c, 0], seg[:, c, 1], np.broadcast_to(o0, (len(Q), 3)),
                                         np.broadcast_to(o1, (len(Q), 3)))
                ok &= d >= cap.radius_m + r_o
    Q = Q[ok]
    if not len(Q):
        raise InfeasibleError(None, "calib-000", f"{robot.name}: no collision-free configuration facing the car "
                              "(|q1| <= 45°) in the cell")
    tcp = arm.positions(Q, arm.frame_tcp)
    return Q[int(np.argmin(np.linalg.norm(tcp - scene.work_target_m, axis=1)))]


def random_design(pool: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Paper 000's heuristic: ``n`` uniformly random configurations (of the feasible pool)."""
    return pool[rng.choice(len(pool), size=n, replace=False)]


def _mirror(robot: RobotModel, Q: np.ndarray) -> np.ndarray:
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    M = Q.copy()
    for j in (0, 3, 5):
        if j < Q.shape[1]:
            M[:, j] = lo[j] + hi[j] - Q[:, j]
    return M


def spread_design(robot: RobotModel, scene: Scene, pool: np.ndarray, n: int) -> np.ndarray:
    """An experimenter's hand-made design (module docstring): farthest-point selection over the
    normalised joint ranges, each pose followed by its mirror when the mirror is feasible."""
    arm = scene_robot(robot, scene, True)
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    mirrors = _mirror(robot, pool)
    mirror_ok = feasible_configurations(arm, mirrors, scene.tracker, scene.obstacles)
    X = (pool - lo) / (hi - lo)
    Xm = (mirrors - lo) / (hi - lo)
    centre = np.full(pool.shape[1], 0.5)
    chosen: list[np.ndarray] = []
    dist = np.full(len(pool), np.inf)
    k = int(np.argmin(np.linalg.norm(X - centre, axis=1)))   # start near the middle of the ranges
    while len(chosen) < n:
        chosen.append(pool[k])
        dist = np.minimum(dist, np.linalg.norm(X - X[k], axis=1))
        if mirror_ok[k] and len(chosen) < n:
            chosen.append(mirrors[k])
            dist = np.minimum(dist, np.linalg.norm(X - Xm[k], axis=1))
        dist[k] = -1.0
        k = int(np.argmax(dist))
    return np.array(chosen)


def notional_arm(base: RobotModel, lambda_m: float, mu_m: float) -> RobotModel:
    """``base`` (a KUKA-type MDH arm) with segment two ``a2 = lambda`` and segment four ``d4 = mu``
    (paper 000 §3.2); the upper-arm, elbow and forearm capsules follow the new lengths."""
    model = base.model.copy()
    a3 = -float(model.jointPlacements[4].translation[0])
    model.jointPlacements[3] = MDHRow(0.0, lambda_m, -np.pi / 2, 0.0).placement()
    model.jointPlacements[4] = MDHRow(-np.pi / 2, -a3, 0.0, mu_m).placement()
    spec = copy.deepcopy(base.spec)
    caps = {c.name: c for c in spec.capsules}
    caps["upper_arm"].p1 = np.array([lambda_m, 0.0, 0.0])
    caps["elbow"].p1 = np.array([-a3, 0.25 * mu_m, 0.0])
    start = mu_m - (caps["upper_arm"].radius_m + caps["forearm"].radius_m) - 0.05
    caps["forearm"].p0 = np.array([0.0, 0.0, -start])
    return base.with_model(model, spec)
