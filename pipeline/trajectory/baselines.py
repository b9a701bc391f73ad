"""Baselines run in the same stage: toppra for CP, ruckig for PtP.

* toppra (reachability analysis, Pham & Pham 2018) on the same joint path with the
  constraints it can express: joint speed limits and ``JointTorqueConstraint`` with the
  rigid-body inverse dynamics and Coulomb friction as its dry-friction coefficients
  ``fs_coef * sign(q')``. Viscous friction cannot be expressed (DESIGN.md "Measured facts").
* ruckig (jerk-limited time-optimal kinematics): the most aggressive kinematic limits whose
  torques (full model, checked every ``check_dt_s`` <= 0.5 ms) stay within the torque limits,
  found by bisection on a scale factor of reference accelerations for several jerk/acceleration
  ratios.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
import toppra
import toppra.algorithm as algo
import toppra.constraint as constraint
from ruckig import InputParameter, Result, Ruckig, Trajectory
from scipy.optimize import minimize

from pipeline.core.errors import InfeasibleError, SolverError
from pipeline.trajectory.cp import CPProfile
from pipeline.trajectory.design import JointPath
from pipeline.trajectory.dynamics import PlanningModel
from pipeline.trajectory.trajectories import JointTrajectory, check_trajectory, within_limits


def _toppra_path(path: JointPath):
    class _Path(toppra.interpolator.AbstractGeometricPath):
        def __call__(self, s, order=0):
            out = path(np.asarray(s, float), order)
            if order >= 1:
                out = np.where(np.abs(out) < 1e-9, 0.0, out)
            return out

        @property
        def dof(self):
            return path.nq

        @property
        def path_interval(self):
            return np.array([0.0, 1.0])

    return _Path()


#: the most uniform slow-downs tried to bring toppra's profile within the limits on the fine grid
MAX_SLOWDOWN_STEPS = 40
#: toppra's grid refined by these factors, densest last, before its profile is slowed uniformly
TOPPRA_GRID_REFINEMENTS = (2, 4, 8)


def toppra_within_limits(pm: PlanningModel, path: JointPath, profile: CPProfile, fine_dt_s: float,
                         tolerance: float, acceleration_limits: bool) -> CPProfile | None:
    """The peer a CP's duration is judged by: toppra's profile when it keeps every limit on the fine
    time grid with the full friction model; else toppra on a grid :data:`TOPPRA_GRID_REFINEMENTS` times
    as dense, the first that does; else the densest one slowed uniformly (``time_scale`` > 1) until
    it does. toppra enforces its constraints at the grid points alone (collocation), so between them
    a joint acceleration or torque may exceed its limit, less on a denser grid. The first scale is
    ``max(speed ratio, sqrt(acceleration ratio))``, then it grows by the remaining excess; None when
    no scale up to :data:`MAX_SLOWDOWN_STEPS` steps succeeds (gravity alone over a torque limit)."""
    n_grid = len(profile.s) - 1
    for factor in (1, *TOPPRA_GRID_REFINEMENTS):
        if factor > 1:
            profile = toppra_cp(pm, path, factor * n_grid, name=profile.name, acceleration_limits=acceleration_limits)
        check = check_trajectory(pm, profile.sample(path, fine_dt_s))
        if within_limits(check, tolerance, acceleration_limits):
            return profile
    scale = max(1.0, check.max_velocity_ratio,
                float(np.sqrt(check.max_acceleration_ratio)) if acceleration_limits else 1.0)
    for _ in range(MAX_SLOWDOWN_STEPS):
        slowed = profile.time_scaled(scale, f"{profile.name}_slowed")
        check = check_trajectory(pm, slowed.sample(path, fine_dt_s))
        if within_limits(check, tolerance, acceleration_limits):
            return slowed
        excess = max(check.violation, check.max_velocity_ratio - 1.0,
                     check.max_acceleration_ratio - 1.0 if acceleration_limits else 0.0)
        scale *= 1.0 + max(excess, tolerance, 1e-6)
    return None


def toppra_cp(pm: PlanningModel, path: JointPath, n_grid: int = 400, coulomb: bool = True,
              name: str = "cp_toppra", acceleration_limits: bool = False) -> CPProfile:
    """toppra time-optimal profile on the same grid (collocation), velocity + torque limits
    (+ ``JointAccelerationConstraint`` at ``pm.acceleration_rad_s2`` with ``acceleration_limits``)."""
    toppra.setup_logging("WARNING")
    t0 = time.perf_counter()
    data = pm.model.createData()

    def inv_dyn(q, v, a):
        return pin.rnea(pm.model, data, np.asarray(q, float), np.asarray(v, float), np.asarray(a, float))

    vlim = np.stack([-pm.velocity_rad_s, pm.velocity_rad_s], axis=1)
    tlim = np.stack([-pm.effort_Nm, pm.effort_Nm], axis=1)
    fs = pm.coulomb_Nm if coulomb else np.zeros(pm.nq)
    cons = [constraint.JointVelocityConstraint(vlim),
            constraint.JointTorqueConstraint(inv_dyn, tlim, fs,
                                             discretization_scheme=constraint.DiscretizationType.Collocation)]
    if acceleration_limits:
        alim = np.stack([-pm.acceleration_rad_s2, pm.acceleration_rad_s2], axis=1)
        cons.append(constraint.JointAccelerationConstraint(
            alim, discretization_scheme=constraint.DiscretizationType.Collocation))
    grid = np.linspace(0.0, 1.0, n_grid + 1)
    inst = algo.TOPPRA(cons, _toppra_path(path), gridpoints=grid, solver_wrapper="seidel")
    _, sd_vec, _ = inst.compute_parameterization(0.0, 0.0)
    if sd_vec is None:
        raise SolverError(None, name, "toppra found no feasible parametrisation")
    sd = np.sqrt(np.maximum(np.asarray(sd_vec, float) ** 2, 0.0))
    ds = np.diff(grid)
    dur = float(np.sum(2 * ds / np.maximum(sd[:-1] + sd[1:], 1e-300)))
    sdd = np.diff(sd**2) / (2 * ds)
    return CPProfile(name, grid, sd, sdd, dur, time.perf_counter() - t0,
                     info={"n_grid": n_grid, "coulomb": coulomb, "method": "toppra seidel collocation",
                           "acceleration_limits": acceleration_limits})


@dataclass
class RuckigResult:
    trajectory: JointTrajectory
    duration_s: float
    accel_scale: float
    jerk_ratio_1_s: float
    max_torque_ratio: float
    search_time_s: float
    evaluations: int
    info: dict = field(default_factory=dict)


def _ruckig_input(q0, q1, vmax, amax, jmax, amin=None):

    n = len(q0)
    inp = InputParameter(n)
    inp.current_position, inp.target_position = list(q0), list(q1)
    inp.current_velocity = inp.current_acceleration = [0.0] * n
    inp.target_velocity = inp.target_acceleration = [0.0] * n
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = list(vmax), list(amax), list(jmax)
    if amin is not None:
        inp.min_acceleration = list(-np.asarray(amin, float))
    return inp


def _ruckig_sample(q0: np.ndarray, q1: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
                   jmax: np.ndarray, dt_s: float, amin: np.ndarray | None = None) -> JointTrajectory | None:

    n = len(q0)
    traj = Trajectory(n)
    res = Ruckig(n).calculate(_ruckig_input(q0, q1, vmax, amax, jmax, amin), traj)
    if res not in (Result.Working, Result.Finished):
        return None
    T = traj.duration
    t = np.append(np.arange(0.0, T, dt_s), T)
    Q, V, A = _states_at(traj, t)
    return JointTrajectory("ptp_ruckig", t, Q, V, A)


def _integrate(t: np.ndarray, p0: np.ndarray, v0: np.ndarray, a0: np.ndarray,
               j: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ruckig's ``integrate``: constant jerk ``j`` for ``t`` from (p0, v0, a0), its order of operations."""
    return p0 + t * (v0 + t * (a0 / 2 + t * j / 6)), v0 + t * (a0 + t * j / 2), a0 + t * j


def _states_at(traj: Trajectory, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``traj.at_time`` at all times ``t`` at once, each ``(len(t), dofs)``: per joint the phase holding
    each time (``t_sum`` = cumulative phase durations, ``upper_bound``), then ruckig's ``integrate`` from
    the phase's start state, past the end at constant acceleration from the final state; the same
    arithmetic as ruckig's ``Trajectory::at_time`` (one section, no brake pre-trajectory), so the same
    numbers without a Python call per sample. A trajectory with a brake phase or several sections is
    sampled by ruckig itself."""
    profiles = traj.profiles
    if len(profiles) != 1 or any(p.brake.duration > 0 for p in profiles[0]):
        states = np.array([traj.at_time(tk) for tk in t], float)     # (len(t), 3, dofs)
        return states[:, 0], states[:, 1], states[:, 2]
    out = np.empty((3, t.size, len(profiles[0])))
    past = t >= traj.duration
    for dof, prof in enumerate(profiles[0]):
        t_sum = np.cumsum(prof.t)           # ruckig: t_sum[i + 1] = t_sum[i] + t[i + 1]
        p, v, a, j = (np.asarray(x, float) for x in (prof.p, prof.v, prof.a, [*prof.j, 0.0]))
        end = past | (t >= t_sum[-1])
        index = np.where(end, 7, np.searchsorted(t_sum, t, side="right"))
        start = np.concatenate([[0.0], t_sum])[index]
        tau = np.where(past, t - (prof.brake.duration + t_sum[-1]), t - start)
        tau = np.where(end & ~past, t - t_sum[-1], tau)
        out[:, :, dof] = _integrate(tau, p[index], v[index], a[index], j[index])
    return out[0], out[1], out[2]


#: ruckig moves a search keeps (about 0.3 MB each): the bisections and the simplex come back to a
#: limit at most 28 moves after trying it (RX130L's robot.yaml move)
_KEPT_MOVES = 32


class _CheckedSamples:
    """ruckig moves of one search (start, goal, speed limits fixed) with their largest full-model torque
    ratio, the last :data:`_KEPT_MOVES` kept: a move tried again is not computed again."""

    def __init__(self, pm: PlanningModel, q0: np.ndarray, q1: np.ndarray) -> None:
        self.pm, self.q0, self.q1 = pm, q0, q1
        self._kept: OrderedDict[tuple[bytes, ...], tuple[JointTrajectory | None, float]] = OrderedDict()

    def __call__(self, ap: np.ndarray, am: np.ndarray, jm: np.ndarray,
                 dt_s: float) -> tuple[JointTrajectory | None, float]:
        key = (*(np.asarray(x, float).tobytes() for x in (ap, am, jm)), np.float64(dt_s).tobytes())
        if key in self._kept:
            self._kept.move_to_end(key)
            return self._kept[key]
        tr = _ruckig_sample(self.q0, self.q1, self.pm.velocity_rad_s, ap, jm, dt_s, amin=am)
        result = (None, np.inf) if tr is None else (tr, check_trajectory(self.pm, tr).max_torque_ratio)
        self._kept[key] = result
        if len(self._kept) > _KEPT_MOVES:
            self._kept.popitem(last=False)
        return result


def ruckig_torque_feasible(pm: PlanningModel, q0: np.ndarray, q1: np.ndarray, check_dt_s: float = 5e-4,
                           jerk_ratios_1_s: tuple[float, ...] = (10.0, 25.0, 60.0),
                           bisection_steps: int = 12, joint_rounds: int = 6, tol: float = 0.0,
                           refine_evaluations: int = 0, refine_dt_s: float = 2e-3,
                           acceleration_limits: bool = False) -> RuckigResult:
    """Fastest ruckig move whose full-model torques stay within limits (max ratio <= 1 + tol).

    ``acceleration_limits``: every searched acceleration limit is capped at
    ``pm.acceleration_rad_s2`` (ruckig then never exceeds it).

    The kinematic limits searched: per joint a maximum and a (separate) minimum acceleration
    ``alpha_i^± a_ref_i`` (``a_ref_i = tau_max_i / M_ii(q0)``; separate signs let the
    baseline use gravity), jerks ``ratio * max(alpha^±) a_ref``, velocities at the joint speed
    limits. First a common ``alpha`` by bisection, then ``joint_rounds`` rounds in which the joint
    that sets the duration (largest independent minimum duration) gets each of its two factors
    raised by bisection while the move stays torque-feasible. Repeated for several
    jerk/acceleration ratios; the shortest feasible move wins.

    The joint-wise rounds stall when the joints are coupled (on a heavy arm the axis-2 torque
    near the goal is gravity plus the centrifugal load of axis 1, so raising one factor violates
    another joint). ``refine_evaluations > 0`` then continues with Nelder-Mead on the 2 nq
    log-factors of the winner (its jerk ratio): each candidate direction is scaled by bisection
    onto the torque boundary (checked every ``refine_dt_s``) and scored by its duration; the best
    one is finally scaled down, by bisection, until it is feasible on the ``check_dt_s`` grid.
    """
    t0 = time.perf_counter()
    a_ref = pm.effort_Nm / np.maximum(pm.mass_diagonal(q0), 1e-9)
    best: RuckigResult | None = None
    evals = 0

    a_cap = np.asarray(pm.acceleration_rad_s2, float) if acceleration_limits else np.full(pm.nq, np.inf)

    def limits(al: np.ndarray, ratio: float):
        ap, am = np.minimum(al[: pm.nq] * a_ref, a_cap), np.minimum(al[pm.nq:] * a_ref, a_cap)
        return ap, am, ratio * np.maximum(ap, am)

    checked = _CheckedSamples(pm, q0, q1)

    def run(al: np.ndarray, ratio: float):
        nonlocal evals
        evals += 1
        ap, am, jm = limits(al, ratio)
        return checked(ap, am, jm, check_dt_s)

    def bisect(make, lo: float, hi: float):
        """Largest factor in [lo, hi] that is feasible, given feasible(lo) (or lo == 0)."""
        good = None
        tr_hi, r_hi = make(hi)
        while r_hi <= 1.0 + tol and hi < 1e4:
            lo, good, hi = hi, (tr_hi, r_hi), 2 * hi
            tr_hi, r_hi = make(hi)
        for _ in range(bisection_steps):
            mid = 0.5 * (lo + hi) if lo > 0 else hi / 4
            tr, r = make(mid)
            if r <= 1.0 + tol:
                lo, good = mid, (tr, r)
            else:
                hi = mid
            if lo > 0 and (hi - lo) / hi < 2e-3:
                break
        return lo, good

    for ratio in jerk_ratios_1_s:
        scale, good = bisect(lambda a, ratio=ratio: run(np.full(2 * pm.nq, a), ratio), 0.0, 1.0)
        if good is None:
            continue
        alpha = np.full(2 * pm.nq, scale)
        for _ in range(joint_rounds):
            ap, am, jm = limits(alpha, ratio)
            durations = _independent_durations(q0, q1, pm.velocity_rad_s, ap, jm, am)
            j = int(np.argmax(durations))
            improved = False
            for idx in (j, j + pm.nq):
                def make(f, idx=idx, alpha=alpha, ratio=ratio):
                    al = alpha.copy()
                    al[idx] = f
                    return run(al, ratio)
                f_new, g_new = bisect(make, alpha[idx], alpha[idx] * 1.5)
                if g_new is not None and f_new > alpha[idx] * (1 + 2e-3) \
                        and g_new[0].duration_s < good[0].duration_s * (1 - 1e-5):
                    alpha[idx] = f_new
                    good = g_new
                    improved = True
            if not improved:
                break
        tr, r = good
        if best is None or tr.duration_s < best.duration_s:
            best = _ruckig_result(tr, r, alpha, ratio, limits)
    if best is None:
        raise InfeasibleError(None, "ptp ruckig baseline", "no torque-feasible kinematic limits found "
                              "(the static torques may exceed the limits)")
    if refine_evaluations > 0:
        refined = _refine(best, limits, checked, check_dt_s, refine_dt_s, refine_evaluations, tol)
        evals += refined[1]
        if refined[0] is not None and refined[0].duration_s < best.duration_s:
            best = refined[0]
            best.info["refined"] = True
    best.search_time_s = time.perf_counter() - t0
    best.evaluations = evals
    best.trajectory.info.update({"jerk_ratio_1_s": best.jerk_ratio_1_s, **best.info})
    return best


def ruckig_resampled(pm: PlanningModel, q0: np.ndarray, q1: np.ndarray, rk: RuckigResult, dt_s: float,
                     name: str = "ptp_ruckig") -> JointTrajectory:
    """The same ruckig profile (its searched limits) sampled every ``dt_s``, e.g. on the fine grid."""
    info = rk.info
    tr = _ruckig_sample(np.asarray(q0, float), np.asarray(q1, float), pm.velocity_rad_s,
                        np.asarray(info["max_accel_rad_s2"], float), np.asarray(info["jerk_rad_s3"], float), dt_s,
                        amin=-np.asarray(info["min_accel_rad_s2"], float))
    if tr is None:
        raise SolverError(None, "ptp ruckig baseline", "ruckig cannot recompute its own profile")
    tr.name = name
    tr.info.update(rk.trajectory.info)
    return tr


def _ruckig_result(tr: JointTrajectory, r: float, alpha: np.ndarray, ratio: float, limits) -> RuckigResult:
    ap, am, jm = limits(alpha, ratio)
    return RuckigResult(tr, tr.duration_s, float(np.min(alpha)), ratio, r, 0.0, 0,
                        info={"max_accel_rad_s2": ap.tolist(), "min_accel_rad_s2": (-am).tolist(),
                              "jerk_rad_s3": jm.tolist(), "alpha": alpha.tolist(), "refined": False})


def _refine(start: RuckigResult, limits, checked: _CheckedSamples, check_dt_s: float,
            search_dt_s: float, max_evaluations: int, tol: float) -> tuple[RuckigResult | None, int]:
    """Nelder-Mead over log(alpha) (see :func:`ruckig_torque_feasible`); returns (result or None, evals)."""

    ratio = start.jerk_ratio_1_s
    count = 0

    def run(log_alpha: np.ndarray, dt_s: float):
        nonlocal count
        count += 1
        ap, am, jm = limits(np.exp(log_alpha), ratio)
        return checked(ap, am, jm, dt_s)

    def onto_boundary(x: np.ndarray, dt_s: float, lo: float, hi: float, steps: int):
        """Largest common log-shift in [lo, hi] keeping ``x`` feasible (None when lo is not)."""
        tr, r = run(x + hi, dt_s)
        if r <= 1.0 + tol:
            return hi, tr, r
        found = None
        for _ in range(steps):
            mid = 0.5 * (lo + hi)
            tr, r = run(x + mid, dt_s)
            if r <= 1.0 + tol:
                lo, found = mid, (tr, r)
            else:
                hi = mid
        if found is None:
            tr, r = run(x + lo, dt_s)
            if r > 1.0 + tol:
                return None
            found = (tr, r)
        return lo, *found

    best: dict = {"duration": np.inf, "x": None}

    def objective(x: np.ndarray) -> float:
        b = onto_boundary(x, search_dt_s, -0.4, 0.3, 6)
        if b is None:
            return 1e3
        shift, tr, _ = b
        if tr.duration_s < best["duration"]:
            best.update(duration=tr.duration_s, x=x + shift)
        return tr.duration_s

    x0 = np.log(np.asarray(start.info["alpha"], float))
    n_obj = max(1, max_evaluations // 8)
    minimize(objective, x0, method="Nelder-Mead",
             options={"maxfev": n_obj, "initial_simplex": x0 + np.vstack([np.zeros(x0.size), 0.3 * np.eye(x0.size)])})
    if best["x"] is None:
        return None, count
    b = onto_boundary(best["x"], check_dt_s, -0.3, 0.0, 10)  # feasible on the required check grid
    if b is None:
        return None, count
    shift, tr, r = b
    return _ruckig_result(tr, r, np.exp(best["x"] + shift), ratio, limits), count


def _independent_durations(q0, q1, vmax, amax, jmax, amin=None) -> np.ndarray:

    n = len(q0)
    traj = Trajectory(n)
    Ruckig(n).calculate(_ruckig_input(q0, q1, vmax, amax, jmax, amin), traj)
    return np.asarray(traj.independent_min_durations, float)
