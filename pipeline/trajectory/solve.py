"""High-level planning: CP (convex + friction refinement + smooth variant + toppra baseline) and
PtP (time/energy NLP + ruckig baseline + fixed-duration energy optimum + Pareto sweep), each
re-checked on a fine time grid with the full friction model.

Public entry points: :func:`cp_joint_path`, :func:`plan_cp`, :func:`plan_ptp` (its solves verified on the
fine grid: :mod:`pipeline.trajectory.ptp_verified`).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pipeline.core.forks import fork_map
from pipeline.robot.defaults import iso_cube, ready_pose_rad
from pipeline.robot.iso9283 import iso9283_path, tool_rotation
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import SplinePath
from pipeline.robot.symbolic import SymbolicRobot
from pipeline.trajectory.baselines import (
    RuckigResult,
    ruckig_resampled,
    ruckig_torque_feasible,
    toppra_cp,
    toppra_within_limits,
)
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.cp import (
    CP_ACTIVE_LEVEL,
    CPProfile,
    cp_constraint_activity,
    cp_grid_activity,
    solve_cp_convex,
    solve_cp_refined,
)
from pipeline.trajectory.cp_smooth import SmoothCPResult, solve_cp_smooth
from pipeline.trajectory.design import JointPath, joint_path_from_cartesian
from pipeline.trajectory.dynamics import PlanningModel, torque_ratio
from pipeline.trajectory.pareto import settle_pareto
from pipeline.trajectory.ptp import PtpProblem, PtpResult, energy_weights
from pipeline.trajectory.ptp_verified import best_ptp_candidate, solve_ptp_verified
from pipeline.trajectory.reachability import solve_cp_reachability
from pipeline.trajectory.trajectories import (
    FINE_GRID_ROUNDOFF,
    JointTrajectory,
    TorqueCheck,
    check_trajectory,
)


def cp_joint_path(robot: RobotModel, cfg: TrajectoryConfig) -> tuple[JointPath, Any]:
    """The configured Cartesian path and its joint path by IK: a smooth piece of the EN ISO 9283
    path (stage 3's builder) or a cubic spline through ``cp_points_m``.

    Raises InfeasibleError naming the first unreachable sample or a joint jump larger than
    ``cp_max_ik_step_deg`` between samples.
    """
    cfg.validate()       # segment, spline points, centre: ConfigError naming the field
    cube_start = None
    if cfg.cp_segment == "spline":
        piece = SplinePath(np.asarray(cfg.cp_points_m, float), tool_rotation(cfg.cp_plane, True), label="spline")
    else:
        edge, centre = cfg.cp_edge_m, cfg.cp_centre_m
        rotation = tool_rotation(cfg.cp_plane, True)
        if edge is None or centre is None:           # None: the robot's largest feasible ISO cube (and its tool)
            cube = iso_cube(robot, cfg.cp_plane, None, frame=robot.frame_tcp)
            edge, centre = (cube.edge_m if edge is None else edge), (cube.centre_m if centre is None else centre)
            rotation = cube.rotation
            if cfg.cp_edge_m is None and cfg.cp_centre_m is None:
                cube_start = cube.q_start_rad      # the branch the cube search validated (a redundant arm's)
        iso = iso9283_path(robot, edge, tuple(centre), cfg.cp_plane, rotation, segments=(cfg.cp_segment,))
        piece = iso.pieces[0]
    seed = (np.radians(cfg.cp_ik_seed_deg) if cfg.cp_ik_seed_deg is not None
            else cube_start if cube_start is not None else ready_pose_rad(robot))
    path = joint_path_from_cartesian(robot, piece, cfg.cp_ik_points, seed,
                                     robot.frame_tcp, np.radians(cfg.cp_max_ik_step_deg),
                                     name=f"trajectory.cp_segment {cfg.cp_segment}")
    return path, piece


@dataclass
class CPPlan:
    path: JointPath
    toppra: CPProfile                 # baseline: rigid body + Coulomb, grid points
    equal: CPProfile                  # our convex problem with toppra's constraints
    convex: CPProfile | None          # rigid body + Coulomb at grid points and midpoints (cp_method nlp)
    optimal: CPProfile                # + viscous and smooth Coulomb (the result)
    smooth: SmoothCPResult | None
    trajectories: dict[str, JointTrajectory] = field(default_factory=dict)
    checks: dict[str, TorqueCheck] = field(default_factory=dict)
    activity: dict = field(default_factory=dict)
    timings_s: dict = field(default_factory=dict)
    #: toppra's profile, or toppra on a denser grid, or that slowed uniformly, the first that keeps every
    #: limit on the fine grid with the full friction model
    #: (:func:`~pipeline.trajectory.baselines.toppra_within_limits`; None: none does): the CP's peer
    toppra_feasible: CPProfile | None = None

    def _per_toppra(self, key: str) -> float | None:
        """A CPU time of ours / toppra's single solve, measured in the same run."""
        toppra = self.timings_s.get("cp_toppra_cpu")
        return self.timings_s[key] / toppra if toppra else None

    def summary(self) -> dict:
        s = {
            "cp_duration_s": self.optimal.duration_s,
            "cp_toppra_duration_s": self.toppra.duration_s,
            "cp_equal_constraints_duration_s": self.equal.duration_s,
            "cp_equal_vs_toppra_ratio": self.equal.duration_s / self.toppra.duration_s,
            "cp_convex_duration_s": None if self.convex is None else self.convex.duration_s,
            "cp_method": self.optimal.info.get("method"),
            "cp_solver_status": self.optimal.info.get("solver_status"),
            "cp_source": self.optimal.info.get("source", "ours"),
            "cp_ours_duration_s": self.optimal.info.get("ours_duration_s", self.optimal.duration_s),
            "cp_fine_max_acceleration_ratio": self.checks["cp"].max_acceleration_ratio,
            "cp_acceleration_limits": bool(self.optimal.info.get("acceleration_limits")),
            "cp_fine_violation": self.checks["cp"].violation,
            "cp_fine_max_velocity_ratio": self.checks["cp"].max_velocity_ratio,
            "cp_toppra_fine_violation_full_friction": self.checks["cp_toppra"].violation,
            "cp_toppra_fine_violation_rigid_coulomb": self.checks["cp_toppra_rigid"].violation,
            "cp_toppra_fine_max_acceleration_ratio": self.checks["cp_toppra"].max_acceleration_ratio,
            "cp_toppra_fine_max_velocity_ratio": self.checks["cp_toppra"].max_velocity_ratio,
            "cp_toppra_within_limits": self.toppra_feasible is self.toppra,
            "cp_toppra_feasible_duration_s": None if self.toppra_feasible is None else self.toppra_feasible.duration_s,
            "cp_toppra_feasible_n_grid": None if self.toppra_feasible is None else len(self.toppra_feasible.s) - 1,
            "cp_toppra_feasible_time_scale": (None if self.toppra_feasible is None
                                              else float(self.toppra_feasible.info.get("time_scale", 1.0))),
            "cp_n_grid": len(self.toppra.s) - 1,
            "cp_active_fraction": self.activity.get("active_fraction"),
            "cp_grid_min_activity": self.activity.get("grid_min_activity"),
            "cp_grid_active_fraction": self.activity.get("grid_active_fraction"),
            # to the verified plan (solve, fine-grid check, local re-solves) / one solve; wall and process CPU
            "cp_solve_time_s": self.timings_s.get("cp_convex", 0.0) + self.timings_s.get("cp_refined", 0.0),
            "cp_first_solve_time_s": self.timings_s.get("cp_first_solve"),
            "cp_solve_cpu_time_s": self.timings_s.get("cp_verified_cpu"),
            "cp_first_solve_cpu_time_s": self.timings_s.get("cp_first_solve_cpu"),
            "cp_tightening_rounds": self.timings_s.get("cp_tightening_rounds"),
            "cp_toppra_solve_time_s": self.toppra.solve_time_s,
            "cp_toppra_solve_cpu_time_s": self.timings_s.get("cp_toppra_cpu"),
            "cp_verified_vs_toppra_cpu_ratio": self._per_toppra("cp_verified_cpu"),
            "cp_first_solve_vs_toppra_cpu_ratio": self._per_toppra("cp_first_solve_cpu"),
        }
        if self.smooth is not None:
            s["cp_smooth_duration_s"] = self.smooth.duration_s
            s["cp_smooth_time_cost"] = self.smooth.duration_s / self.optimal.duration_s - 1.0
            s["cp_smooth_fine_violation"] = self.checks["cp_smooth"].violation
            s["cp_smooth_solve_time_s"] = self.smooth.solve_time_s
        return s


def verified_cp(pm: PlanningModel, path: JointPath, opt: CPProfile, cfg: TrajectoryConfig,
                 solve: Callable[[np.ndarray | None, np.ndarray | None, CPProfile | None], CPProfile],
                 ) -> tuple[CPProfile, int]:
    """Check ``opt`` on the fine time grid (full friction model) and, while a torque (or, with
    ``cfg.acceleration_limits``, a joint acceleration) exceeds its limit by more than
    ``cfg.violation_tolerance``, tighten and re-solve warm-started from it (the reachability solver
    from its speeds, the NLP from its primal and dual solution). Tightening is local: only the grid
    intervals (and joints) whose fine samples exceed, by their excess; the grid enforces the limits
    at each interval's ends and midpoint, and between them the path's curvature moves both.
    ``solve(torque_scale, acceleration_scale, warm)``. Returns the plan and the number of re-solves."""
    N = len(opt.s) - 1
    scales = {"torque": np.ones((N, pm.nq)), "acceleration": np.ones((N, pm.nq))}
    rounds = 0
    for _ in range(cfg.max_tightening_rounds):
        tr = opt.sample(path, cfg.fine_dt_s)
        ratios = {"torque": torque_ratio(pm, pm.torques(tr.q, tr.v, tr.a))}     # full model, every fine sample
        if cfg.acceleration_limits:
            ratios["acceleration"] = np.abs(tr.a) / pm.acceleration_rad_s2
        if max(r.max() for r in ratios.values()) <= 1.0 + cfg.violation_tolerance:
            break
        rounds += 1
        k = np.clip(np.searchsorted(opt.grid_times(), tr.t_s, side="right") - 1, 0, N - 1)
        for kind, ratio in ratios.items():
            worst = np.zeros((N, pm.nq))
            np.maximum.at(worst, k, ratio)
            bad = worst > 1.0 + cfg.violation_tolerance
            scales[kind][bad] = scales[kind][bad] / worst[bad] * (1.0 - 0.25 * cfg.violation_tolerance)
        opt = solve(scales["torque"], scales["acceleration"] if cfg.acceleration_limits else None, opt)
    return opt, rounds


def shorter_cp(ours: CPProfile, peer: CPProfile | None) -> CPProfile:
    """The CP handed on, never slower than toppra: ``peer`` (toppra's profile made to keep every limit
    on the fine time grid with the full friction model to the round-off
    :data:`~pipeline.trajectory.trajectories.FINE_GRID_ROUNDOFF`, not to the gates' slack,
    :func:`~pipeline.trajectory.baselines.toppra_within_limits`) when it is shorter than ours, else
    ours. Ours enforces the limits at each interval's midpoint as well as its ends and toppra at its
    grid points alone; on a denser grid toppra's can be a few per mille shorter. ``info["source"]``
    says which (``ours`` or ``toppra``), ``info["ours_duration_s"]`` keeps ours."""
    if peer is None or peer.duration_s >= ours.duration_s:
        return ours
    return replace(peer, name="cp", info={**ours.info, "source": "toppra", "ours_duration_s": ours.duration_s},
                   multipliers=None, nlp=None)


def plan_cp(pm: PlanningModel, path: JointPath, cfg: TrajectoryConfig) -> CPPlan:
    """Time-optimal CP on ``path``: toppra baseline, our convex problem with toppra's
    constraints (equal-constraints comparison), convex + midpoints, friction refinement,
    smooth variant; all re-checked on a ``cfg.fine_dt_s`` grid with the full friction model."""
    N = cfg.cp_n_grid
    acc = bool(cfg.acceleration_limits)
    tim = {}
    c0 = time.process_time()
    tp = toppra_cp(pm, path, N, acceleration_limits=acc)
    tim["cp_toppra_cpu"] = time.process_time() - c0
    eq = solve_cp_convex(pm, path, N, midpoints=False, name="cp_equal", acceleration_limits=acc)
    cv = None

    def solve(scale: np.ndarray | None, acceleration_scale: np.ndarray | None, warm: CPProfile | None) -> CPProfile:
        if cfg.cp_method == "reachability":
            return solve_cp_reachability(pm, path, N, name="cp", torque_margin=cfg.cp_torque_margin,
                                         torque_scale=scale, acceleration_limits=acc, warm=warm,
                                         acceleration_scale=acceleration_scale)
        return solve_cp_refined(pm, path, warm, midpoints=True, name="cp", torque_margin=cfg.cp_torque_margin,
                                torque_scale=scale, acceleration_limits=acc, acceleration_scale=acceleration_scale)

    if cfg.cp_method == "nlp":
        t0 = time.perf_counter()
        cv = solve_cp_convex(pm, path, N, midpoints=True, name="cp_convex", acceleration_limits=acc)
        tim["cp_convex"] = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), time.process_time()
    opt = solve(None, None, cv)
    tim["cp_first_solve"], tim["cp_first_solve_cpu"] = time.perf_counter() - t0, time.process_time() - c0
    opt, tim["cp_tightening_rounds"] = verified_cp(pm, path, opt, cfg, solve)
    tim["cp_verified_cpu"] = time.process_time() - c0
    tim["cp_refined"] = time.perf_counter() - t0
    # the peer's refinements and checks are the baseline's work, not counted in our solve times
    peer = toppra_within_limits(pm, path, tp, cfg.fine_dt_s, FINE_GRID_ROUNDOFF, acc)
    opt = shorter_cp(opt, peer)
    sm = None
    if cfg.cp_smooth:
        margin = cfg.cp_smooth_torque_margin
        for _ in range(cfg.max_tightening_rounds + 1):
            sm = solve_cp_smooth(pm, path, opt, cfg.cp_smooth_intervals, cfg.cp_smooth_jerk_rise_time_s,
                                 torque_margin=margin, acceleration_limits=acc)
            chk = check_trajectory(pm, sm.sample(path, cfg.fine_dt_s))
            over = max(chk.max_torque_ratio, chk.max_acceleration_ratio if acc else 0.0) - 1.0
            if over <= cfg.violation_tolerance:
                break
            margin = 1.0 - (1.0 - margin) / (1.0 + over) * (1.0 - 0.25 * cfg.violation_tolerance)
        sm.info["torque_margin"] = margin
    trajs = {"cp": opt.sample(path, cfg.fine_dt_s), "cp_toppra": tp.sample(path, cfg.fine_dt_s)}
    if sm is not None:
        trajs["cp_smooth"] = sm.sample(path, cfg.fine_dt_s)
    checks = {k: check_trajectory(pm, v) for k, v in trajs.items()}
    # toppra against the model it was given (rigid body + sharp Coulomb), for reference
    tr = trajs["cp_toppra"]
    rigid = pm.rigid_torques(tr.q, tr.v, tr.a) + pm.coulomb_Nm * np.sign(np.where(np.abs(tr.v) < 1e-9, 0, tr.v))
    r = np.abs(rigid) / pm.effort_Nm
    checks["cp_toppra_rigid"] = TorqueCheck(tr.t_s, rigid, r, np.abs(tr.v) / pm.velocity_rad_s,
                                            float(r.max()), float(max(0.0, r.max() - 1.0)), 0.0, 0.0)
    act = cp_constraint_activity(pm, path, trajs["cp"], checks["cp"].tau_Nm)
    act["grid_activity"] = cp_grid_activity(pm, path, opt)
    act["grid_min_activity"] = float(act["grid_activity"].min())
    # share of grid points with some limit at >= 98 % (paper 004 Fig. 8: always one active)
    act["grid_active_fraction"] = float(np.mean(act["grid_activity"] >= CP_ACTIVE_LEVEL))
    return CPPlan(path, tp, eq, cv, opt, sm, trajs, checks, act, tim, peer)


@dataclass
class PTPPlan:
    q0: np.ndarray
    q1: np.ndarray
    weights: np.ndarray
    result: PtpResult
    ruckig: RuckigResult
    at_ruckig_duration: PtpResult | None          # None: no plan of the transcription at ruckig's duration
    pareto: list[PtpResult]
    trajectories: dict[str, JointTrajectory] = field(default_factory=dict)
    checks: dict[str, TorqueCheck] = field(default_factory=dict)
    compile_time_s: float = 0.0
    build_time_s: float = 0.0
    at_ruckig_duration_note: str = ""             # why at_ruckig_duration is None

    def summary(self) -> dict:
        """Headline figures. Every energy here (``ptp_energy``, ``ptp_energy_at_ruckig_duration``,
        ``ptp_ruckig_energy`` and each ``ptp_pareto`` entry's ``energy``) is the fine-grid re-check
        ``check_trajectory(pm, traj sampled every fine_dt_s, energy_weights=weights).energy``
        (full friction model, trapezoid rule), never the optimiser's Simpson-rule value
        ``PtpResult.energy``, so the same motion always reports the same energy. Violations are
        fractions over the planning limit (0.005 = 0.5 %). ``ptp_pareto`` entries: ``k2``,
        ``duration_s``, ``energy``, ``dominated`` (another point of the sweep is at least as short
        and as economical: a poorer local optimum, kept after a cold-start re-solve did not beat it)
        and ``cold_restart`` (the outcome of that re-solve, None when the point was not dominated)."""
        e_rk = self.checks["ptp_ruckig"].energy
        fixed = self.checks.get("ptp_energy_at_ruckig_duration")
        e_nlp = None if fixed is None else fixed.energy
        return {
            "ptp_duration_s": self.trajectories["ptp"].duration_s,     # the plan handed on (slowed into
            "ptp_nlp_duration_s": self.result.duration_s,              # the fine-grid limits) / the NLP's
            "ptp_ruckig_duration_s": self.ruckig.duration_s,
            "ptp_duration_vs_ruckig_ratio": self.trajectories["ptp"].duration_s / self.ruckig.duration_s,
            # which candidate is the plan (nlp, or ruckig's profile when no NLP solve beat it) and the
            # start of the NLP solve kept (quintic, or ruckig's profile)
            "ptp_source": self.trajectories["ptp"].info.get("source", "nlp"),
            "ptp_nlp_warm_start": self.result.info.get("warm_start"),
            "ptp_fine_violation": self.checks["ptp"].violation,
            "ptp_fine_max_velocity_ratio": self.checks["ptp"].max_velocity_ratio,
            "ptp_ruckig_fine_violation": self.checks["ptp_ruckig"].violation,
            "ptp_energy": self.checks["ptp"].energy,
            "ptp_energy_at_ruckig_duration": e_nlp,
            "ptp_ruckig_energy": e_rk,
            "ptp_energy_at_ruckig_duration_ratio": None if e_nlp is None else e_nlp / e_rk,
            "ptp_energy_at_ruckig_duration_fine_violation": None if fixed is None else fixed.violation,
            "ptp_energy_at_ruckig_duration_note": self.at_ruckig_duration_note,
            "ptp_solve_time_s": self.result.solve_time_s,
            "ptp_solver_status": self.result.info.get("solver_status"),
            "ptp_energy_at_ruckig_duration_solver_status": self.at_ruckig_duration_status(),
            "ptp_fine_max_acceleration_ratio": self.checks["ptp"].max_acceleration_ratio,
            "ptp_ruckig_fine_max_acceleration_ratio": self.checks["ptp_ruckig"].max_acceleration_ratio,
            "ptp_acceleration_limits": bool(self.result.info.get("acceleration_limits")),
            "ptp_solve_cpu_time_s": self.result.info.get("cpu_time_s"),
            "ptp_first_solve_time_s": self.result.info.get("first_solve_time_s"),
            "ptp_tightening_rounds": self.result.info.get("tightening_rounds"),
            "ptp_iterations": self.result.iterations,
            "ptp_compile_time_s": self.compile_time_s,
            "ptp_ruckig_search_time_s": self.ruckig.search_time_s,
            "ptp_pareto": [{"k2": r.k2, "duration_s": r.duration_s, "energy": r.info["fine_energy"],
                            "dominated": bool(r.info.get("dominated", False)),
                            "cold_restart": r.info.get("cold_restart")} for r in self.pareto],
        }


    def at_ruckig_duration_status(self) -> str | None:
        """IPOPT status of the energy plan at ruckig's duration, or ``not_attempted`` when there is none."""
        if self.at_ruckig_duration is None:
            return "not_attempted"
        return self.at_ruckig_duration.info.get("solver_status")


def ptp_problem(pm: PlanningModel, robot: RobotModel, cfg: TrajectoryConfig) -> PtpProblem:
    """The PtP NLP for ``robot``'s dynamics (symbolic bridge), compiled once and cached on disk."""
    return PtpProblem(pm, SymbolicRobot(robot), cfg.ptp_n_intervals, jit=cfg.ptp_jit,
                      # tol 1e-4 on the scaled KKT error with constraints (dynamics defects in rad, torques
                      # over their limits) held to 1e-6: half the IPOPT iterations of tol 1e-6 over 12
                      # moves of the nominal and the identified RX130L, total duration within 0.01 %
                      ipopt_options={"ipopt.tol": 1e-4, "ipopt.constr_viol_tol": 1e-6,
                                     "ipopt.acceptable_tol": 1e-4, "ipopt.acceptable_constr_viol_tol": 1e-6,
                                     "ipopt.mu_strategy": "adaptive"},
                      jit_flags=(*cfg.ptp_jit_flags, "-shared", "-fPIC"))


def plan_ptp(pm: PlanningModel, problem: PtpProblem, q0: np.ndarray, q1: np.ndarray,
             cfg: TrajectoryConfig, pareto: bool = True) -> PTPPlan:
    """Time-optimal PtP (k1, k2), never slower than its ruckig baseline (:func:`best_ptp_candidate`),
    minimum energy at ruckig's duration, Pareto sweep."""
    w = energy_weights(pm, cfg.ptp_energy, cfg.motor_resistance_ohm, cfg.torque_constant_Nm_A,
                       getattr(getattr(pm.robot, "actuation", None), "gear_ratio", None))
    rk = ruckig_torque_feasible(pm, q0, q1, cfg.ruckig_check_dt_s, tuple(cfg.ruckig_jerk_ratios_1_s),
                                joint_rounds=cfg.ruckig_joint_rounds,
                                refine_evaluations=cfg.ruckig_refine_evaluations,
                                acceleration_limits=cfg.acceleration_limits)
    # the baseline verified on the same fine grid as every plan
    rk_fine = ruckig_resampled(pm, q0, q1, rk, cfg.fine_dt_s)
    res, ptp_tr, ptp_chk = best_ptp_candidate(pm, problem, q0, q1, cfg, w, rk_fine)
    note = ""
    energy_at_ruckig = rk.duration_s >= res.duration_s
    if not energy_at_ruckig:
        # ruckig's jerk-limited profile of a kinematically limited move switches its accelerations
        # between the transcription's nodes: no plan of this transcription exists at its duration
        note = (f"ruckig's plan ({rk.duration_s:.4f} s) is shorter than this transcription's minimum time "
                f"({res.duration_s:.4f} s, {problem.N} intervals): no energy plan at ruckig's duration")
    # the Pareto sweep: continuation from the main solution outwards (k1 = 1), same verification as
    # the main one; its two branches and the energy plan at ruckig's duration are independent chains
    # of solves, run side by side on forked workers (:func:`pipeline.core.forks.fork_map`, same numbers)
    ks = sorted(float(k) for k in cfg.ptp_pareto_k2) if pareto else []
    up = [k for k in ks if k > cfg.ptp_k2 and not np.isclose(k, cfg.ptp_k2)]
    down = [k for k in reversed(ks) if k < cfg.ptp_k2 and not np.isclose(k, cfg.ptp_k2)]
    scale0 = np.asarray(res.info["torque_scale"])

    def continuation(branch: list[float]) -> list[PtpResult]:
        out, prev = [], res
        for k2 in branch:
            prev = solve_ptp_verified(pm, problem, q0, q1, cfg, 1.0, k2, w, x0=prev.info["x"], torque_scale=scale0)
            out.append(prev)
        return out

    def at_ruckig_duration() -> list[PtpResult]:
        return [solve_ptp_verified(pm, problem, q0, q1, cfg, 0.0, 1.0, w, duration_s=rk.duration_s,
                                   coulomb_widths_rad_s=tuple(cfg.ptp_fixed_coulomb_widths_rad_s))]

    tasks: list[tuple[int, bool, Callable[[], list[PtpResult]]]] = [
        (len(b), False, functools.partial(continuation, b)) for b in (up, down) if b]
    if energy_at_ruckig:
        tasks.append((1, True, at_ruckig_duration))
    tasks.sort(key=lambda t: -t[0])          # the longest chain first: the workers finish together
    fixed: PtpResult | None = None
    sweep: list[PtpResult] = []
    for (_, is_fixed, _), out in zip(tasks, fork_map(lambda k: tasks[k][2](), len(tasks)), strict=True):
        if is_fixed:
            fixed = out[0]
        else:
            sweep += out
    if pareto:
        if cfg.ptp_k1 == 1.0 and any(np.isclose(k, cfg.ptp_k2) for k in ks):
            sweep.append(res)          # the main solution is a point of the front too
        sweep.sort(key=lambda r: r.k2)
        # energies on the fine grid (as every other reported energy); a dominated point of the
        # warm-started continuation is re-solved once from a cold start (the main solution
        # already is one), the lower objective kept, a still dominated point flagged
        sweep = settle_pareto(
            sweep, lambda r: check_trajectory(pm, r.sample(cfg.fine_dt_s), energy_weights=w).energy,
            lambda r: solve_ptp_verified(pm, problem, q0, q1, cfg, r.k1, r.k2, w, torque_scale=scale0),
            cold_started=(res,))
    trajs = {"ptp": ptp_tr, "ptp_ruckig": rk_fine}
    if fixed is not None:
        trajs["ptp_energy_at_ruckig_duration"] = fixed.sample(cfg.fine_dt_s, "ptp_energy_at_ruckig_duration")
    checks = {k: check_trajectory(pm, v, energy_weights=w) for k, v in trajs.items() if k != "ptp"}
    checks["ptp"] = ptp_chk
    return PTPPlan(np.asarray(q0, float), np.asarray(q1, float), w, res, rk, fixed, sweep, trajs, checks,
                   problem.compile_time_s, problem.build_time_s, note)
