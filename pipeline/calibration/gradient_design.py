"""Gradient-based optimum experimental design of n configurations (paper 000, §2.3, eq. 24).

Decision variables: the joint angles ``Q`` (n x nq) of all measurement configurations.
Objective (paper 000 eq. 24a with the KPI covariance ``C_s``): the index of an
:class:`~pipeline.calibration.indices.IndexSpec` of the A type,

    phi(Q) = trace(W M(Q)^-1),   M(Q) = sum_k G_k(q_k)^T G_k(q_k),

``G_k = J_k P / sigma_k`` the whitened identification Jacobian (exact, CasADi AD of the measurement
model at ``x = 0``), ``W = J_w^T J_w / n_w`` for the TCP criterion. Constraints per configuration
(paper 000 eqs. 19-24): joint limits (bounds); laser incidence ``cos(beta) >= cos(beta_max - margin)``;
capsule-capsule distances of non-adjacent links ``>= margin`` (segment-segment distance in closed
form with clamped parameters as in Lumelsky's algorithm, paper 000 eq. 20, squared to avoid the
square root); capsule end points above the floor; the tracker beam (a thin segment) clear of every
link capsule and obstacle; robot capsules clear of optional obstacle capsules.

Solved by IPOPT (limited-memory Hessian) warm-started from a discrete design (remove-and-replace).
Every configuration of the result is re-checked with the numpy filter (no margins); a configuration
that fails is replaced by its warm start, so the result is never less feasible than the start.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import indices as ix
from pipeline.calibration.error_model import MeasurementModel, se3_to_vector


@dataclass
class GradientDesignConfig:
    max_iterations: int = 200
    margin_collision_m: float = 0.005
    margin_incidence_deg: float = 2.0
    margin_beam_m: float = 0.01
    #: obstacle capsules in the base frame: (p0 (3,), p1 (3,), radius_m)
    obstacles: list = field(default_factory=list)
    tol: float = 1e-6
    print_level: int = 0


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

    def as_dict(self) -> dict:
        return {"method": "gradient (IPOPT)", "index_name": self.index_name,
                "index_value_start": self.index_value_start, "index_value": self.index_value,
                "run_time_s": self.run_time_s, "iterations": self.iterations, "evaluations": self.evaluations,
                "status": self.status, "reverted_configurations": self.reverted,
                "n_configurations": int(len(self.Q))}


def _rot_axis_sx(axis: np.ndarray, q) -> ca.SX:
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return ca.DM.eye(3) + ca.sin(q) * ca.DM(K) + (1 - ca.cos(q)) * ca.DM(K @ K)


def _fk_sx(chain: cd.Chain, q: ca.SX):
    """Post-motion joint frames (R, o) and the reflector point/axis as SX."""
    R = ca.DM.eye(3)
    o = ca.DM.zeros(3, 1)
    frames = []
    for i in range(chain.nq):
        o = o + R @ ca.DM(chain.p_place[i])
        R = R @ ca.DM(chain.R_place[i]) @ _rot_axis_sx(chain.axis[i], q[i])
        frames.append((R, o))
    p_refl = o + R @ ca.DM(chain.reflector_p)
    axis = R @ ca.DM(chain.reflector_axis_joint)
    return frames, p_refl, axis


def _capsule_world(chain: cd.Chain, frames, c: int):
    j = int(chain.capsule_joint[c])
    a, b = chain.capsule_p[c]
    if j == 0:
        return ca.DM(a), ca.DM(b)
    R, o = frames[j - 1]
    return o + R @ ca.DM(a), o + R @ ca.DM(b)


def segment_distance_sq(p0, p1, q0, q1, eps: float = 1e-9):
    """Squared distance between segments (closed form with clamped parameters; Ericson §5.1.9,
    Lumelsky 1985), continuous and piecewise smooth; ``eps`` regularises parallel segments."""
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = ca.dot(d1, d1)
    e = ca.dot(d2, d2)
    f = ca.dot(d2, r)
    c = ca.dot(d1, r)
    b = ca.dot(d1, d2)
    denom = a * e - b * b + eps

    def clamp(x):
        return ca.fmin(ca.fmax(x, 0), 1)

    s = clamp((b * f - c * e) / denom)
    t = (b * s + f) / (e + eps)
    s = ca.if_else(t < 0, clamp(-c / (a + eps)), ca.if_else(t > 1, clamp((b - c) / (a + eps)), s))
    t = clamp(t)
    diff = p0 + s * d1 - q0 - t * d2
    return ca.dot(diff, diff)


def gradient_design(robot, mm: MeasurementModel, basis: np.ndarray, Q_start: np.ndarray, spec: ix.IndexSpec,
                    cfg: GradientDesignConfig | None = None, transform_tracker_to_base=None) -> GradientDesignResult:
    """Optimise the joint angles of ``len(Q_start)`` configurations (module docstring).

    ``transform_tracker_to_base``: the tracker pose used for the incidence/beam constraints and the
    Jacobians (default: nominal; better: registered from a few pilot measurements).
    """
    cfg = cfg or GradientDesignConfig()
    t0 = time.perf_counter()
    chain = cd.chain_from_robot(robot, transform_tracker_to_base)
    Q_start = np.asarray(Q_start, float)
    n, nq = Q_start.shape
    P = np.asarray(basis, float)
    p = P.shape[1]
    T0 = transform_tracker_to_base if transform_tracker_to_base is not None else \
        robot.tracker.transform_tracker_to_base
    if spec.name in ("A", "tcp_A", "tcp_A_mixed"):
        W = spec.weight_matrix(p)
    else:
        raise ValueError(f"gradient design supports the A-type indices, not {spec.name}")

    # per-configuration information matrix as a function of q (exact AD of the measurement model)
    q = ca.SX.sym("q", nq)
    y, J = mm.hj(q, ca.DM.zeros(mm.n), ca.DM(se3_to_vector(T0)))
    sigma = chain.noise_const_m + chain.noise_per_m * ca.norm_2(y)
    G = (J @ ca.DM(P)) / sigma
    info = ca.Function("info", [q], [G.T @ G])
    # constraints of one configuration
    frames, p_refl, axis = _fk_sx(chain, q)
    tracker = ca.DM(chain.tracker_t)
    beam = tracker - p_refl
    dist = ca.norm_2(beam)
    g, lb = [], []
    g.append(ca.dot(axis, beam) / dist)
    lb.append(math.cos(max(chain.max_incidence_rad - math.radians(cfg.margin_incidence_deg), 0.0)))
    caps = [_capsule_world(chain, frames, c) for c in range(len(chain.capsule_r))]
    for a, b in chain.self_pairs:
        g.append(segment_distance_sq(*caps[a], *caps[b]))
        lb.append((chain.capsule_r[a] + chain.capsule_r[b] + cfg.margin_collision_m) ** 2)
    for c in chain.floor_caps:
        for end in caps[c]:
            g.append(end[2])
            lb.append(chain.floor_z + chain.capsule_r[c] + cfg.margin_collision_m)
    beam_end = p_refl + cd.BEAM_END_CLEARANCE_M * beam / dist
    for c in range(len(chain.capsule_r)):
        margin = 0.001 if chain.capsule_joint[c] == chain.nq else cfg.margin_beam_m
        g.append(segment_distance_sq(beam_end, tracker, *caps[c]))
        lb.append((chain.capsule_r[c] + margin) ** 2)
    for (o0, o1, r_o) in cfg.obstacles:
        o0, o1 = ca.DM(np.asarray(o0, float)), ca.DM(np.asarray(o1, float))
        g.append(segment_distance_sq(beam_end, tracker, o0, o1))
        lb.append((r_o + cfg.margin_beam_m) ** 2)
        for c in range(len(chain.capsule_r)):
            if chain.capsule_joint[c] >= 1:
                g.append(segment_distance_sq(*caps[c], o0, o1))
                lb.append((chain.capsule_r[c] + r_o + cfg.margin_collision_m) ** 2)
    cons = ca.Function("cons", [q], [ca.vertcat(*g)])
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
            "ipopt.hessian_approximation": "limited-memory", "print_time": False,
            "ipopt.acceptable_tol": 1e-4, "ipopt.acceptable_iter": 5, "ipopt.mu_strategy": "adaptive"}
    solver = ca.nlpsol("oed", "ipopt", nlp, opts)
    lbx = np.tile(chain.lower, n)
    ubx = np.tile(chain.upper, n)
    x0 = np.clip(Q_start.reshape(-1), lbx, ubx)
    sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=np.tile(lb, n), ubg=np.full(n * n_g, np.inf))
    stats = solver.stats()
    Q = np.asarray(sol["x"]).reshape(n, nq)
    # re-check every configuration with the numpy rules (no margins) and revert failures
    mask, _ = cd.filter_configurations(chain, Q, cd.FilterMargins(0.0, 0.0, 0.0))
    reverted = int((~mask).sum())
    Q[~mask] = Q_start[~mask]
    phi_end = float(phi_f(Q.T))
    if not phi_end <= phi0:   # never worse than the warm start
        Q, phi_end = Q_start.copy(), phi0
    return GradientDesignResult(Q, Q_start, spec.name, phi0, phi_end, time.perf_counter() - t0,
                                int(stats.get("iter_count", -1)),
                                int(stats.get("n_call_nlp_grad_f", 0) + stats.get("n_call_nlp_f", 0)),
                                str(stats.get("return_status", "")), reverted)
