"""PtP solves verified on the fine time grid (paper 004 section 5.2), for :func:`pipeline.trajectory.solve.plan_ptp`.

* :func:`solve_ptp_verified`: one NLP solve (:class:`pipeline.trajectory.ptp.PtpProblem`) re-checked with
  the full friction model every ``fine_dt_s``; a joint over its torque or speed limit by more than
  ``violation_tolerance`` between the transcription's check points has its limit tightened by the
  excess and the NLP is solved again, warm-started (primal and dual).
* :func:`best_ptp_candidate`: the shortest plan within the limits among the NLP from its cold start,
  the NLP warm-started from the torque-feasible ruckig profile and that profile itself: a time-optimal
  plan is never slower than a feasible motion.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.errors import InfeasibleError, PipelineError, SolverError
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.ptp import PtpProblem, PtpResult
from pipeline.trajectory.trajectories import (
    FINE_GRID_ROUNDOFF,
    JointTrajectory,
    TorqueCheck,
    check_trajectory,
    slowed_into_limits,
    within_limits,
)


def solve_ptp_verified(pm: PlanningModel, problem: PtpProblem, q0: np.ndarray, q1: np.ndarray,
                       cfg: TrajectoryConfig, k1: float, k2: float, weights: np.ndarray,
                       duration_s: float | None = None, x0: np.ndarray | None = None,
                       torque_scale: np.ndarray | None = None,
                       coulomb_widths_rad_s: tuple[float, ...] | None = None,
                       multipliers: tuple[np.ndarray, np.ndarray] | None = None) -> PtpResult:
    """Solve, re-check torques and speeds on the fine grid, and while a joint exceeds its torque
    or speed limit by more than ``cfg.violation_tolerance`` (between the transcription's check
    points) tighten that joint's limit by the excess and re-solve (warm start from the previous
    solution and its multipliers).
    The returned result records the rounds and total solve time. ``coulomb_widths_rad_s``: the
    Coulomb-width continuation of a cold start (default ``cfg.ptp_coulomb_widths_rad_s``; none
    when warm-started)."""
    if coulomb_widths_rad_s is None:
        coulomb_widths_rad_s = tuple(cfg.ptp_coulomb_widths_rad_s)
    widths = tuple(coulomb_widths_rad_s) if x0 is None else ()
    scale = np.ones(pm.nq) if torque_scale is None else np.asarray(torque_scale, float).copy()
    v_scale = np.ones(pm.nq)
    acc = pm.acceleration_rad_s2 if cfg.acceleration_limits else None
    res = problem.solve(q0, q1, k1, k2, weights=weights, duration_s=duration_s, effort_Nm=pm.effort_Nm * scale,
                        x0=x0, coulomb_widths_rad_s=widths, multipliers=multipliers if x0 is not None else None,
                        acceleration_rad_s2=acc)
    first = total = res.solve_time_s
    cpu = res.info["cpu_time_s"]
    iters, rounds = res.iterations, 0
    for _ in range(cfg.max_tightening_rounds):
        chk = check_trajectory(pm, res.sample(cfg.fine_dt_s))
        ratio = chk.torque_ratio.max(axis=0)
        v_ratio = chk.velocity_ratio.max(axis=0)
        bad = ratio > 1.0 + cfg.violation_tolerance
        bad_v = v_ratio > 1.0 + cfg.violation_tolerance
        if not (bad.any() or bad_v.any()):
            break
        rounds += 1
        scale[bad] = scale[bad] / ratio[bad] * (1.0 - 0.25 * cfg.violation_tolerance)
        v_scale[bad_v] = v_scale[bad_v] / v_ratio[bad_v] * (1.0 - 0.25 * cfg.violation_tolerance)
        res = problem.solve(q0, q1, k1, k2, weights=weights, duration_s=duration_s, effort_Nm=pm.effort_Nm * scale,
                            velocity_rad_s=pm.velocity_rad_s * v_scale, x0=res.info["x"], coulomb_widths_rad_s=(),
                            multipliers=res.info["multipliers"], acceleration_rad_s2=acc)
        total += res.solve_time_s
        cpu += res.info["cpu_time_s"]
        iters += res.iterations
    res.info.update({"tightening_rounds": rounds, "torque_scale": scale.tolist(), "velocity_scale": v_scale.tolist(),
                     "first_solve_time_s": first, "cpu_time_s": cpu})
    res.solve_time_s, res.iterations = total, iters
    return res


def _ruckig_nodes(problem: PtpProblem, ruckig_fine: JointTrajectory) -> np.ndarray:
    """ruckig's profile at the transcription's nodes (interpolated from its fine samples): a warm start."""
    t = np.linspace(0.0, ruckig_fine.duration_s, problem.N + 1)
    q, v, a = (np.column_stack([np.interp(t, ruckig_fine.t_s, x[:, j]) for j in range(problem.nq)])
               for x in (ruckig_fine.q, ruckig_fine.v, ruckig_fine.a))
    v[0] = v[-1] = a[0] = a[-1] = 0.0
    return problem.pack(ruckig_fine.duration_s, q, v, a)


def best_ptp_candidate(pm: PlanningModel, problem: PtpProblem, q0: np.ndarray, q1: np.ndarray,
                       cfg: TrajectoryConfig, weights: np.ndarray, ruckig_fine: JointTrajectory
                       ) -> tuple[PtpResult, JointTrajectory, TorqueCheck]:
    """The shortest plan found that keeps the limits on the fine grid, among: the NLP from its cold
    start, the NLP warm-started from the torque-feasible ruckig profile (solved when the cold start
    is not shorter than ruckig, or fails) and that ruckig profile itself.

    A time-optimal plan of the full dynamics can never be slower than a torque-feasible ruckig
    profile, which is itself a feasible motion; when the NLP ends above it (a poorer local optimum,
    or the transcription's piecewise-linear accelerations cannot follow ruckig's switching times
    between its nodes), the ruckig profile is the plan (``info["source"] = "ruckig"``). Each NLP
    plan is slowed into its limits (:func:`slowed_into_limits`, ``FINE_GRID_ROUNDOFF``) before the
    comparison, so the durations compared are those handed on."""
    acc = bool(cfg.acceleration_limits)
    plans: list[tuple[float, str, PtpResult, JointTrajectory, TorqueCheck]] = []
    failure: PipelineError | None = None

    def attempt(start: str, x0: np.ndarray | None) -> None:
        nonlocal failure
        try:
            r = solve_ptp_verified(pm, problem, q0, q1, cfg, cfg.ptp_k1, cfg.ptp_k2, weights, x0=x0)
        except (InfeasibleError, SolverError) as exc:
            failure = failure or exc
            return
        r.info["warm_start"] = start
        tr, chk = slowed_into_limits(pm, r.sample(cfg.fine_dt_s, "ptp"), FINE_GRID_ROUNDOFF, acc, weights)
        plans.append((tr.duration_s, start, r, tr, chk))

    attempt("quintic", None)
    if not plans or plans[0][0] >= ruckig_fine.duration_s:
        attempt("ruckig", _ruckig_nodes(problem, ruckig_fine))
    if not plans:
        raise failure or SolverError(None, "ptp", "no NLP solve was attempted")
    _, _, res, tr, chk = min(plans, key=lambda x: x[0])
    rk_chk = check_trajectory(pm, ruckig_fine, energy_weights=weights)
    if within_limits(rk_chk, FINE_GRID_ROUNDOFF, acc) and ruckig_fine.duration_s < tr.duration_s:
        tr = JointTrajectory("ptp", ruckig_fine.t_s, ruckig_fine.q, ruckig_fine.v, ruckig_fine.a,
                             {**ruckig_fine.info, "source": "ruckig"})
        chk = rk_chk
    else:
        tr.info["source"] = "nlp"
    tr.info["nlp_warm_start"] = res.info["warm_start"]
    tr.info["nlp_candidates_s"] = {start: d for d, start, *_ in plans}
    return res, tr, chk
