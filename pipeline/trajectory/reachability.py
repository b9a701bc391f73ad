"""Time-optimal CP by reachability analysis with the full friction model (no NLP).

Method: TOPP-RA (Pham & Pham 2018, "A new approach to time-optimal path parameterization based
on reachability analysis", IEEE T-RO 34(3), sections III-IV): a backward pass computes the
*controllable* sets ``K_k = [0, kmax_k]`` of ``b = sdot^2`` (from which the rest at ``s = 1`` can
still be reached), a forward pass takes at every stage the largest ``b_{k+1}`` reachable from
``b_k`` inside ``K_{k+1}``; for stage-wise constraints linear in ``(b_k, b_{k+1})`` this greedy
profile is the time-optimal one of the discretised problem (ibid., section IV).

Discretisation: the same as the NLP reference (:mod:`pipeline.trajectory.cp`, Verscheure 2009):
``a_k = (b_{k+1} - b_k) / (2 ds)`` constant per interval, torques

    tau = m(s) a + c(s) b + g(s) + F_v q'(s) sqrt(b) + F_c tanh(q'(s) sqrt(b) / w)

checked at the start, midpoint (``b = (b_k + b_{k+1}) / 2``) and end of every interval, joint
speeds ``|q' sqrt(b)| <= v_max`` there, and joint accelerations ``|q' a + q'' b| <= a_max``.

The friction terms are the only non-linear ones (``sqrt(b)`` and ``tanh``). They are handled
by *linearise and correct* (a fixed-point iteration): the friction at every check point is
frozen at the speeds of the previous profile, which makes every stage's constraints linear in
``(b_k, b_{k+1})``; one exact TOPP-RA solve gives a new profile; the friction is re-evaluated
at its speeds; repeat until the profile moves by less than ``tol`` (relative, in ``sdot``). At
the fixed point the torques at the check points are exactly those of the full model at the
profile's own speeds. Friction changes slowly with ``b`` compared with the ``m a`` term
(``a`` carries a factor ``1 / (2 ds)``), so the map is a strong contraction: 2-6 rounds to
``tol = 1e-4`` (the duration then agrees with the converged one to ~1e-6 relative on the
RX130L, TX40, UR5 and Panda paths of ``benchmarks/bench_cp.py``).

Per stage both passes are closed-form (no LP solver): with frozen friction each row
``-1 <= cb b + cy y + h <= 1`` bounds ``b`` (given ``y = b_{k+1}``) by a line in ``y``, so the
largest controllable ``b`` is the maximum of the concave piecewise-linear ``H_k(y) = min_r
(p_r + s_r y)`` over ``0 <= y <= kmax_{k+1}``, i.e. ``H_k(min(kmax_{k+1}, y*_k))`` with the
unconstrained maximiser ``y*_k`` found for all stages at once (vectorised safeguarded Newton on
the crossing of the active rising and falling lines, exact on a piecewise-linear ``H``, warm-started
from the previous round's maximiser: :func:`_argmax_concave`); the forward step is the minimum
of the rows' upper bounds on ``y``.
Lower bounds (rows that would demand a minimum speed) are not propagated; the caller's
fine-grid re-check catches such (rare) cases. The two sequential passes run as CasADi folds
(``mapaccum``, one per row count and grid size, cached), so a round costs about a millisecond at
N = 400 and the whole solve is linear in N; ``benchmarks/bench_cp.py`` measures it against
toppra and against the NLP reference (same durations to ~1e-5 relative).
"""

from __future__ import annotations

import time
from functools import lru_cache

import casadi as ca
import numpy as np

from pipeline.core.errors import InfeasibleError, SolverError
from pipeline.trajectory.cp import CPProfile
from pipeline.trajectory.design import JointPath
from pipeline.trajectory.dynamics import PlanningModel, path_coefficients

_BIG = 1e30


def _rows(pm: PlanningModel, path: JointPath, s: np.ndarray, tau_max: np.ndarray,
          acceleration: bool, acceleration_scale: np.ndarray | None = None) -> dict:
    """Stage rows normalised by their limits, for points start / mid / end of every interval;
    ``acceleration_scale`` (nq,) or (N, nq) shrinks the acceleration limits as ``tau_max`` does the
    torque limits (per interval: the intervals whose fine samples exceed).

    Returns per point P (0 start, 1 mid, 2 end) arrays of shape (N, R): ``A`` (coefficient of
    ``a``), ``C`` (of ``b_P``), ``G`` (constant), ``FV``, ``FC`` (friction coefficients on
    ``q' x`` and ``tanh(q' x / w)``), ``D`` (``q'``) and the speed bound ``vb`` of ``b_P`` (N,).
    """
    N = len(s) - 1
    pts = np.concatenate([s, 0.5 * (s[:-1] + s[1:])])
    q, dq, ddq = path.derivatives(pts)
    pc = path_coefficients(pm, pts, q, dq, ddq)
    with np.errstate(divide="ignore"):
        vb = np.min((pm.velocity_rad_s / np.abs(dq)) ** 2, axis=1)
    vb = np.minimum(vb, _BIG)
    zero = np.zeros_like(dq)
    # per-interval limits (N, nq): interval k's start, midpoint and end rows divide by row k
    tau_int = np.broadcast_to(np.asarray(tau_max, float), (N, pm.nq))
    tau_pts = {0: tau_int, 1: tau_int, 2: tau_int}
    A, C, G = pc.m, pc.c, pc.g
    FV = np.tile(pm.viscous_Nms_rad, (len(pts), 1))
    FC = np.tile(pm.coulomb_Nm, (len(pts), 1))
    D = dq
    if acceleration:
        amax = np.asarray(pm.acceleration_rad_s2, float)
        A = np.hstack([A, dq / amax])
        C = np.hstack([C, ddq / amax])
        G = np.hstack([G, zero])
        FV = np.hstack([FV, zero])
        FC = np.hstack([FC, zero])
        D = np.hstack([D, dq])
    idx = {0: np.arange(N), 1: N + 1 + np.arange(N), 2: np.arange(1, N + 1)}
    out = {}
    for P, i in idx.items():
        scale = np.ones((N, A.shape[1]))
        scale[:, :pm.nq] = tau_pts[P]
        if acceleration and acceleration_scale is not None:
            scale[:, pm.nq:] = np.broadcast_to(np.asarray(acceleration_scale, float), (N, pm.nq))
        out[P] = {"A": A[i] / scale, "C": C[i] / scale, "G": G[i] / scale, "FV": FV[i] / scale,
                  "FC": FC[i] / scale, "D": D[i], "vb": vb[i], "nq": pm.nq}
    return out


_W = {0: (1.0, 0.0), 1: (0.5, 0.5), 2: (0.0, 1.0)}   # b_P = w0 b_k + w1 b_{k+1}


def _friction(row: dict, x: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Normalised friction of the torque rows (the first ``nq`` columns; acceleration rows have none)."""
    nq = row["nq"]
    v = row["D"][:, :nq] * x[:, None]
    return row["FV"][:, :nq] * v + row["FC"][:, :nq] * np.tanh(v / width)


class _StageLines:
    """Per stage the lines bounding b (``b <= p + s y``) and y (``y <= u + t b``), (N, R').

    Row ``-1 <= cb b + cy y + h <= 1`` with ``h = G + friction``: only ``h`` changes between the
    friction rounds, so the slopes, the reciprocals and the speed-limit lines are computed once and
    a round costs two multiply-adds (:meth:`lines`)."""

    def __init__(self, rows: dict, ds: float) -> None:
        inv_b, sgn_b, inv_y, sgn_y, sl, t = [], [], [], [], [], []
        for P, row in rows.items():
            w0, w1 = _W[P]
            cb = -row["A"] / (2 * ds) + row["C"] * w0
            cy = row["A"] / (2 * ds) + row["C"] * w1
            okb, oky = np.abs(cb) > 1e-12, np.abs(cy) > 1e-12
            ib = np.where(okb, 1.0 / np.where(okb, cb, 1.0), 0.0)
            iy = np.where(oky, 1.0 / np.where(oky, cy, 1.0), 0.0)
            inv_b.append(ib)
            inv_y.append(iy)
            # a row without b (or y) bounds nothing: its line sits at _BIG
            sgn_b.append(np.where(okb, np.sign(cb) * ib, _BIG))
            sgn_y.append(np.where(oky, np.sign(cy) * iy, _BIG))
            sl.append(-cy * ib)
            t.append(-cb * iy)
        N = rows[0]["A"].shape[0]
        # speed limits: b <= vb_start, (b + y)/2 <= vb_mid, y <= vb_end
        self.p_speed = np.hstack([rows[0]["vb"][:, None], 2 * rows[1]["vb"][:, None]])
        self.u_speed = np.hstack([rows[2]["vb"][:, None], 2 * rows[1]["vb"][:, None]])
        self.inv_b, self.sgn_b = np.hstack(inv_b), np.hstack(sgn_b)
        self.inv_y, self.sgn_y = np.hstack(inv_y), np.hstack(sgn_y)
        self.sl = np.hstack([*sl, np.zeros((N, 1)), -np.ones((N, 1))])
        self.t = np.hstack([*t, np.zeros((N, 1)), -np.ones((N, 1))])

    def lines(self, rows: dict, fr: dict) -> tuple[np.ndarray, ...]:
        h = np.hstack([rows[P]["G"] for P in rows])
        width = rows[0]["G"].shape[1]
        for P in rows:
            h[:, P * width: P * width + rows[P]["nq"]] += fr[P]
        p = np.hstack([self.sgn_b - h * self.inv_b, self.p_speed])
        u = np.hstack([self.sgn_y - h * self.inv_y, self.u_speed])
        return p, self.sl, u, self.t


def _argmax_concave(p: np.ndarray, sl: np.ndarray, hi: np.ndarray, start: np.ndarray | None = None,
                    iters: int = 60, tol: float = 1e-12) -> np.ndarray:
    """Maximiser in [0, hi] of H(y) = min_r (p_r + s_r y) for every stage.

    H is concave and piecewise linear: its maximiser is where the lowest rising line
    (``U(y) = min_{s_r > 0} (p_r + s_r y)``) meets the lowest falling one (``D``, ``s_r <= 0``),
    or an end of [0, hi] (H rising at ``hi``: ``hi``; falling at 0: 0). Inside, a safeguarded
    Newton step: a bracket ``[lo, hi]`` with ``U < D`` (H rising) at ``lo`` and ``U >= D`` at
    ``hi``; the next trial point is the crossing of the two lines active at the current one when
    that lies inside the bracket, else the midpoint. On a piecewise-linear function the crossing
    is exact once the active pair is the final one, so a warm ``start`` (the previous friction
    round's maximiser) ends in 1-3 steps and a cold one in a few more, instead of the ~30
    halvings of plain bisection."""
    n = p.shape[0]
    rows = np.arange(n)
    rising = sl > 0
    p_up, p_dn = np.where(rising, p, np.inf), np.where(rising, np.inf, p)

    def at(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """H rising at y, and the crossing of the active rising and falling lines there."""
        i = np.argmin(p_up + sl * y[:, None], axis=1)
        j = np.argmin(p_dn + sl * y[:, None], axis=1)
        pu, su, pd, sd = p_up[rows, i], sl[rows, i], p_dn[rows, j], sl[rows, j]
        with np.errstate(divide="ignore", invalid="ignore"):
            return (pu + su * y) < (pd + sd * y), (pd - pu) / (su - sd)

    hi = hi.astype(float).copy()
    lo = np.zeros(n)
    at_hi, _ = at(hi)
    at_lo, cross = at(lo)
    y = np.where(at_hi, hi, 0.0)
    done = at_hi | ~at_lo                                 # maximiser at an end
    if start is not None:
        trial = np.clip(start, lo, hi)
        left, c_start = at(trial)
        lo, hi = np.where(left & ~done, trial, lo), np.where(~left & ~done, trial, hi)
        cross = c_start
        y = np.where(done, y, trial)
        done |= np.abs(cross - trial) <= tol * np.maximum(hi, 1.0)
    for _ in range(iters):
        if done.all():
            break
        inside = np.isfinite(cross) & (cross > lo) & (cross < hi)
        y_new = np.where(done, y, np.where(inside, cross, 0.5 * (lo + hi)))
        left, cross = at(y_new)
        lo, hi = np.where(left & ~done, y_new, lo), np.where(~left & ~done, y_new, hi)
        # converged: the active pair crosses at the trial point (exact), or the bracket is closed
        scale = tol * np.maximum(hi, 1.0)
        done |= (np.abs(cross - y_new) <= scale) | (hi - lo <= scale)
        y = y_new
    return y


@lru_cache(maxsize=16)
def _passes(n_rows: int, n_stages: int) -> ca.Function:
    """Both recursions as ONE CasADi fold (``mapaccum``: one C loop over stages; building a fold
    costs more than a round, so the two passes share it) of the stage step

        x' = max(0, min(c, min_r (a_r + e_r min(x, d))))

    backward (stages reversed):  kmax_k = max(0, min_r (p_r + s_r min(kmax_{k+1}, y*_k)))
        (a, e, c, d) = (p, s, inf, y*_k);
    forward:  b_{k+1} = max(0, min(kmax_{k+1}, min_r (u_r + t_r b_k)))
        (a, e, c, d) = (u, t, kmax_{k+1}, inf).
    """
    x = ca.SX.sym("x")
    a, e = ca.SX.sym("a", n_rows), ca.SX.sym("e", n_rows)
    c, d = ca.SX.sym("c"), ca.SX.sym("d")
    step = ca.Function("cp_stage", [x, ca.vertcat(a, e, c, d)],
                       [ca.fmax(0.0, ca.fmin(c, ca.mmin(a + e * ca.fmin(x, d))))])
    return step.mapaccum("cp_pass", n_stages)


def _topp_ra(p: np.ndarray, sl: np.ndarray, u: np.ndarray, t: np.ndarray,
             y_star: np.ndarray) -> np.ndarray:
    """Exact TOPP-RA for frozen-friction (linear) stage constraints: b at the N+1 grid points."""
    N, R = p.shape
    fold = _passes(R, N)
    inf = np.full((N, 1), np.inf)
    K = np.zeros(N + 1)                      # rest at s = 1
    K[:-1] = _call(fold, np.hstack([p, sl, inf, y_star[:, None]])[::-1], N)[::-1]
    b = np.zeros(N + 1)                      # rest at s = 0
    b[1:] = _call(fold, np.hstack([u, t, K[1:, None], inf]), N)
    return b


def _call(fold: ca.Function, stages: np.ndarray, n: int) -> np.ndarray:
    """Evaluate a fold from rest (x0 = 0) on per-stage rows ``stages`` (n, m), through CasADi's
    buffer interface (numpy memory passed as is: converting 3e4 numbers to a DM costs ~8 ms)."""
    buf, evaluate = fold.buffer()
    x0 = np.zeros(1)
    data = np.ascontiguousarray(stages).ravel()          # row k = stage k: column-major (m, n)
    out = np.zeros(n)
    buf.set_arg(0, memoryview(x0))
    buf.set_arg(1, memoryview(data))
    buf.set_res(0, memoryview(out))
    evaluate()
    return out


def solve_cp_reachability(pm: PlanningModel, path: JointPath, n_grid: int = 400, name: str = "cp",
                          torque_margin: float = 0.0, torque_scale: np.ndarray | None = None,
                          acceleration_limits: bool = True, tol: float = 1e-4,
                          max_rounds: int = 30, warm: CPProfile | None = None,
                          acceleration_scale: np.ndarray | None = None) -> CPProfile:
    """Time-optimal profile with viscous + smooth Coulomb friction (module docstring).

    ``torque_margin`` / ``torque_scale`` tighten the torque limits as in
    :func:`pipeline.trajectory.cp.solve_cp_refined`: per joint (nq,) or per grid interval and
    joint (N, nq), the latter to tighten only where a fine-grid check found an excess;
    ``acceleration_scale`` likewise the acceleration limits. ``warm``:
    a profile on the same grid whose speeds start the friction iteration (fewer rounds). Raises
    InfeasibleError when the path cannot be held at rest within the torque limits, SolverError when
    the friction iteration does not settle within ``max_rounds``.
    """
    t0 = time.perf_counter()
    N = int(n_grid)
    s = np.linspace(0.0, 1.0, N + 1)
    ds = float(s[1] - s[0])
    tau_max = pm.effort_Nm * (1.0 - torque_margin)
    if torque_scale is not None:
        tau_max = tau_max * np.asarray(torque_scale, float)
    rows = _rows(pm, path, s, tau_max, acceleration_limits, acceleration_scale)
    nq = pm.nq
    limits = np.broadcast_to(tau_max, (N, nq))
    for P in (0, 2):
        hold = np.abs(rows[P]["G"][:, :nq])
        if (hold > 1.0).any():
            k, j = np.argwhere(hold > 1.0)[0]
            sk = s[k] if P == 0 else s[k + 1]
            raise InfeasibleError(None, f"{path.name} at s = {sk:.3f} joint {j + 1} torque limit",
                                  f"holding torque {hold[k, j] * limits[k, j]:.1f} N·m exceeds the limit "
                                  f"{limits[k, j]:.1f} N·m even at crawling speed")
    width = pm.coulomb_smoothing_rad_s
    # round 0: Coulomb friction saturated in the direction of motion (toppra's model), no viscous
    fr = {P: row["FC"][:, :nq] * np.sign(np.where(np.abs(row["D"][:, :nq]) < 1e-9, 0.0, row["D"][:, :nq]))
          for P, row in rows.items()}
    if warm is not None and len(warm.sdot) == N + 1:
        xw = warm.sdot
        xwm = np.sqrt(0.5 * (xw[:-1] ** 2 + xw[1:] ** 2))
        fr = {0: _friction(rows[0], xw[:-1], width), 1: _friction(rows[1], xwm, width),
              2: _friction(rows[2], xw[1:], width)}
    x_prev = None
    rounds = 0
    stage = _StageLines(rows, ds)
    y_star = None
    for _ in range(max_rounds):
        rounds += 1
        p, sl, u, t = stage.lines(rows, fr)
        y_star = _argmax_concave(p, sl, np.minimum(rows[2]["vb"], _BIG), y_star)
        b = _topp_ra(p, sl, u, t, y_star)
        x = np.sqrt(b)
        xm = np.sqrt(0.5 * (b[:-1] + b[1:]))
        fr = {0: _friction(rows[0], x[:-1], width), 1: _friction(rows[1], xm, width),
              2: _friction(rows[2], x[1:], width)}
        if x_prev is not None and np.max(np.abs(x - x_prev)) <= tol * max(np.max(x), 1e-12):
            break
        x_prev = x
    else:
        raise SolverError(None, f"{name} (reachability CP, N={N})",
                          f"the friction iteration did not settle in {max_rounds} rounds")
    if not np.all(x[1:-1] > 0):
        raise InfeasibleError(None, f"{name} (reachability CP, N={N})",
                              "no admissible speed on part of the path (a limit cannot be met)")
    sdd = np.diff(b) / (2 * ds)
    dur = float(np.sum(2 * ds / np.maximum(x[:-1] + x[1:], 1e-300)))
    return CPProfile(name, s, x, sdd, dur, time.perf_counter() - t0,
                     info={"method": "reachability", "friction_rounds": rounds, "midpoints": True,
                           "friction": "viscous+tanh coulomb", "n_grid": N, "torque_margin": torque_margin,
                           "acceleration_limits": acceleration_limits,
                           "torque_scale": None if torque_scale is None else np.asarray(torque_scale).tolist(),
                           "acceleration_scale": (None if acceleration_scale is None
                                                  else np.asarray(acceleration_scale).tolist())})
