"""Optimal periodic excitation (paper ``004_abbe750b8bbcc3aa.txt`` §4.2, after Swevers et al. [14]).

Each joint follows a rest-to-rest finite Fourier series (:mod:`pipeline.identification.fourier`,
§4.2.1).

The coefficients minimise the condition number of the base regressor stacked over ``N`` samples
of one period, ``W = [Y_b(q(t_k), v(t_k), a(t_k))]_k`` (``cond(W)^2 = lambda_max / lambda_min`` of
``G = W^T W``), or, as an option, ``-log det G`` (D-optimality). IPOPT (through CasADi) solves

    min_x  f(x) = log lambda_max(G) - log lambda_min(G)        (= 2 log cond W)
    s.t.   q, v, a within the limits at every sample             (simple bounds, see below)
           |tau_nominal(q, v, a)| <= margin x tau_max            (symbolic RNEA, exact Jacobian)
           z_tcp(q) >= floor + clearance                        (symbolic FK)
           capsule pair distances >= clearance, capsule end points above the floor
           |p_dot_tcp| <= v_max, |p_ddot_tcp| <= a_max  (optional; :mod:`.tcp_motion`)
           rest-to-rest equalities.

The NLP is lifted: the sample states ``S = [q; v; a]_k`` are variables tied to the coefficients by
linear equalities, so every nonlinear constraint touches one sample (block-sparse Jacobian from
the per-sample CasADi function mapped with ``.map(N)``, compiled with its Jacobian by gcc when the
starts pay for the build) and the kinematic limits are bounds. The capsule distance is Ericson's
segment-segment distance written with ``if_else`` clamps (the symbolic twin of
``RobotModel.capsule_clearances``). The NLP works inside the checked limits
(factor 0.98, +5 mm clearance); the result is re-checked on a fine grid (``check_trajectory``:
limits, nominal torques, all capsules) and, if IPOPT stopped on a slightly infeasible iterate,
its oscillation is shrunk until the check passes; a start that still fails is rejected.

``log cond`` is not differentiable where the extreme eigenvalues cross, which makes IPOPT's line
search erratic; by default (``softness`` w > 0) IPOPT minimises the smooth surrogate
``w log sum_i exp(log lambda_i / w) + w log sum_i exp(-log lambda_i / w)`` (soft max minus soft
min of ``log lambda``), which bounds ``2 log cond`` from above by at most ``2 w log n_b``; the
starts, the selection of the best start and every reported figure use the exact condition number.

``f`` and its exact gradient are computed in a CasADi ``Callback``: the regressor and its
vector-Jacobian product come from the symbolic regressor mapped over the samples (``.map(N)``),
and ``d lambda = u^T dG u`` for a simple eigenvalue (so the gradient is exact wherever the extreme
eigenvalues are simple; IPOPT uses a limited-memory Hessian). Several random feasible starts are
solved and the best feasible optimum is kept. The baseline is the median condition number of random
feasible Fourier trajectories with the same harmonics and limits.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from pipeline.core.blas import single_thread_blas
from pipeline.core.compiled_on_demand import compiled_with_jacobian
from pipeline.core.forks import fork_map
from pipeline.core.interrupts import raise_if_interrupted
from pipeline.core.progress import Progress
from pipeline.core.solver_status import is_success
from pipeline.identification.excitation_criterion import (
    CriterionCallback,
    ExcitationCriterion,
    condition_number,
    regressor_casadi,
)
from pipeline.identification.fourier import (
    NLP_EXTRA_CLEARANCE_M,
    NLP_LIMIT_FACTOR,
    ExcitationLimits,
    FeasibilityReport,
    FourierTrajectory,
    check_trajectory,
    fourier_basis,
    random_feasible_trajectories,
    rest_constraint_matrix,
)
from pipeline.identification.regressor import BaseParameters, RegressorModel
from pipeline.identification.tcp_motion import tcp_motion_sx
from pipeline.robot.collision_sx import capsule_clearance_function
from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot

#: cache folder of the compiled per-sample constraints (:mod:`pipeline.core.codegen`)
CONSTRAINTS_CACHE = "excitation"


@dataclass
class ExcitationResult:
    """The optimised trajectory and the evidence around it."""

    trajectory: FourierTrajectory
    cond_optimized: float
    cond_random: list[float]
    cond_starts: list[float]
    cond_history: list[list[float]]  # per start: cond at every IPOPT iteration
    start_results: list[dict]
    feasibility: FeasibilityReport
    criterion: str
    n_samples: int
    details: dict = field(default_factory=dict)
    #: "optimised" (an IPOPT optimum that beats every random start) or "best random"
    source: str = "optimised"
    fallback_reason: str = ""

    @property
    def cond_random_median(self) -> float:
        return float(np.median(self.cond_random))


def sample_constraint_function(robot: RobotModel, sym: SymbolicRobot, limits: ExcitationLimits) -> ca.Function:
    """Per-sample nonlinear constraints ``h([q; v; a])``: torque / limit (nominal model), TCP
    height, capsule self clearances, capsule floor clearances and, when ``limits`` bound them,
    ``|p_dot|^2 / v_max^2`` and ``|p_ddot|^2 / a_max^2`` of the TCP (SX, expanded)."""
    nq = robot.nq
    s = ca.SX.sym("s", 3 * nq)
    q, v, a = s[:nq], s[nq : 2 * nq], s[2 * nq :]
    tau = sym.rnea(q, v, a, ca.DM(sym.nominal_dynamic_parameters()))
    pos, _ = sym.fk(robot.frame_tcp)(q, ca.DM(sym.nominal_kinematic_parameters()))
    pair, floor = capsule_clearance_function(robot, sym)(q)
    h = ca.vertcat(tau / ca.DM(limits.effort_Nm), pos[2], pair, floor)
    if limits.bounds_tcp:
        speed2, acc2 = tcp_motion_sx(robot, sym, q, v, a)
        h = ca.vertcat(h, speed2 / limits.tcp_speed_m_s**2, acc2 / limits.tcp_acceleration_m_s2**2)
    return ca.Function("sample_constraints", [s], [h]).expand()


def _build_nlp(
    robot: RobotModel,
    sym: SymbolicRobot,
    crit: ExcitationCriterion,
    limits: ExcitationLimits,
    harmonics: int,
    max_iter: int,
    objective_change_tol: float = 1e-2,
    n_starts: int = 1,
) -> tuple[Any, dict, CriterionCallback]:
    """Lifted NLP: variables ``z = [c (nq (2L+1)); S (3 nq x N)]`` with ``S = B(c)`` as linear
    equalities, so every nonlinear constraint touches one sample (block-sparse Jacobian) and the
    position/velocity/acceleration limits are simple bounds on ``S``. The per-sample constraints
    and their Jacobian are compiled when the ``n_starts`` solves are expected to pay for the build
    (:func:`~pipeline.core.compiled_on_demand.compiled_with_jacobian`: same numbers)."""
    nq, n = robot.nq, crit.n
    nc = nq * (2 * harmonics + 1)
    c = ca.MX.sym("c", nc)
    S = ca.MX.sym("S", 3 * nq, n)
    X = ca.reshape(c, 2 * harmonics + 1, nq).T  # (nq, 2L+1), row-major layout of c
    S_of_c = ca.vertcat(
        ca.mtimes(X, ca.DM(crit.bq.T)), ca.mtimes(X, ca.DM(crit.bv.T)), ca.mtimes(X, ca.DM(crit.ba.T))
    )
    rest = ca.mtimes(X, ca.DM(rest_constraint_matrix(harmonics).T))
    per_sample = compiled_with_jacobian(sample_constraint_function(robot, sym, limits),
                                        n * (max_iter + 1) * n_starts, subdir=CONSTRAINTS_CACHE)
    h = per_sample.map(n)(S)
    n_h = h.shape[0]
    n_tau = nq
    n_pair = len(robot.self_collision_pairs)
    n_tcp = 2 if limits.bounds_tcp else 0
    h_lo = np.concatenate([
        -np.ones(n_tau),
        [robot.spec.collision.floor_z_m + limits.floor_clearance_m],
        np.broadcast_to(np.asarray(limits.self_clearance_m, float), (n_pair,)),
        np.full(n_h - n_tau - 1 - n_pair - n_tcp, limits.floor_clearance_m),
        np.full(n_tcp, -np.inf),
    ])
    h_hi = np.concatenate([np.ones(n_tau), np.full(n_h - n_tau - n_tcp, np.inf), np.ones(n_tcp)])
    g = ca.vertcat(ca.vec(rest), ca.vec(S - S_of_c), ca.vec(h))
    lbg = np.concatenate([np.zeros(2 * nq + 3 * nq * n), np.tile(h_lo, n)])
    ubg = np.concatenate([np.zeros(2 * nq + 3 * nq * n), np.tile(h_hi, n)])
    s_lo = np.concatenate([limits.lower_rad, -limits.velocity_rad_s, -limits.acceleration_rad_s2])
    s_hi = np.concatenate([limits.upper_rad, limits.velocity_rad_s, limits.acceleration_rad_s2])
    lbx = np.concatenate([np.full(nc, -np.inf), np.tile(s_lo, n)])
    ubx = np.concatenate([np.full(nc, np.inf), np.tile(s_hi, n)])
    obj = CriterionCallback("excitation_objective", crit)
    z = ca.vertcat(c, ca.vec(S))
    solver = ca.nlpsol(
        "excitation",
        "ipopt",
        {"x": z, "f": obj(S), "g": g},
        {
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.sb": "yes",
            "ipopt.max_iter": max_iter,
            "ipopt.hessian_approximation": "limited-memory",
            "ipopt.tol": 1e-6,
            # the (soft) log cond is not smooth enough for a small dual infeasibility with a
            # limited-memory Hessian: "acceptable" = feasible to 1e-6 and the objective changing
            # by less than objective_change_tol (relative) over 5 iterations
            "ipopt.acceptable_tol": 1e6,
            "ipopt.acceptable_constr_viol_tol": 1e-2,
            "ipopt.acceptable_obj_change_tol": objective_change_tol,
            "ipopt.acceptable_iter": 5,
        },
    )
    bounds = {"lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
    return solver, bounds, obj


def shrink_to_feasible(
    robot: RobotModel, traj: FourierTrajectory, limits: ExcitationLimits, n_check: int
) -> tuple[FourierTrajectory, FeasibilityReport]:
    """Scale the oscillation about the mean (keeps rest-to-rest) until the fine-grid check
    passes: IPOPT may stop at its iteration limit on a slightly infeasible iterate, and the NLP
    grid does not see what happens between its samples."""
    report = check_trajectory(robot, traj, limits, n_check)
    scale = 1.0
    for _ in range(25):
        if report.feasible:
            break
        scale *= 0.97
        coef = traj.coefficients.copy()
        coef[:, 1:] *= scale
        mid = 0.5 * (limits.lower_rad + limits.upper_rad)
        coef[:, 0] = mid + scale * (traj.coefficients[:, 0] - mid)
        trial = FourierTrajectory(coef, traj.base_frequency_hz)
        report = check_trajectory(robot, trial, limits, n_check)
        if report.feasible:
            return trial, report
    return traj, report


@dataclass
class _StartOutcome:
    """One excitation start: condition numbers before/after, the criterion's score, the feasible
    trajectory, IPOPT's status, iterations and objective history, and the criterion's evaluations."""

    cond_start: float
    cond_end: float
    score: float
    trajectory: FourierTrajectory
    feasibility: FeasibilityReport
    status: str
    iterations: int
    objective_history: list[float]
    criterion_evaluations: int


def optimize_excitation(robot: RobotModel, sym: SymbolicRobot, reg: RegressorModel, base: BaseParameters,
                        limits: ExcitationLimits, rng: np.random.Generator,
                        **options: Any) -> ExcitationResult:  # Any: the options of _optimize_excitation_impl
    """Random-start IPOPT optimisation of the excitation (see the module docstring) with one BLAS
    thread; ``options`` are those of :func:`_optimize_excitation_impl`."""
    with single_thread_blas():
        return _optimize_excitation_impl(robot, sym, reg, base, limits, rng, **options)


def _optimize_excitation_impl(
    robot: RobotModel,
    sym: SymbolicRobot,
    reg: RegressorModel,
    base: BaseParameters,
    limits: ExcitationLimits,
    rng: np.random.Generator,
    harmonics: int = 5,
    base_frequency_hz: float = 0.1,
    n_samples: int = 100,
    n_starts: int = 4,
    n_random: int = 20,
    max_iter: int = 150,
    criterion: str = "cond",
    n_check: int = 400,
    progress: Progress | None = None,
    softness: float = 0.0,
    objective_change_tol: float = 1e-2,
) -> ExcitationResult:
    """Random-start IPOPT optimisation of the excitation (see the module docstring).

    ``n_random`` random feasible trajectories give the baseline median; the ``n_starts`` best of
    them (by the criterion) are the starts of the NLP.
    """
    nq = robot.nq
    L = harmonics
    t = np.arange(n_samples) / (n_samples * base_frequency_hz)
    basis = fourier_basis(t, base_frequency_hz, L)
    y_base = regressor_casadi(sym, reg, base)
    crit = ExcitationCriterion(y_base, basis, nq, criterion, softness)

    randoms = random_feasible_trajectories(
        robot, limits, L, base_frequency_hz, max(n_random, n_starts), rng, n_check=n_check // 2
    )
    # the baseline is scored on the same sample grid as the optimum
    cond_random = [condition_number(crit.matrix(tr.coefficients.ravel())) for tr in randoms]
    score_random = (np.log(cond_random) if criterion == "cond" else
                    [crit.value_and_gradient(tr.coefficients.ravel(), gradient=False)[0] for tr in randoms])
    order = np.argsort(score_random)
    starts = [randoms[i] for i in order[:n_starts]]

    inner = limits.tightened(NLP_LIMIT_FACTOR, NLP_EXTRA_CLEARANCE_M)
    solver, bounds, _obj = _build_nlp(robot, sym, crit, inner, L, max_iter, objective_change_tol, len(starts))
    nc = nq * (2 * L + 1)

    def solve_start(k: int) -> _StartOutcome:
        """One IPOPT start, made feasible and scored (runs in a forked child: pure in ``k``)."""
        evals0 = crit.n_evals
        c0 = starts[k].coefficients.copy()
        c0[:, 1:] *= NLP_LIMIT_FACTOR - 0.01  # start inside the NLP's tighter limits
        x0 = c0.ravel()
        z0 = np.concatenate([x0, crit.states(x0).ravel(order="F")])
        cond0 = condition_number(crit.matrix(x0))
        sol = solver(x0=z0, **bounds)
        st = solver.stats()
        xk = np.asarray(sol["x"]).ravel()[:nc]
        traj = FourierTrajectory(xk.reshape(nq, 2 * L + 1), base_frequency_hz)
        traj, feas = shrink_to_feasible(robot, traj, limits, n_check)
        condk = condition_number(crit.matrix(traj.coefficients.ravel()))
        score = (np.log(condk) if criterion == "cond"
                 else crit.value_and_gradient(traj.coefficients.ravel(), gradient=False)[0])
        objs = list(st.get("iterations", {}).get("obj", []))
        return _StartOutcome(cond0, condk, float(score), traj, feas, str(st["return_status"]), int(st["iter_count"]),
                             [float(o) for o in objs], crit.n_evals - evals0)

    best: tuple[float, FourierTrajectory, FeasibilityReport, float] | None = None
    histories, start_results, cond_starts = [], [], []
    indices = range(len(starts))
    iterable = indices if progress is None else progress.track(indices, "excitation starts")
    n_evals = crit.n_evals
    # the starts are independent: side by side on the available cores (pipeline.core.forks)
    for _, out in zip(iterable, fork_map(solve_start, len(starts)), strict=True):
        raise_if_interrupted(out.status, "excitation IPOPT")
        n_evals += out.criterion_evaluations
        cond_starts.append(out.cond_start)
        histories.append([float(np.exp(0.5 * o)) for o in out.objective_history] if criterion == "cond" else [])
        start_results.append(
            {
                "cond_start": out.cond_start,
                "cond_end": out.cond_end,
                "status": out.status,
                "iterations": out.iterations,
                "feasible": out.feasibility.feasible,
                "feasibility": out.feasibility.to_dict(),
            }
        )
        ok = out.feasibility.feasible and is_success(out.status)
        if ok and (best is None or out.score < best[3]):
            best = (out.cond_end, out.trajectory, out.feasibility, out.score)
    # never worse than the best random feasible trajectory (quality gate)
    i0 = int(order[0])
    score0 = float(score_random[i0])
    source, reason = "optimised", ""
    if best is None:
        reason = ("no IPOPT start ended with Solve_Succeeded/Solved_To_Acceptable_Level on a feasible "
                  f"trajectory (statuses: {', '.join(r['status'] for r in start_results) or 'none'})")
    elif best[3] >= score0:
        reason = (f"the optimised trajectory ({criterion} criterion {best[3]:.4g}, cond {best[0]:.4g}) is not better "
                  f"than the best random feasible one ({score0:.4g}, cond {cond_random[i0]:.4g})")
    if reason:
        # the randoms passed a grid of n_check // 2 samples: on the fine grid a peak between those
        # samples may cross a limit, so the fallback is scaled into it as every optimised start is
        source = "best random"
        fallback, feasibility = shrink_to_feasible(robot, randoms[i0], limits, n_check)
        cond_fallback = (cond_random[i0] if fallback is randoms[i0]
                         else condition_number(crit.matrix(fallback.coefficients.ravel())))
        best = (cond_fallback, fallback, feasibility, score0)
    return ExcitationResult(
        trajectory=best[1],
        cond_optimized=float(best[0]),
        cond_random=[float(c) for c in cond_random],
        cond_starts=cond_starts,
        cond_history=histories,
        start_results=start_results,
        feasibility=best[2],
        criterion=criterion,
        n_samples=n_samples,
        details={"criterion_evaluations": n_evals},
        source=source,
        fallback_reason=reason,
    )
