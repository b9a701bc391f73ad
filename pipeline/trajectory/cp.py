"""Time-optimal continuous-path (CP) parametrisation (paper 004 section 5.1; Verscheure 2009).

Given a joint path ``q(s)``, ``s in [0, 1]``, find ``s(t)`` minimising the duration under
joint velocity and torque limits. With ``b = sdot^2`` and ``a = sddot`` (piecewise constant on
the grid intervals, so ``b`` is piecewise linear: ``b_{k+1} = b_k + 2 a_k ds``):

    tau(s) = m(s) a + c(s) b + g(s) + F_c sign(q'(s))           (convex step)
    T = sum_k 2 ds / (sqrt(b_k) + sqrt(b_{k+1}))

The convex step writes the objective with second-order-cone slacks (DESIGN.md "Measured
facts": ``1/sqrt(b)`` is singular at rest):  ``e_k^2 <= b_k``,  ``d_k (e_k + e_{k+1}) >= 1``,
minimise ``sum 2 ds d_k``. Torques and velocities are constrained at the start, midpoint and
end of every interval (where ``b`` is exactly known because ``a`` is constant there).

The refinement is the non-convex problem in ``x = sdot`` (warm-started from the convex
solution) with the full friction model

    tau = m a + c x^2 + g + F_v q' x + F_c tanh(q' x / w),   a_k = (x_{k+1}^2 - x_k^2) / (2 ds)

and the smooth variant (:func:`pipeline.trajectory.cp_smooth.solve_cp_smooth`, warm-started from
these) is a time-domain problem with continuous joint velocity, acceleration and jerk.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from pipeline.core.errors import InfeasibleError, SolverError
from pipeline.core.interrupts import raise_if_interrupted
from pipeline.trajectory.design import JointPath
from pipeline.trajectory.dynamics import PlanningModel, path_coefficients
from pipeline.trajectory.trajectories import JointTrajectory

#: a constraint counts as active at this fraction of its limit (paper 004 Fig. 8)
CP_ACTIVE_LEVEL = 0.98

#: IPOPT options of the CP problems (quiet, tight tolerance; :mod:`.cp_smooth` tightens its own)
IPOPT_OPTIONS: dict[str, Any] = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                          "ipopt.tol": 1e-9, "ipopt.acceptable_tol": 1e-6, "ipopt.max_iter": 3000}
#: IPOPT from the given primal and dual point, small barrier: a re-solve from the previous solution
#: takes 1-3 iterations instead of ~30; the first solve starts from the (close) convex optimum
_WARM_START: dict[str, Any] = {"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                               "ipopt.warm_start_bound_push": 1e-9, "ipopt.warm_start_mult_bound_push": 1e-9,
                               "ipopt.warm_start_slack_bound_push": 1e-9}


@dataclass
class CPProfile:
    """Path velocity profile on a grid: ``sdot`` at grid points, ``sddot`` per interval."""

    name: str
    s: np.ndarray
    sdot: np.ndarray
    sddot: np.ndarray
    duration_s: float
    solve_time_s: float
    info: dict = field(default_factory=dict)
    #: IPOPT's (lam_x, lam_g) of an NLP solution: the dual warm start of a re-solve
    multipliers: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    #: the built NLP that produced it (re-solves with other limits reuse it)
    nlp: object = field(default=None, repr=False)

    def grid_times(self) -> np.ndarray:
        ds = np.diff(self.s)
        dt = 2.0 * ds / np.maximum(self.sdot[:-1] + self.sdot[1:], 1e-300)
        return np.concatenate([[0.0], np.cumsum(dt)])

    def sample(self, path: JointPath, dt_s: float) -> JointTrajectory:
        """Exact samples of q, v, a every ``dt_s`` (piecewise constant sddot per interval)."""
        tk = self.grid_times()
        t = np.arange(0.0, tk[-1], dt_s)
        t = np.append(t, tk[-1]) if tk[-1] - t[-1] > 1e-12 else t
        k = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, len(self.sddot) - 1)
        tau = t - tk[k]
        s = np.clip(self.s[k] + self.sdot[k] * tau + 0.5 * self.sddot[k] * tau**2, 0.0, self.s[-1])
        sd = np.maximum(self.sdot[k] + self.sddot[k] * tau, 0.0)
        sdd = self.sddot[k]
        q, dq, ddq = path.derivatives(s)
        v = dq * sd[:, None]
        a = ddq * (sd**2)[:, None] + dq * sdd[:, None]
        return JointTrajectory(self.name, t, q, v, a, info={"profile": self.name})

    def time_scaled(self, factor: float, name: str | None = None) -> CPProfile:
        """The same path ``factor`` times slower: ``sdot / factor``, ``sddot / factor²``, duration x factor
        (``info["time_scale"]``)."""
        return CPProfile(name or self.name, self.s.copy(), self.sdot / factor, self.sddot / factor**2,
                         self.duration_s * factor, self.solve_time_s, {**self.info, "time_scale": float(factor)})


def check_solver(solver: ca.Function, what: str) -> dict:
    """The solver's statistics after a successful solve; else :class:`InfeasibleError` (IPOPT finds the limits
    cannot be met) or :class:`SolverError`, naming ``what``."""
    stats = solver.stats()
    if not stats.get("success", False):
        status = stats.get("return_status", "unknown")
        raise_if_interrupted(status, what)
        if status in ("Infeasible_Problem_Detected", "Local_Infeasibility"):
            raise InfeasibleError(None, what, f"IPOPT reports the limits cannot be met ({status})")
        raise SolverError(None, what, f"IPOPT failed: {status}")
    return stats


def _eval_points(path: JointPath, s: np.ndarray, midpoints: bool) -> tuple[np.ndarray, list]:
    """Evaluation points: interval starts, midpoints and ends (or grid points only)."""
    if midpoints:
        sm = 0.5 * (s[:-1] + s[1:])
        return np.concatenate([s[:-1], sm, s[1:]]), ["start", "mid", "end"]
    return s[:-1].copy(), ["start"]


def _check_static(pm: PlanningModel, s: np.ndarray, g: np.ndarray, tau_max: np.ndarray, name: str) -> None:
    """No parametrisation exists if holding the path still already exceeds a torque limit."""
    over = np.abs(g) > tau_max
    if over.any():
        k, j = np.argwhere(over)[0]
        raise InfeasibleError(None, f"{name} at s = {s[k]:.3f} joint {j + 1} torque limit",
                              f"holding torque + Coulomb friction {g[k, j]:.1f} N·m exceeds the limit "
                              f"{tau_max[j]:.1f} N·m even at crawling speed")


def _velocity_bound_b(pm: PlanningModel, dq: np.ndarray) -> np.ndarray:
    """Upper bound on b = sdot^2 from joint speed limits at points with path tangent dq."""
    with np.errstate(divide="ignore"):
        r = pm.velocity_rad_s / np.abs(dq)
    return np.min(r, axis=1) ** 2


def solve_cp_convex(pm: PlanningModel, path: JointPath, n_grid: int = 400, midpoints: bool = True,
                    coulomb: bool = True, name: str = "cp_convex",
                    torque_scale: float = 1.0, acceleration_limits: bool = False) -> CPProfile:
    """Convex minimum-time problem (rigid body + sharp Coulomb), SOC objective, IPOPT.

    ``torque_scale`` shrinks the torque limits (used to leave margin for unmodelled terms);
    ``acceleration_limits`` adds ``|q'' b + q' a| <= pm.acceleration_rad_s2`` at the same points.
    """
    t0 = time.perf_counter()
    N = int(n_grid)
    s = np.linspace(0.0, 1.0, N + 1)
    ds = s[1] - s[0]
    pts, kinds = _eval_points(path, s, midpoints)
    q, dq, ddq = path.derivatives(pts)
    pc = path_coefficients(pm, pts, q, dq, ddq)
    fc = pm.coulomb_Nm * np.sign(dq) if coulomb else np.zeros_like(dq)
    tau_max = pm.effort_Nm * torque_scale
    _check_static(pm, pts, pc.g + fc, tau_max, path.name)

    b = ca.SX.sym("b", N + 1)
    a = ca.SX.sym("a", N)
    e = ca.SX.sym("e", N + 1)
    d = ca.SX.sym("d", N)
    # b at each evaluation point, a of the interval it belongs to
    b_pts = [b[:-1], 0.5 * (b[:-1] + b[1:]), b[1:]][: len(kinds)]
    if not midpoints:
        b_pts = [b[:-1]]
    b_p = ca.vertcat(*b_pts)
    a_p = ca.vertcat(*([a] * len(kinds)))
    n_p = pts.size
    A_p = ca.repmat(a_p, 1, pm.nq)
    B_p = ca.repmat(b_p, 1, pm.nq)
    tau = pc.m * A_p + pc.c * B_p + (pc.g + fc)
    tau_scaled = tau / np.tile(tau_max, (n_p, 1))
    g_dyn = b[1:] - b[:-1] - 2.0 * ds * a
    g_soc1 = b - e**2
    g_soc2 = d * (e[:-1] + e[1:])
    vb = _velocity_bound_b(pm, dq)
    g_list = [g_dyn, ca.vec(tau_scaled), g_soc1, g_soc2]
    lbg = [np.zeros(N), -np.ones(n_p * pm.nq), np.zeros(N + 1), np.ones(N)]
    ubg = [np.zeros(N), np.ones(n_p * pm.nq), np.full(N + 1, np.inf), np.full(N, np.inf)]
    if acceleration_limits:
        acc = (ddq * B_p + dq * A_p) / np.tile(pm.acceleration_rad_s2, (n_p, 1))
        g_list.append(ca.vec(acc))
        lbg.append(-np.ones(n_p * pm.nq))
        ubg.append(np.ones(n_p * pm.nq))
    # velocity limits: grid points as simple bounds, midpoints as linear constraints
    ub_b = np.full(N + 1, np.inf)
    ub_b[:-1] = np.minimum(ub_b[:-1], vb[:N])
    if midpoints:
        ub_b[1:] = np.minimum(ub_b[1:], vb[2 * N:])
        g_list.append(b_pts[1])
        lbg.append(np.zeros(N))
        ubg.append(vb[N:2 * N])
    else:
        qN, dqN, _ = path.derivatives(s[-1:])
        ub_b[-1] = min(ub_b[-1], _velocity_bound_b(pm, dqN)[0])
    ub_b[0] = ub_b[-1] = 0.0  # rest to rest
    x = ca.vertcat(b, a, e, d)
    nlp = {"x": x, "f": 2.0 * ds * ca.sum1(d), "g": ca.vertcat(*g_list)}
    solver = ca.nlpsol(name, "ipopt", nlp, IPOPT_OPTIONS)
    # initial guess: a fraction of the speed limit
    b0 = np.minimum(ub_b, 0.1 * np.min(ub_b[1:-1]))
    b0[0] = b0[-1] = 0.0
    e0 = np.sqrt(b0)
    d0 = 1.0 / np.maximum(e0[:-1] + e0[1:], 1e-3)
    a0 = np.diff(b0) / (2 * ds)
    lbx = np.concatenate([np.zeros(N + 1), np.full(N, -np.inf), np.zeros(N + 1), np.zeros(N)])
    ubx = np.concatenate([ub_b, np.full(N, np.inf), np.full(N + 1, np.inf), np.full(N, np.inf)])
    sol = solver(x0=np.concatenate([b0, a0, e0, d0]), lbx=lbx, ubx=ubx,
                 lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    stats = check_solver(solver, f"{name} (convex CP, N={N})")
    xs = np.asarray(sol["x"]).ravel()
    bs = np.maximum(xs[: N + 1], 0.0)
    sd = np.sqrt(bs)
    sdd = np.diff(bs) / (2 * ds)
    dur = float(np.sum(2 * ds / np.maximum(sd[:-1] + sd[1:], 1e-300)))
    return CPProfile(name, s, sd, sdd, dur, time.perf_counter() - t0,
                     info={"iterations": int(stats["iter_count"]), "objective_s": float(sol["f"]),
                           "midpoints": midpoints, "coulomb": coulomb, "n_grid": N, "method": "nlp",
                           "solver_status": stats["return_status"], "acceleration_limits": acceleration_limits})


def _fric_sx(pm: PlanningModel, dq: np.ndarray, x: ca.SX) -> ca.SX:
    """Full friction along the path for path speeds ``x`` (column) at tangents dq (n, nq)."""
    X = ca.repmat(x, 1, pm.nq)
    qd = dq * X
    n = dq.shape[0]
    return (np.tile(pm.viscous_Nms_rad, (n, 1)) * qd
            + np.tile(pm.coulomb_Nm, (n, 1)) * ca.tanh(qd / np.tile(pm.coulomb_smoothing_rad_s, (n, 1))))


@dataclass
class _RefinedNLP:
    """The refinement NLP of one path, grid and model, built once: the torque limits are the bounds
    ``-scale <= tau / tau_max <= scale`` of its first rows, so a re-solve with tightened limits
    calls the same solver (building it costs more than a solve)."""

    key: tuple
    solver: ca.Function
    lbg: np.ndarray
    ubg: np.ndarray
    ubx: np.ndarray
    n_kinds: int


def _refined_nlp(pm: PlanningModel, path: JointPath, s: np.ndarray, midpoints: bool, name: str,
                 torque_margin: float, acceleration_limits: bool) -> _RefinedNLP:
    N = len(s) - 1
    ds = s[1] - s[0]
    pts, kinds = _eval_points(path, s, midpoints)
    q, dq, ddq = path.derivatives(pts)
    pc = path_coefficients(pm, pts, q, dq, ddq)
    tau_max = pm.effort_Nm * (1.0 - torque_margin)
    x = ca.SX.sym("x", N + 1)
    b = x**2
    a = (b[1:] - b[:-1]) / (2 * ds)
    bm = 0.5 * (b[:-1] + b[1:])
    xs = [x[:-1], ca.sqrt(bm + 1e-14), x[1:]][: len(kinds)]
    bs = [b[:-1], bm, b[1:]][: len(kinds)]
    x_p, B_p = ca.vertcat(*xs), ca.repmat(ca.vertcat(*bs), 1, pm.nq)
    A_p = ca.repmat(ca.vertcat(*([a] * len(kinds))), 1, pm.nq)
    n_p = pts.size
    tau = pc.m * A_p + pc.c * B_p + pc.g + _fric_sx(pm, dq, x_p)
    vb = np.sqrt(_velocity_bound_b(pm, dq))
    g_list = [ca.vec(tau / np.tile(tau_max, (n_p, 1)))]
    lbg, ubg = [-np.ones(n_p * pm.nq)], [np.ones(n_p * pm.nq)]
    if acceleration_limits:
        g_list.append(ca.vec((ddq * B_p + dq * A_p) / np.tile(pm.acceleration_rad_s2, (n_p, 1))))
        lbg.append(-np.ones(n_p * pm.nq))
        ubg.append(np.ones(n_p * pm.nq))
    ubx = np.full(N + 1, np.inf)
    ubx[:-1] = np.minimum(ubx[:-1], vb[:N])
    if midpoints:
        ubx[1:] = np.minimum(ubx[1:], vb[2 * N:])
        g_list.append(xs[1])
        lbg.append(np.zeros(N))
        ubg.append(vb[N:2 * N])
    ubx[0] = ubx[-1] = 0.0
    f = ca.sum1(2 * ds / (x[:-1] + x[1:] + 1e-12))
    solver = ca.nlpsol(name, "ipopt", {"x": x, "f": f, "g": ca.vertcat(*g_list)}, {**IPOPT_OPTIONS, **_WARM_START})
    return _RefinedNLP((pm, path, N, midpoints, torque_margin, acceleration_limits), solver,
                       np.concatenate(lbg), np.concatenate(ubg), ubx, len(kinds))


def _row_bounds(scale: np.ndarray, n_kinds: int, n_intervals: int, nq: int) -> np.ndarray:
    """Bounds (kinds x N, nq) of one block of normalised rows from a scale per joint (nq,) or per
    grid interval and joint (N, nq), the same for each kind of check point of an interval."""
    bound = np.ones((n_kinds * n_intervals, nq))
    return bound * (np.tile(scale, (n_kinds, 1)) if scale.ndim == 2 else scale)


def solve_cp_refined(pm: PlanningModel, path: JointPath, warm: CPProfile, midpoints: bool = True,
                     name: str = "cp", torque_margin: float = 0.0,
                     torque_scale: np.ndarray | None = None, acceleration_limits: bool = False,
                     acceleration_scale: np.ndarray | None = None) -> CPProfile:
    """Non-convex refinement in ``x = sdot`` with viscous + smooth Coulomb friction.

    Warm-started from ``warm`` (same grid): its speeds; when ``warm`` came from this problem (a
    re-solve with tightened limits) also its multipliers and its built solver, so such a re-solve
    takes a few iterations and no build. ``torque_margin`` (e.g. 0.002) or ``torque_scale`` (per
    joint (nq,), or per grid interval and joint (N, nq): only the intervals whose fine samples
    exceed) tighten the torque limits; ``acceleration_limits`` adds the joint acceleration rows,
    which ``acceleration_scale`` (same shapes) tightens likewise.
    """
    t0 = time.perf_counter()
    s = warm.s
    N = len(s) - 1
    ds = s[1] - s[0]
    nlp = warm.nlp
    key = (N, midpoints, torque_margin, acceleration_limits)
    if not (isinstance(nlp, _RefinedNLP) and nlp.key[0] is pm and nlp.key[1] is path and nlp.key[2:] == key):
        nlp = _refined_nlp(pm, path, s, midpoints, name, torque_margin, acceleration_limits)
    lbg, ubg = nlp.lbg.copy(), nlp.ubg.copy()
    # the torque rows, then (acceleration_limits) the acceleration rows: (kinds x N, nq) each, by column
    for block, limit_scale in enumerate((torque_scale, acceleration_scale if acceleration_limits else None)):
        if limit_scale is None:
            continue
        bound = _row_bounds(np.asarray(limit_scale, float), nlp.n_kinds, N, pm.nq).ravel(order="F")
        rows = slice(block * bound.size, (block + 1) * bound.size)
        lbg[rows], ubg[rows] = -bound, bound
    lam = warm.multipliers if warm.nlp is nlp else None
    extra = {"lam_x0": lam[0], "lam_g0": lam[1]} if lam is not None else {}
    sol = nlp.solver(x0=np.minimum(warm.sdot, nlp.ubx), lbx=np.zeros(N + 1), ubx=nlp.ubx, lbg=lbg, ubg=ubg, **extra)
    stats = check_solver(nlp.solver, f"{name} (CP refinement with friction, N={N})")
    sd = np.maximum(np.asarray(sol["x"]).ravel(), 0.0)
    sdd = np.diff(sd**2) / (2 * ds)
    dur = float(np.sum(2 * ds / np.maximum(sd[:-1] + sd[1:], 1e-300)))
    return CPProfile(name, s, sd, sdd, dur, time.perf_counter() - t0,
                     info={"iterations": int(stats["iter_count"]), "midpoints": midpoints, "method": "nlp",
                           "solver_status": stats["return_status"], "acceleration_limits": acceleration_limits,
                           "friction": "viscous+tanh coulomb", "n_grid": N,
                           "torque_margin": torque_margin, "warm_started_multipliers": lam is not None,
                           "torque_scale": None if torque_scale is None else np.asarray(torque_scale).tolist(),
                           "acceleration_scale": (None if acceleration_scale is None
                                                  else np.asarray(acceleration_scale).tolist())},
                     multipliers=(np.asarray(sol["lam_x"]).ravel(), np.asarray(sol["lam_g"]).ravel()), nlp=nlp)


def cp_constraint_activity(pm: PlanningModel, path: JointPath, traj: JointTrajectory,
                           tau: np.ndarray) -> dict:
    """Normalised torques and speeds, and the share of time with some constraint active.

    ``active`` at a sample = max over joints of max(|tau|/tau_max, |v|/v_max) >= 0.98
    (paper 004 Fig. 8: at least one constraint is always active on a time-optimal path).
    """
    tr = np.abs(tau) / pm.effort_Nm
    vr = np.abs(traj.v) / pm.velocity_rad_s
    level = np.maximum(tr.max(axis=1), vr.max(axis=1))
    return {"torque_ratio": tr, "velocity_ratio": vr, "activity": level,
            "active_fraction": float(np.mean(level >= CP_ACTIVE_LEVEL)), "min_activity": float(level.min())}


def cp_grid_activity(pm: PlanningModel, path: JointPath, profile: CPProfile) -> np.ndarray:
    """Per grid point, the largest constraint level of the intervals next to it.

    Level = max over joints and over the interval's check points (start, midpoint, end) of
    ``|tau| / tau_max`` (the limits the profile was solved with: ``torque_margin`` and
    ``torque_scale`` from its info, full friction model) and ``|v| / v_max``. On a minimum-time
    solution of the discretised problem every interior ``sdot_k`` is held down by a constraint
    it enters (else raising it would shorten the motion), so the level is 1 at every grid point:
    the grid form of paper 004 Fig. 8 ("at least one constraint is always active"). Between the
    check points the fine time grid dips below 1 (``a`` is constant per interval, ``b`` is not).
    """
    s, x = profile.s, profile.sdot
    N = len(s) - 1
    ds = np.diff(s)
    b = x**2
    a = (b[1:] - b[:-1]) / (2 * ds)
    pts = np.concatenate([s[:-1], 0.5 * (s[:-1] + s[1:]), s[1:]])
    xs = np.concatenate([x[:-1], np.sqrt(0.5 * (b[:-1] + b[1:])), x[1:]])
    q, dq, ddq = path.derivatives(pts)
    aa = np.tile(a, 3)[:, None]
    v = dq * xs[:, None]
    tau = pm.torques(q, v, ddq * xs[:, None] ** 2 + dq * aa)
    tau_max = pm.effort_Nm * (1.0 - float(profile.info.get("torque_margin") or 0.0))
    if profile.info.get("torque_scale") is not None:
        scale = np.asarray(profile.info["torque_scale"], float)          # per joint, or per interval and joint
        tau_max = tau_max * (np.tile(scale, (3, 1)) if scale.ndim == 2 else scale)
    level = np.maximum(np.abs(tau) / tau_max, np.abs(v) / pm.velocity_rad_s).max(axis=1)
    per_interval = level.reshape(3, N).max(axis=0)
    node = np.empty(N + 1)
    node[0], node[-1] = per_interval[0], per_interval[-1]
    node[1:-1] = np.maximum(per_interval[:-1], per_interval[1:])
    return node
