"""Time/energy-optimal point-to-point (PtP) motion (paper 004 section 5.4, eq. 40).

    min  k1 T + k2 int_0^T tau^T W tau dt
    s.t. tau = RNEA(q, v, a; p_dyn) (rigid body + rotor + viscous + smooth Coulomb),
         |tau_i| <= tau_max_i,  |v_i| <= v_max_i,  q_min <= q <= q_max,
         q(0) = q0, q(T) = q1, v(0) = v(T) = 0   (rest to rest)

Inverse-dynamics transcription (DESIGN.md "Measured facts"): N intervals of length h = T/N,
states q, v and accelerations a at the nodes, acceleration linear within an interval (so
velocity and acceleration are continuous, jerk piecewise constant; paper 004 section 5 asks for
continuous motion), exact integration
``q_{k+1} = q_k + h v_k + h^2 (a_k/3 + a_{k+1}/6)``, ``v_{k+1} = v_k + h (a_k + a_{k+1})/2``;
torques from the symbolic RNEA (one CasADi function applied with ``.map(2N+1)``) at the nodes
and interval midpoints, as path constraints scaled by their limits; energy by Simpson's rule.
Rest to rest: v = 0 and (optionally) a = 0 at both ends. Coulomb friction is added outside the
RNEA as ``F_c tanh(v / w)`` with ``F_c`` and ``w`` NLP parameters (same model as the symbolic
bridge, but the smoothing width can be continued from wide to the model's value).

``W`` selects the energy measure: ``"torque"`` (W = I, the paper's tau^T tau), ``"normalised"``
(W = diag(1 / tau_max^2)), ``"electrical"`` (copper losses, W = diag(R_i / (k_t,i G_i)^2) with
motor resistance R, torque constant k_t and gear ratio G).

The NLP is built once per robot structure with start, goal, limits, weights, k1, k2, the dynamic
parameters and the joint placements (:func:`arm_parameters`) as NLP parameters/bounds; with
``jit=True`` its C code (all derivative functions, size independent of N thanks to ``map``) is
compiled once by gcc and cached on disk keyed by the SHA-256 of what the code is generated from
(:func:`nlp_library_key`), which holds no parameter of the arm: every calibration and identification
of the arm reuses one library.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import numpy.typing as npt

from pipeline.core import codegen
from pipeline.core.errors import InfeasibleError, PipelineError, SolverError
from pipeline.core.identifiers import casadi_identifier
from pipeline.core.interrupts import raise_if_interrupted
from pipeline.robot.symbolic import SymbolicRobot
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.trajectories import JointTrajectory

JIT_FLAGS = ("-O1",)
#: directional derivatives CasADi propagates per call of a derivative function of the RNEA (its option
#: ``max_num_dir``, default 64): the constraint Jacobian and the Lagrangian Hessian of the NLP ask for
#: 25-31 directions (graph colouring), and one function for all of them is most of the generated C.
#: In batches of 6 the values are the same bit for bit (every direction is its own chain of operations),
#: gcc -O1 needs about half the CPU (84 -> 45 s for the RX130L, -O0: 23 -> 10 s) and the compiled
#: Hessian evaluates as fast (``benchmarks/bench_ptp_code.py``)
DERIVATIVE_DIRECTIONS = 6
FORMULATION_VERSION = "ptp-v1"


def energy_weights(pm: PlanningModel, kind: str, motor_resistance_ohm: npt.ArrayLike | None = None,
                   torque_constant_Nm_A: npt.ArrayLike | None = None,
                   gear_ratio: npt.ArrayLike | None = None) -> np.ndarray:
    """Weights W of ``int tau^T W tau dt`` for the energy measures described in the module doc."""
    if kind == "torque":
        return np.ones(pm.nq)
    if kind == "normalised":
        return 1.0 / pm.effort_Nm**2
    if kind == "electrical":
        if motor_resistance_ohm is None or torque_constant_Nm_A is None:
            raise PipelineError(None, "trajectory.energy", "electrical needs motor_resistance_ohm and "
                                "torque_constant_Nm_A")
        g = np.ones(pm.nq) if gear_ratio is None else np.asarray(gear_ratio, float)
        return np.asarray(motor_resistance_ohm, float) / (np.asarray(torque_constant_Nm_A, float) * g) ** 2
    raise PipelineError(None, "trajectory.energy", f"unknown energy measure {kind!r} "
                        "(torque, normalised, electrical)")


@dataclass
class PtpResult:
    """Optimal PtP motion on the transcription grid plus solver facts."""

    t_nodes_s: np.ndarray
    q_nodes: np.ndarray
    v_nodes: np.ndarray
    a_nodes: np.ndarray
    duration_s: float
    energy: float
    objective: float
    solve_time_s: float
    iterations: int
    k1: float
    k2: float
    info: dict = field(default_factory=dict)

    def sample(self, dt_s: float, name: str = "ptp") -> JointTrajectory:
        """Exact samples (acceleration linear within each interval) every ``dt_s``."""
        T = self.duration_s
        N = len(self.t_nodes_s) - 1
        h = T / N
        t = np.append(np.arange(0.0, T, dt_s), T)
        k = np.clip((t / h).astype(int), 0, N - 1)
        tau = (t - k * h)[:, None]
        a0, a1 = self.a_nodes[k], self.a_nodes[k + 1]
        jerk = (a1 - a0) / h
        a = a0 + jerk * tau
        v = self.v_nodes[k] + a0 * tau + 0.5 * jerk * tau**2
        q = self.q_nodes[k] + self.v_nodes[k] * tau + 0.5 * a0 * tau**2 + jerk * tau**3 / 6.0
        return JointTrajectory(name, t, q, v, a, info={"k1": self.k1, "k2": self.k2})


def _check_duration_attainable(dq_rad: np.ndarray, duration_s: float, velocity_rad_s: np.ndarray,
                               acceleration_rad_s2: npt.ArrayLike | None) -> None:
    """Refuse a fixed duration below a bound no rest-to-rest move can beat, before IPOPT spends its
    iterations proving it: the mean speed ``|dq| / T`` cannot exceed the velocity limit, and under an
    acceleration limit ``a`` the bang-bang move takes ``2 sqrt(|dq| / a)``."""
    distance = np.abs(np.asarray(dq_rad, float))
    bound_s = distance / np.asarray(velocity_rad_s, float)
    if acceleration_rad_s2 is not None:
        bound_s = np.maximum(bound_s, 2.0 * np.sqrt(distance / np.asarray(acceleration_rad_s2, float)))
    j = int(np.argmax(bound_s))
    if duration_s < bound_s[j] * (1.0 - 1e-9):
        raise InfeasibleError(None, f"ptp duration joint {j + 1}",
                              f"{duration_s:.4g} s is below the {bound_s[j]:.4g} s that its "
                              f"{np.degrees(distance[j]):.1f} deg need at the velocity/acceleration limits")


def nlp_functions(solver: ca.Function) -> list[ca.Function]:
    """What ``nlpsol(name, "ipopt", library)`` loads: the oracle, then nlp_f, nlp_g, nlp_grad_f, ..."""
    return [solver.oracle(), *(solver.get_function(fn) for fn in solver.get_function())]


def nlp_library_key(solver: ca.Function, options: dict, flags: tuple[str, ...]) -> str:
    """What names the compiled library of an NLP: the SHA-256 of everything its C code is generated
    from, namely the NLP itself (its expression graph, serialised by CasADi), CasADi's own options (not
    IPOPT's ``ipopt.*``, which the code never sees), the names of the generated functions, the gcc flags
    and the CasADi version. The derivative functions (gradient, constraint Jacobian, Lagrangian Hessian)
    are a deterministic function of these, so one key is one code; serialising the NLP takes
    milliseconds where generating the code to hash it takes a second (the Hessian of a 6-axis arm's
    RNEA is megabytes of C)."""
    casadi_options = sorted((k, v) for k, v in options.items() if not k.startswith("ipopt."))
    text = "\n".join([FORMULATION_VERSION, solver.oracle().serialize(), repr(casadi_options),
                      " ".join(solver.get_function()), " ".join(flags), ca.CasadiMeta.version()])
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _compile_nlp(solver_sx: ca.Function, key: str, cache_dir: Path | None, name: str,
                 flags: tuple[str, ...] = JIT_FLAGS) -> Path:
    """C code of the NLP's functions (objective, constraints and their derivatives) -> .so.

    Named by ``key`` (:func:`nlp_library_key`, :func:`pipeline.core.codegen.build_library`; the code itself is
    generated only when the library is missing): the arm's parameters are inputs of the code, so one
    library serves every calibration and identification of an arm (its structure, grid size and
    velocity/acceleration scales name it), and is never compiled twice."""
    return codegen.build_library(name, lambda: nlp_functions(solver_sx), subdir="trajectory", flags=flags,
                                 cache_dir=cache_dir, key=key)


def arm_parameters(sym: SymbolicRobot, p_dyn: np.ndarray) -> np.ndarray:
    """What the PtP NLP's RNEA reads of the arm: ``p_dyn`` with zero Coulomb friction (added outside
    the RNEA), then every joint's placement in its parent, ``vec(R)`` (column-major) and ``p``."""
    pd = np.asarray(p_dyn, float).copy()
    pd[sym.dyn.coulomb] = 0.0
    return np.concatenate([pd, *(np.concatenate([np.ravel(j.rotation, order="F"), np.ravel(j.translation)])
                                 for j in sym.joints)])


def _rnea_function(sym: SymbolicRobot, values: np.ndarray, parametric: bool) -> ca.Function:
    """``rnea_ptp(q, v, a, arm) -> tau``: rigid body + rotor + viscous friction + offset of the arm
    :func:`arm_parameters` describes. Only q, v and a are differentiable: the NLP needs no derivative
    with respect to the arm, and none is generated. ``parametric=False``: ``rnea_ptp(q, v, a)`` with
    the arm's ``values`` as constants of the code."""
    qs, vs, as_ = (ca.SX.sym(nm, sym.nq) for nm in ("q", "v", "a"))
    arm = ca.SX.sym("arm", values.size) if parametric else ca.SX(values)
    n_dyn = sym.n_dyn
    placements = [(ca.reshape(arm[n_dyn + 12 * k:n_dyn + 12 * k + 9], 3, 3),
                   arm[n_dyn + 12 * k + 9:n_dyn + 12 * k + 12]) for k in range(sym.nq)]
    p_dyn = arm[:n_dyn]
    tau = sym.inverse_dynamics_expression(qs, vs, as_, p_dyn, placements=placements, coulomb=False)
    if not parametric:
        return ca.Function("rnea_ptp", [qs, vs, as_], [tau])
    return ca.Function("rnea_ptp", [qs, vs, as_, arm], [tau], {"is_diff_in": [True, True, True, False]})


class PtpProblem:
    """The PtP NLP for one robot structure and grid size, reusable for any move.

    ``problem.solve(q0, q1, k1=1, k2=0.01)`` or with ``duration_s=T`` for a fixed duration
    (then only the energy is minimised). Limits default to the planning model's and may be
    overridden per call; ``p_dyn`` defaults to the symbolic robot's nominal parameters.
    """

    def __init__(self, pm: PlanningModel, sym: SymbolicRobot, n_intervals: int = 50, jit: bool = True,
                 cache_dir: Path | None = None, ipopt_options: dict | None = None,
                 jit_flags: tuple[str, ...] = JIT_FLAGS, p_dyn: np.ndarray | None = None,
                 parametric: bool = True, derivative_directions: int = DERIVATIVE_DIRECTIONS) -> None:
        t0 = time.perf_counter()
        self.pm, self.sym, self.N, self.nq = pm, sym, int(n_intervals), pm.nq
        self.p_dyn_nominal = np.asarray(sym.nominal_dynamic_parameters() if p_dyn is None else p_dyn, float)
        self.coulomb_slice = sym.dyn.coulomb
        nq, N = self.nq, self.N
        self.v_scale = pm.velocity_rad_s.copy()
        # scales of the decision variables (constants in the generated code: independent of the
        # torque reserve so that one compiled library serves every torque limit)
        self.a_scale = np.asarray(pm.acceleration_rad_s2, float).copy()
        # decision variables (scaled): T, Q (nq x N+1), Vn = V / v_scale, An = A / a_scale (nodes)
        T = ca.MX.sym("T")
        Q = ca.MX.sym("Q", nq, N + 1)
        Vn = ca.MX.sym("V", nq, N + 1)
        An = ca.MX.sym("A", nq, N + 1)
        coulomb = ca.MX.sym("coulomb", nq)
        inv_width = ca.MX.sym("inv_width", nq)
        inv_tau_max = ca.MX.sym("inv_tau_max", nq)
        inv_v_max = ca.MX.sym("inv_v_max", nq)
        w = ca.MX.sym("w", nq)
        k1 = ca.MX.sym("k1")
        k2 = ca.MX.sym("k2")
        V = Vn * ca.repmat(ca.DM(self.v_scale), 1, N + 1)
        A = An * ca.repmat(ca.DM(self.a_scale), 1, N + 1)
        h = T / N
        q0, v0, a0, a1 = Q[:, :-1], V[:, :-1], A[:, :-1], A[:, 1:]
        q_mid = q0 + 0.5 * h * v0 + h**2 * (5 * a0 + a1) / 48.0
        v_mid = v0 + h * (3 * a0 + a1) / 8.0
        a_mid = 0.5 * (a0 + a1)
        g_q = Q[:, 1:] - q0 - h * v0 - h**2 * (a0 / 3.0 + a1 / 6.0)
        g_v = (V[:, 1:] - v0 - 0.5 * h * (a0 + a1)) / ca.repmat(ca.DM(self.v_scale), 1, N)
        M = 2 * N + 1
        # the arm's parameters (dynamic parameters, joint placements) are NLP parameters: one
        # compiled library serves every identification and calibration of the arm (or, with
        # parametric=False, constants of the code); Coulomb friction is added outside the RNEA
        self.parametric = bool(parametric)
        self.model_parameters = arm_parameters(sym, self.p_dyn_nominal)
        arm = ca.MX.sym("arm", self.model_parameters.size if self.parametric else 0)
        rnea = _rnea_function(sym, self.model_parameters, self.parametric).map(M)
        qa, va, aa = ca.horzcat(Q, q_mid), ca.horzcat(V, v_mid), ca.horzcat(A, a_mid)
        tau = (rnea(qa, va, aa, *([arm] if self.parametric else []))
               + ca.repmat(coulomb, 1, M) * ca.tanh(va * ca.repmat(inv_width, 1, M)))
        tau_n = tau * ca.repmat(inv_tau_max, 1, M)
        wt = ca.sum1(tau**2 * ca.repmat(w, 1, M))
        e_n, e_m = wt[:N + 1], wt[N + 1:]
        energy = h / 6.0 * (ca.sum2(e_n[:-1] + e_n[1:]) + 4 * ca.sum2(e_m))
        x = ca.vertcat(T, ca.vec(Q), ca.vec(Vn), ca.vec(An))
        p = ca.vertcat(coulomb, inv_width, inv_tau_max, inv_v_max, w, k1, k2, arm)
        g_vmid = v_mid * ca.repmat(inv_v_max, 1, N)
        g = ca.vertcat(ca.vec(g_q), ca.vec(g_v), ca.vec(tau_n), ca.vec(g_vmid))
        self.n_x, self.n_g, self.n_p = x.numel(), g.numel(), p.numel()
        self._energy_fn = ca.Function("energy", [x, p], [energy, tau])
        nlp = {"x": x, "p": p, "f": k1 * T + k2 * energy, "g": g}
        opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-8,
                "ipopt.acceptable_tol": 1e-5, "ipopt.max_iter": 1000,
                "oracle_options": {"max_num_dir": int(derivative_directions)}}
        opts.update(ipopt_options or {})
        name = casadi_identifier("ptp", pm.model.name or "robot", N)
        self.jit = bool(jit)
        solver = ca.nlpsol(name, "ipopt", nlp, opts)
        self.library_key = nlp_library_key(solver, opts, tuple(jit_flags))   # of the compiled code (jit)
        self.build_time_s = time.perf_counter() - t0
        self.compile_time_s = 0.0
        source: dict[str, ca.SX] | str = nlp
        if self.jit:
            t1 = time.perf_counter()
            lib = _compile_nlp(solver, self.library_key, Path(cache_dir) if cache_dir else None, name,
                               tuple(jit_flags))
            solver = ca.nlpsol(name, "ipopt", str(lib), opts)
            self.library = lib
            source = str(lib)
            self.compile_time_s = time.perf_counter() - t1
        self.solver = solver
        # the same NLP for re-solves near a known solution: IPOPT starts from its multipliers too
        # (a fine-grid tightening re-solve of the RX130L's robot.yaml PtP move: 45 instead of 75 iterations)
        self.solver_warm = ca.nlpsol(name, "ipopt", source, {**opts, "ipopt.warm_start_init_point": "yes"})

    # ----------------------------------------------------------------------------------------
    def _unpack(self, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        nq, N = self.nq, self.N
        T = float(x[0])
        i = 1
        Q = x[i:i + nq * (N + 1)].reshape(N + 1, nq)
        i += nq * (N + 1)
        V = x[i:i + nq * (N + 1)].reshape(N + 1, nq) * self.v_scale
        i += nq * (N + 1)
        A = x[i:i + nq * (N + 1)].reshape(N + 1, nq) * self.a_scale
        return T, Q, V, A

    def pack(self, T: float, Q: np.ndarray, V: np.ndarray, A: np.ndarray) -> np.ndarray:
        """Decision vector (initial guess) of a motion: duration, node positions, velocities, accelerations."""
        return np.concatenate([[T], Q.ravel(), (V / self.v_scale).ravel(), (A / self.a_scale).ravel()])

    def quintic_guess(self, q0: np.ndarray, q1: np.ndarray, duration_s: float | None = None) -> np.ndarray:
        """Rest-to-rest quintic ``q0 + dq (10 u^3 - 15 u^4 + 6 u^5)`` as initial guess."""
        dq = np.abs(q1 - q0)
        if duration_s is None:
            duration_s = 1.2 * max(np.max(1.875 * dq / self.pm.velocity_rad_s),
                                   np.max(np.sqrt(5.774 * dq / self.a_scale)), 0.05)
        T, N = duration_s, self.N
        u = np.linspace(0.0, 1.0, N + 1)[:, None]
        Q = q0 + (q1 - q0) * (10 * u**3 - 15 * u**4 + 6 * u**5)
        V = (q1 - q0) * (30 * u**2 - 60 * u**3 + 30 * u**4) / T
        A = (q1 - q0) * (60 * u - 180 * u**2 + 120 * u**3) / T**2
        return self.pack(T, Q, V, A)

    def feasible_quintic_duration(self, q0: np.ndarray, q1: np.ndarray, p_dyn: np.ndarray,
                                  coulomb: np.ndarray, tmax: np.ndarray, vmax: np.ndarray) -> float:
        """Shortest duration at which the quintic satisfies torque and speed limits (bisection,
        numeric Pinocchio-free evaluation of the same RNEA); a feasible initial guess."""
        u = np.linspace(0.0, 1.0, 2 * self.N + 1)[:, None]
        dq = q1 - q0
        Q = q0 + dq * (10 * u**3 - 15 * u**4 + 6 * u**5)
        V1 = dq * (30 * u**2 - 60 * u**3 + 30 * u**4)
        A1 = dq * (60 * u - 180 * u**2 + 120 * u**3)
        f = self.sym.rnea.map(Q.shape[0])
        width = self.sym.coulomb_smoothing_rad_s

        def ratio(T: float) -> float:
            V, A = V1 / T, A1 / T**2
            tau = np.asarray(f(Q.T, V.T, A.T, p_dyn)).T + coulomb * np.tanh(V / width)
            return max(np.max(np.abs(tau) / tmax), np.max(np.abs(V) / vmax))

        hi = 1.0
        while ratio(hi) > 1.0 and hi < 100.0:
            hi *= 2.0
        lo = hi / 2.0
        while ratio(lo) <= 1.0 and lo > 1e-3:
            lo, hi = lo / 2.0, lo
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if ratio(mid) <= 1.0 else (mid, hi)
        return hi

    def solve(self, q0: np.ndarray, q1: np.ndarray, k1: float = 1.0, k2: float = 0.01,
              weights: np.ndarray | None = None, duration_s: float | None = None,
              lower_rad: np.ndarray | None = None,
              upper_rad: np.ndarray | None = None, velocity_rad_s: np.ndarray | None = None,
              effort_Nm: np.ndarray | None = None, x0: np.ndarray | None = None,
              max_duration_s: float = 60.0, zero_end_acceleration: bool = True,
              coulomb_widths_rad_s: tuple[float, ...] | None = None,
              multipliers: tuple[np.ndarray, np.ndarray] | None = None,
              acceleration_rad_s2: np.ndarray | None = None) -> PtpResult:
        """Solve one move; raises InfeasibleError / SolverError instead of returning a failure.

        ``coulomb_widths_rad_s``: continuation of the tanh smoothing width (wide first, each solve
        warm-starting the next); the model's width is always solved last. ``multipliers``
        ``(lam_x, lam_g)`` of a nearby solution (``info["multipliers"]``, with its ``x0``) warm-start
        the dual variables as well. ``acceleration_rad_s2`` bounds the joint accelerations (exact:
        they are linear within an interval).
        """
        pm, nq, N = self.pm, self.nq, self.N
        q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
        lo = pm.lower_rad if lower_rad is None else np.asarray(lower_rad, float)
        hi = pm.upper_rad if upper_rad is None else np.asarray(upper_rad, float)
        vmax = pm.velocity_rad_s if velocity_rad_s is None else np.asarray(velocity_rad_s, float)
        tmax = pm.effort_Nm if effort_Nm is None else np.asarray(effort_Nm, float)
        for nm, qq in (("start", q0), ("goal", q1)):
            bad = np.flatnonzero((qq < lo) | (qq > hi))
            if bad.size:
                j = int(bad[0])
                raise InfeasibleError(None, f"ptp {nm} joint {j + 1}",
                                      f"{np.degrees(qq[j]):.2f} deg outside the limits "
                                      f"[{np.degrees(lo[j]):.1f}, {np.degrees(hi[j]):.1f}] deg")
        if duration_s is not None:
            _check_duration_attainable(q1 - q0, float(duration_s), vmax, acceleration_rad_s2)
        pd = self.p_dyn_nominal.copy()
        # static feasibility: holding torque at start and goal
        for nm, qq in (("start", q0), ("goal", q1)):
            tau_s = np.asarray(self.sym.rnea(qq, np.zeros(nq), np.zeros(nq), pd)).ravel()
            bad = np.flatnonzero(np.abs(tau_s) > tmax)
            if bad.size:
                j = int(bad[0])
                raise InfeasibleError(None, f"ptp {nm} joint {j + 1} torque limit",
                                      f"holding torque {tau_s[j]:.1f} N·m exceeds {tmax[j]:.1f} N·m")
        coulomb = pd[self.coulomb_slice].copy()
        pd[self.coulomb_slice] = 0.0
        w = np.ones(nq) if weights is None else np.asarray(weights, float)
        w_model = np.asarray(self.sym.coulomb_smoothing_rad_s, float)
        # each continuation width on every joint the model smooths less, then the model's widths
        widths = [np.maximum(w_model, float(x)) for x in (coulomb_widths_rad_s or ()) if x > w_model.min()] + [w_model]
        # bounds
        lbT, ubT = (duration_s, duration_s) if duration_s is not None else (1e-3, max_duration_s)
        lbQ = np.tile(lo, (N + 1, 1))
        ubQ = np.tile(hi, (N + 1, 1))
        lbQ[0] = ubQ[0] = q0
        lbQ[-1] = ubQ[-1] = q1
        vb = vmax / self.v_scale
        lbV = np.tile(-vb, (N + 1, 1))
        ubV = np.tile(vb, (N + 1, 1))
        lbV[0] = ubV[0] = lbV[-1] = ubV[-1] = 0.0
        # joint accelerations are linear within an interval: bounds at the nodes hold everywhere
        ab = np.inf if acceleration_rad_s2 is None else np.asarray(acceleration_rad_s2, float) / self.a_scale
        lbA = np.tile(-ab * np.ones(nq), (N + 1, 1))
        ubA = np.tile(ab * np.ones(nq), (N + 1, 1))
        if zero_end_acceleration:
            lbA[0] = ubA[0] = lbA[-1] = ubA[-1] = 0.0
        lbx = np.concatenate([[lbT], lbQ.ravel(), lbV.ravel(), lbA.ravel()])
        ubx = np.concatenate([[ubT], ubQ.ravel(), ubV.ravel(), ubA.ravel()])
        n_dyn_eq = 2 * nq * N
        lbg = np.concatenate([np.zeros(n_dyn_eq), -np.ones((3 * N + 1) * nq)])
        ubg = np.concatenate([np.zeros(n_dyn_eq), np.ones((3 * N + 1) * nq)])
        if x0 is None:
            if duration_s is None:
                x0 = self.quintic_guess(q0, q1, self.feasible_quintic_duration(q0, q1, pd, coulomb, tmax, vmax))
            else:
                x0 = self.quintic_guess(q0, q1, duration_s)
        what = f"ptp move {np.round(np.degrees(q0), 1).tolist()} -> {np.round(np.degrees(q1), 1).tolist()} deg"
        solve_time, cpu_time, iters = 0.0, 0.0, 0
        for width in widths:
            p = np.concatenate([coulomb, 1.0 / width, 1.0 / tmax, 1.0 / vmax, w, [k1, k2],
                                self.model_parameters if self.parametric else []])
            solver, duals = self.solver, {}
            if multipliers is not None and len(widths) == 1:
                solver, duals = self.solver_warm, {"lam_x0": multipliers[0], "lam_g0": multipliers[1]}
            t0, c0 = time.perf_counter(), time.process_time()
            sol = solver(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, **duals)
            solve_time += time.perf_counter() - t0
            cpu_time += time.process_time() - c0
            stats = solver.stats()
            iters += int(stats["iter_count"])
            if not stats.get("success", False):
                status = stats.get("return_status", "unknown")
                raise_if_interrupted(status, what)
                if status in ("Infeasible_Problem_Detected", "Local_Infeasibility"):
                    cons = "torque limits" if duration_s is None else f"duration {duration_s:.4f} s with torque limits"
                    raise InfeasibleError(None, what, f"the {cons} cannot be met (IPOPT: {status})")
                raise SolverError(None, what, f"IPOPT failed: {status}")
            x0 = np.asarray(sol["x"]).ravel()
            status = stats.get("return_status", "unknown")
        xs = x0
        T, Q, V, A = self._unpack(xs)
        energy, _ = self._energy_fn(xs, p)
        return PtpResult(np.linspace(0.0, T, N + 1), Q, V, A, T, float(energy), float(sol["f"]),
                         solve_time, iters, k1, k2,
                         info={"x": xs, "multipliers": (np.asarray(sol["lam_x"]).ravel(),
                                                        np.asarray(sol["lam_g"]).ravel()),
                               "jit": self.jit, "fixed_duration": duration_s is not None,
                               "cpu_time_s": cpu_time, "coulomb_widths_rad_s": [x.tolist() for x in widths],
                               "solver_status": status,
                               "acceleration_limits": acceleration_rad_s2 is not None})

    def pareto(self, q0: np.ndarray, q1: np.ndarray, k2_values: list[float], weights: np.ndarray,
               **kw: Any) -> list[PtpResult]:  # Any: the keyword arguments of solve, forwarded
        """Sweep ``k2`` (k1 = 1), each solve warm-started from the previous one."""
        out: list[PtpResult] = []
        x0 = None
        for k2 in k2_values:
            r = self.solve(q0, q1, k1=1.0, k2=float(k2), weights=weights, x0=x0, **kw)
            out.append(r)
            x0 = r.info["x"]
        return out
