"""Smooth time-optimal continuous-path (CP) parametrisation (paper 004 section 5: "continuous
velocities, accelerations, and jerks").

A time-domain problem, warm-started from the path-domain optimum of :mod:`pipeline.trajectory.cp`:
``s(t)`` is a chain of four integrators (s, sdot, sddot, sdddot) driven by piecewise-constant snap
on K intervals of ``h = T/K``, rest to rest, so the joint velocity ``q' sdot``, acceleration
``q'' sdot^2 + q' sddot`` and jerk ``q''' sdot^3 + 3 q'' sdot sddot + q' sdddot`` are continuous;
minimise ``T`` under torque (full friction model), joint speed and joint jerk bounds (CasADi/IPOPT).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from pipeline.trajectory.cp import IPOPT_OPTIONS, CPProfile, check_solver
from pipeline.trajectory.design import JointPath
from pipeline.trajectory.dynamics import PlanningModel, path_coefficients
from pipeline.trajectory.trajectories import JointTrajectory


@dataclass
class SmoothCPResult:
    """Time-domain smooth CP solution: path states at K+1 nodes, snap per interval."""

    name: str
    duration_s: float
    t_nodes_s: np.ndarray
    states: np.ndarray  # (K+1, 4): s, sdot, sddot, sdddot
    snap: np.ndarray    # (K,)
    jerk_limit_rad_s3: np.ndarray
    solve_time_s: float
    info: dict = field(default_factory=dict)

    def sample(self, path: JointPath, dt_s: float) -> JointTrajectory:
        """Exact samples of the chain of integrators; q, v, a from the joint path."""
        T = self.duration_s
        K = len(self.snap)
        h = T / K
        t = np.append(np.arange(0.0, T, dt_s), T)
        k = np.clip((t / h).astype(int), 0, K - 1)
        tau = t - k * h
        x0 = self.states[k]
        u = self.snap[k]
        s = x0[:, 0] + x0[:, 1] * tau + x0[:, 2] * tau**2 / 2 + x0[:, 3] * tau**3 / 6 + u * tau**4 / 24
        sd = x0[:, 1] + x0[:, 2] * tau + x0[:, 3] * tau**2 / 2 + u * tau**3 / 6
        sdd = x0[:, 2] + x0[:, 3] * tau + u * tau**2 / 2
        s = np.clip(s, 0.0, 1.0)
        q, dq, ddq = path.derivatives(s)
        v = dq * sd[:, None]
        a = ddq * (sd**2)[:, None] + dq * sdd[:, None]
        return JointTrajectory(self.name, t, q, v, a, info={"profile": self.name})


def _propagate(x: ca.SX, u: ca.SX, h: ca.SX) -> ca.SX:
    """Chain of four integrators (s, sdot, sddot, sdddot) under constant snap u for time h."""
    s, sd, sdd, sddd = x[0], x[1], x[2], x[3]
    return ca.vertcat(s + h * sd + h**2 / 2 * sdd + h**3 / 6 * sddd + h**4 / 24 * u,
                      sd + h * sdd + h**2 / 2 * sddd + h**3 / 6 * u,
                      sdd + h * sddd + h**2 / 2 * u,
                      sddd + h * u)


def solve_cp_smooth(pm: PlanningModel, path: JointPath, warm: CPProfile, n_intervals: int = 120,
                    jerk_rise_time_s: float = 0.05, n_table: int = 801, name: str = "cp_smooth",
                    torque_margin: float = 0.0, acceleration_limits: bool = False) -> SmoothCPResult:
    """Minimum time with continuous joint velocity, acceleration and jerk (paper 004 section 5).

    ``s(t)`` is driven by piecewise-constant snap through four integrators (K intervals of
    ``h = T/K``), rest to rest with zero path acceleration and jerk at both ends, so
    ``q_dot = q' sdot``, ``q_ddot = q'' sdot^2 + q' sddot`` and
    ``q_dddot = q''' sdot^3 + 3 q'' sdot sddot + q' sdddot`` are continuous. Constraints: full
    friction torques at nodes and midpoints, joint speeds at nodes, and joint jerks at nodes
    bounded by ``|q_ddot|_max / jerk_rise_time_s`` (the peak acceleration of the non-smooth
    optimum ``warm`` reached in that rise time); with ``acceleration_limits`` joint accelerations at
    nodes and midpoints within ``(1 - torque_margin) * pm.acceleration_rad_s2``. Path functions
    are cubic B-spline tables.
    """
    t0 = time.perf_counter()
    K = int(n_intervals)
    st = np.linspace(0.0, 1.0, n_table)
    q, dq, ddq = path.derivatives(st)
    d3q = path(st, 3)
    pc = path_coefficients(pm, st, q, dq, ddq)
    # jerk limit from the time-optimal solution's peak accelerations
    tr = warm.sample(path, 1e-3)
    a_peak = np.maximum(np.max(np.abs(tr.a), axis=0), 1e-3)
    jmax = a_peak / jerk_rise_time_s

    def interp(nm: str, arr: np.ndarray) -> ca.Function:
        return ca.interpolant(nm, "bspline", [st], np.asarray(arr, float).ravel(order="C"))

    f_dq, f_ddq, f_d3q = interp("dq", dq), interp("ddq", ddq), interp("d3q", d3q)
    f_m, f_c, f_g = interp("m", pc.m), interp("c", pc.c), interp("g", pc.g)
    T = ca.SX.sym("T")
    X = ca.SX.sym("X", 4, K + 1)
    U = ca.SX.sym("U", K)
    h = T / K
    g_dyn, g_tau, g_v, g_j, g_a = [], [], [], [], []
    tau_max = pm.effort_Nm * (1.0 - torque_margin)
    acc_max = pm.acceleration_rad_s2 * (1.0 - torque_margin)

    def joint_acc(x: ca.SX) -> ca.SX:
        return (f_ddq(x[0]) * x[1] ** 2 + f_dq(x[0]) * x[2]) / acc_max

    def torque(x: ca.SX) -> ca.SX:
        s = x[0]
        qd = f_dq(s) * x[1]
        fr = pm.viscous_Nms_rad * qd + pm.coulomb_Nm * ca.tanh(qd / ca.DM(pm.coulomb_smoothing_rad_s))
        return (f_m(s) * x[2] + f_c(s) * x[1] ** 2 + f_g(s) + fr) / tau_max

    for k in range(K + 1):
        x = X[:, k]
        g_tau.append(torque(x))
        g_v.append(f_dq(x[0]) * x[1] / pm.velocity_rad_s)
        g_j.append((f_d3q(x[0]) * x[1] ** 3 + 3 * f_ddq(x[0]) * x[1] * x[2] + f_dq(x[0]) * x[3]) / jmax)
        if acceleration_limits:
            g_a.append(joint_acc(x))
        if k < K:
            g_dyn.append(X[:, k + 1] - _propagate(x, U[k], h))
            g_tau.append(torque(_propagate(x, U[k], h / 2)))
            if acceleration_limits:
                g_a.append(joint_acc(_propagate(x, U[k], h / 2)))
    g = ca.vertcat(*g_dyn, *g_tau, *g_v, *g_j, *g_a)
    nq = pm.nq
    n_dyn, n_tau, n_v, n_j = 4 * K, nq * (2 * K + 1), nq * (K + 1), nq * (K + 1)
    n_a = nq * (2 * K + 1) if acceleration_limits else 0
    lbg = np.concatenate([np.zeros(n_dyn), -np.ones(n_tau + n_v + n_j + n_a)])
    ubg = np.concatenate([np.zeros(n_dyn), np.ones(n_tau + n_v + n_j + n_a)])
    x_all = ca.vertcat(T, ca.vec(X), U)
    solver = ca.nlpsol(name, "ipopt", {"x": x_all, "f": T, "g": g},
                       {**IPOPT_OPTIONS, "ipopt.tol": 1e-7, "ipopt.max_iter": 2000})
    # bounds
    lbX = np.full((4, K + 1), -np.inf)
    ubX = np.full((4, K + 1), np.inf)
    lbX[0, :], ubX[0, :] = 0.0, 1.0
    lbX[1, :] = 0.0
    lbX[:, 0] = ubX[:, 0] = [0.0, 0.0, 0.0, 0.0]
    lbX[:, -1] = ubX[:, -1] = [1.0, 0.0, 0.0, 0.0]
    lbx = np.concatenate([[1e-3], lbX.ravel(order="F"), np.full(K, -np.inf)])
    ubx = np.concatenate([[1e3], ubX.ravel(order="F"), np.full(K, np.inf)])
    # initial guess: the non-smooth optimum stretched by 20 %, states sampled on the node grid
    T0 = 1.2 * warm.duration_s
    tg = np.linspace(0.0, warm.duration_s, K + 1)
    tk = warm.grid_times()
    s0 = np.interp(tg, tk, warm.s)
    sd0 = np.interp(tg, tk, warm.sdot) / 1.2
    sdd0 = np.gradient(sd0, T0 / K)
    sddd0 = np.gradient(sdd0, T0 / K)
    X0 = np.stack([s0, sd0, sdd0, sddd0])
    X0[:, 0], X0[:, -1] = [0, 0, 0, 0], [1, 0, 0, 0]
    U0 = np.diff(sddd0) / (T0 / K)
    sol = solver(x0=np.concatenate([[T0], X0.ravel(order="F"), U0]), lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    stats = check_solver(solver, f"{name} (smooth CP, K={K})")
    xs = np.asarray(sol["x"]).ravel()
    Tn = float(xs[0])
    Xn = xs[1:1 + 4 * (K + 1)].reshape(K + 1, 4)
    Un = xs[1 + 4 * (K + 1):]
    return SmoothCPResult(name, Tn, np.linspace(0.0, Tn, K + 1), Xn, Un, jmax, time.perf_counter() - t0,
                          info={"iterations": int(stats["iter_count"]), "n_intervals": K,
                                "solver_status": stats["return_status"], "acceleration_limits": acceleration_limits,
                                "jerk_rise_time_s": jerk_rise_time_s})
