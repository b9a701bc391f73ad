"""Gradient-based optimum experimental design of n configurations (paper 000, §2.3, eq. 24).

Decision variables: the joint angles ``Q`` (n x nq) of all measurement configurations.
Objective (paper 000 eq. 24a with the KPI covariance ``C_s``): the index of an
:class:`~pipeline.calibration.indices.IndexSpec` of the A type,

    phi(Q) = trace(W M(Q)^-1),   M(Q) = sum_k G_k(q_k)^T G_k(q_k),

``G_k = J_k P / sigma_k`` the whitened identification Jacobian (exact, CasADi AD of the measurement
model at ``x = 0``; with joint compliances the static torques are the symbolic gravity torques
:meth:`pipeline.robot.symbolic.SymbolicRobot.gravity` of the model's gravity model),
``W = J_w^T J_w / n_w`` for the TCP criterion. Constraints per configuration
(paper 000 eqs. 19-24): joint limits (bounds); laser incidence ``cos(beta) >= cos(beta_max - margin)``;
capsule-capsule clearances of non-adjacent links and capsule end points above the floor
``>= margin`` (the shared :func:`pipeline.robot.collision_sx.capsule_clearance_function`,
segment-segment distance in closed form with clamped parameters, Ericson §5.1.9 / Lumelsky,
paper 000 eq. 20); the tracker beam (a thin segment) clear of every link capsule and obstacle and
robot capsules clear of optional obstacle capsules (:func:`~pipeline.robot.collision_sx.segment_distance_sx`).
Distances enter squared, ``d^2 >= (r + margin)^2``: the shared distance is ``sqrt(d.d + 1e-12)``,
so its square is the polynomial ``d.d + 1e-12`` (no square root in the NLP). Measured on 60
rx130l configurations, 200 iterations: with the plain distances 5 configurations of the IPOPT end
point failed the margin-free re-check and were reverted, with the squared ones none.
All kinematics is :class:`pipeline.robot.symbolic.SymbolicRobot` forward kinematics at the nominal
kinematic parameters (``p_kin = 0``), i.e. the same model as the numeric filters and the sensor rule.

Solved by IPOPT (limited-memory Hessian) warm-started from a discrete design (remove-and-replace).
Every configuration of the result is re-checked with the numeric rules (Pinocchio capsules,
:func:`pipeline.robot.instruments.tracker_visibility`, joint limits, obstacles; no margins); a
configuration that fails is replaced by its warm start, so the result is never less feasible than
the start.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from pipeline.calibration import indices as ix
from pipeline.calibration.error_model import MeasurementModel, se3_to_vector
from pipeline.core.interrupts import raise_if_interrupted
from pipeline.robot.collision import segment_distances
from pipeline.robot.collision_sx import capsule_clearance_function, segment_distance_sx
from pipeline.robot.instruments import BEAM_END_CLEARANCE_M, tracker_visibility
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import pinocchio_dynamic_parameters


@dataclass
class GradientDesignConfig:
    max_iterations: int = 200
    margin_collision_m: float = 0.005
    margin_incidence_deg: float = 2.0
    margin_beam_m: float = 0.01
    #: obstacle capsules in the base frame: (p0 (3,), p1 (3,), radius_m)
    obstacles: list = field(default_factory=list)
    #: IPOPT tolerance of the scaled problem (objective / its start value): the first-order optimality
    #: error 1e-3 is a slope of 0.1 % of the index per radian of joint motion
    tol: float = 1e-3
    #: trust region: each joint moves at most this far from the warm start (rad); keeps the local
    #: linearisation of the constraints valid and the L-BFGS problem well conditioned
    max_step_rad: float = 0.3
    print_level: int = 0
    #: IPOPT Hessian: "exact" (CasADi AD) or "limited-memory" (L-BFGS)
    hessian: str = "limited-memory"


@dataclass
class GradientDesignResult:
    Q: np.ndarray
    Q_start: np.ndarray
    index_name: str
    index_value_start: float
    index_value: float
    run_time_s: float
    iterations: int
    evaluations: int
    status: str
    reverted: int
    #: why a configuration of the IPOPT end point was replaced by its warm start (one entry each)
    reverted_reasons: list[str] = field(default_factory=list)
    #: set when the IPOPT result was not used (a non-success status): the warm start is the design
    fallback: str | None = None

    def as_dict(self) -> dict:
        return {"method": "gradient (IPOPT)", "index_name": self.index_name, "fallback": self.fallback,
                "reverted_reasons": self.reverted_reasons,
                "index_value_start": self.index_value_start, "index_value": self.index_value,
                "run_time_s": self.run_time_s, "iterations": self.iterations, "evaluations": self.evaluations,
                "status": self.status, "reverted_configurations": self.reverted,
                "n_configurations": int(len(self.Q))}


def feasible_configurations(robot: RobotModel, Q: np.ndarray, transform_tracker_to_base, obstacles=()) -> np.ndarray:
    """Mask of the rows of ``Q`` inside the joint limits, free of self/floor collision
    (``RobotModel.capsule_clearances >= 0``), measurable (:func:`pipeline.robot.instruments.tracker_visibility`)
    and with the beam and the moving capsules clear of the obstacle capsules ``(p0, p1, radius_m)``."""
    Q = np.atleast_2d(np.asarray(Q, float))
    ok = np.all((Q >= robot.limits.lower_rad) & (Q <= robot.limits.upper_rad), axis=1)
    seg = robot.capsule_segments(Q)
    pair, floor = robot.capsule_clearances(seg)
    ok &= np.all(pair >= 0, axis=1) & np.all(floor >= 0, axis=1)
    ok &= tracker_visibility(robot, transform_tracker_to_base, Q).visible
    if len(obstacles):
        pos = robot.positions(Q, robot.frame_reflector)
        tracker = np.broadcast_to(np.asarray(transform_tracker_to_base.translation, float), pos.shape)
        beam = tracker - pos
        beam_end = pos + BEAM_END_CLEARANCE_M * beam / np.linalg.norm(beam, axis=1, keepdims=True)
        moving = [robot.model.frames[robot.frame_id(c.frame)].parentJoint >= 1 for c in robot.capsules]
        for o0, o1, r_o in obstacles:
            o0b, o1b = np.broadcast_to(o0, pos.shape), np.broadcast_to(o1, pos.shape)
            ok &= segment_distances(beam_end, tracker, o0b, o1b) >= r_o
            for c, cap in enumerate(robot.capsules):
                if moving[c]:
                    d = segment_distances(seg[:, c, 0], seg[:, c, 1], o0b, o1b)
                    ok &= d >= cap.radius_m + r_o
    return ok


def gradient_design(robot: RobotModel, mm: MeasurementModel, basis: np.ndarray, Q_start: np.ndarray, spec: ix.IndexSpec,
                    cfg: GradientDesignConfig | None = None, transform_tracker_to_base=None) -> GradientDesignResult:
    """Optimise the joint angles of ``len(Q_start)`` configurations (module docstring).

    ``transform_tracker_to_base``: the tracker pose used for the incidence/beam constraints and the
    Jacobians (default: nominal; better: registered from a few pilot measurements).
    """
    cfg = cfg or GradientDesignConfig()
    t0 = time.perf_counter()
    Q_start = np.asarray(Q_start, float)
    n, nq = Q_start.shape
    P = np.asarray(basis, float)
    p = P.shape[1]
    T0 = transform_tracker_to_base if transform_tracker_to_base is not None else \
        robot.tracker.transform_tracker_to_base
    if spec.name in ix.TRACE_INDICES:
        W = spec.weight_matrix(p)
    else:
        raise ValueError(f"gradient design supports the A-type indices, not {spec.name}")
    tracker_spec = robot.tracker
    lower, upper = np.asarray(robot.limits.lower_rad, float), np.asarray(robot.limits.upper_rad, float)
    radii = [c.radius_m for c in robot.capsules]
    obstacles = [(np.asarray(o0, float), np.asarray(o1, float), float(r_o)) for o0, o1, r_o in cfg.obstacles]

    # per-configuration information matrix as a function of q (exact AD of the measurement model)
    q = ca.SX.sym("q", nq)
    extra: list[ca.SX | ca.DM] = []
    if mm.compliance:   # compliance columns: the gravity torques of mm's dynamic model, symbolic in q
        extra.append(mm.sym.gravity(q, pinocchio_dynamic_parameters(mm.gravity_model)))
    if mm.marker_points:
        extra.append(ca.DM.zeros(3))
    y, J = mm.hj(q, ca.DM.zeros(mm.n), ca.DM(se3_to_vector(T0)), *extra)
    sigma = tracker_spec.noise_const_m + tracker_spec.noise_per_m * ca.norm_2(y)
    G = (J @ ca.DM(P)) / sigma
    info = ca.Function("info", [q], [G.T @ G])
    # constraints of one configuration, on SymbolicRobot FK at the nominal parameters
    sym = mm.sym
    p_kin = ca.DM(sym.nominal_kinematic_parameters())
    p_refl, R_refl = sym.fk(robot.frame_reflector)(q, p_kin)
    axis = R_refl @ ca.DM(np.asarray(robot.reflector_axis, float))   # as tracker_visibility
    caps = []
    for cap in robot.capsules:
        pos, rot = sym.fk(cap.frame)(q, p_kin)
        caps.append((pos + rot @ ca.DM(np.asarray(cap.p0, float)), pos + rot @ ca.DM(np.asarray(cap.p1, float))))
    # capsule of the reflector's own link (rigid, known geometry: a small beam margin only)
    last_joint = robot.model.frames[robot.frame_id(robot.frame_reflector)].parentJoint
    on_last = [robot.model.frames[robot.frame_id(c.frame)].parentJoint == last_joint for c in robot.capsules]
    moving = [robot.model.frames[robot.frame_id(c.frame)].parentJoint >= 1 for c in robot.capsules]
    tracker = ca.DM(np.asarray(T0.translation, float))
    beam = tracker - p_refl
    dist = ca.norm_2(beam)
    g, lb = [], []
    g.append(ca.dot(axis, beam) / dist)
    lb.append(math.cos(max(tracker_spec.max_incidence_rad - math.radians(cfg.margin_incidence_deg), 0.0)))
    # distances enter squared (d^2 >= (r + margin)^2, as in the reference formulation): the
    # shared distance is sqrt(d.d + 1e-12), so its square is the smooth polynomial d.d + 1e-12
    pair_clear, floor_clear = capsule_clearance_function(robot, sym)(q)
    pair_radii = [radii[i] + radii[k] for i, k in robot.self_collision_pairs]
    g.append((pair_clear + ca.DM(pair_radii)) ** 2)
    lb += [(r + cfg.margin_collision_m) ** 2 for r in pair_radii]
    g.append(floor_clear)
    lb += [cfg.margin_collision_m] * floor_clear.numel()
    beam_end = p_refl + BEAM_END_CLEARANCE_M * beam / dist
    for c, (a, b) in enumerate(caps):
        g.append(segment_distance_sx(beam_end, tracker, a, b) ** 2)
        lb.append((radii[c] + (0.001 if on_last[c] else cfg.margin_beam_m)) ** 2)
    for (o0, o1, r_o) in obstacles:
        o0_dm, o1_dm = ca.DM(o0), ca.DM(o1)
        g.append(segment_distance_sx(beam_end, tracker, o0_dm, o1_dm) ** 2)
        lb.append((r_o + cfg.margin_beam_m) ** 2)
        for c, (a, b) in enumerate(caps):
            if moving[c]:
                g.append(segment_distance_sx(a, b, o0_dm, o1_dm) ** 2)
                lb.append((radii[c] + r_o + cfg.margin_collision_m) ** 2)
    cons = ca.Function("cons", [q], [ca.vertcat(*g)], {"cse": True})
    n_g = len(lb)

    # NLP over all configurations (MX graph with mapped SX functions)
    X = ca.MX.sym("Q", nq, n)
    M = ca.MX.zeros(p, p)
    info_map = info.map(n, "serial")
    blocks = info_map(X)
    for k in range(n):
        M = M + blocks[:, k * p : (k + 1) * p]
    phi = ca.trace(ca.solve(M, ca.DM(W), "symbolicqr"))
    phi_f = ca.Function("phi", [X], [phi])
    phi0 = float(phi_f(Q_start.T))
    scale = 1.0 / phi0 if phi0 > 0 and np.isfinite(phi0) else 1.0
    G_all = ca.reshape(cons.map(n, "serial")(X), -1, 1)
    nlp = {"x": ca.reshape(X, -1, 1), "f": scale * phi, "g": G_all}
    opts = {"ipopt.max_iter": cfg.max_iterations, "ipopt.tol": cfg.tol, "ipopt.print_level": cfg.print_level,
            "ipopt.hessian_approximation": cfg.hessian, "print_time": False,
            "ipopt.acceptable_iter": 0, "ipopt.mu_strategy": "adaptive"}
    solver = ca.nlpsol("oed", "ipopt", nlp, opts)
    x0 = np.clip(Q_start.reshape(-1), np.tile(lower, n), np.tile(upper, n))
    lbx = np.maximum(np.tile(lower, n), x0 - cfg.max_step_rad)
    ubx = np.minimum(np.tile(upper, n), x0 + cfg.max_step_rad)
    sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=np.tile(lb, n), ubg=np.full(n * n_g, np.inf))
    stats = solver.stats()
    status = str(stats.get("return_status", ""))
    raise_if_interrupted(status, "calibration design IPOPT")
    Q = np.asarray(sol["x"]).reshape(n, nq)
    fallback = None
    if not stats.get("success", False):   # a non-success status is never the design
        Q = Q_start.copy()
        fallback = f"IPOPT ended with {status}: the remove-and-replace design is kept"
    # re-check every configuration with the numeric rules (no margins) and revert failures
    mask = feasible_configurations(robot, Q, T0, obstacles)
    reasons = [f"configuration {k}: {why}" for k, why in infeasibility_reasons(robot, Q, T0, obstacles, ~mask)]
    Q[~mask] = Q_start[~mask]
    phi_end = float(phi_f(Q.T))
    if not phi_end <= phi0:   # never worse than the warm start
        Q, phi_end = Q_start.copy(), phi0
        fallback = fallback or "after reverting infeasible configurations the index was worse than the warm start's"
    return GradientDesignResult(Q, Q_start, spec.name, phi0, phi_end, time.perf_counter() - t0,
                                int(stats.get("iter_count", -1)),
                                int(stats.get("n_call_nlp_grad_f", 0) + stats.get("n_call_nlp_f", 0)),
                                status, int((~mask).sum()), reasons, fallback)


def infeasibility_reasons(robot: RobotModel, Q: np.ndarray, transform_tracker_to_base, obstacles, which: np.ndarray
                          ) -> list[tuple[int, str]]:
    """(row, rule) for the rows ``which`` of ``Q``: the first numeric rule each one breaks."""
    out = []
    for k in np.flatnonzero(which):
        q = Q[k : k + 1]
        if not np.all((q >= robot.limits.lower_rad) & (q <= robot.limits.upper_rad)):
            out.append((int(k), "outside the joint limits"))
            continue
        pair, floor = robot.capsule_clearances(robot.capsule_segments(q))
        if not (np.all(pair >= 0) and np.all(floor >= 0)):
            out.append((int(k), "capsule collision or below the floor"))
        elif not tracker_visibility(robot, transform_tracker_to_base, q).visible[0]:
            out.append((int(k), "not visible to the tracker (incidence or beam blocked)"))
        else:
            out.append((int(k), "an obstacle capsule"))
    return out
