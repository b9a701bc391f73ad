"""Exact designs from the optimal approximate design: efficient rounding, polished by exchanges.

The optimal approximate design (:func:`pipeline.calibration.design_bound.optimal_approximate_design`,
weights ``w`` on the candidates minimising ``V(w) = trace(W M(w)^-1)``) is the continuous optimum;
an exact design needs ``n`` whole configurations. **Efficient rounding** (Pukelsheim & Rieder 1992,
"Efficient rounding of approximate designs", *Biometrika* 79, 763-770; Pukelsheim, *Optimal Design
of Experiments*, Wiley 1993, §12.4-12.5) apportions ``n`` runs to the ``l`` support points:

1. ``n_i = ceil((n - l/2) w_i)`` (0 when ``n <= l/2``);
2. while ``sum n_i < n``: increase an ``n_j`` with the smallest ``n_j / w_j``;
   while ``sum n_i > n``: decrease an ``n_k`` with the largest ``(n_k - 1) / w_k``

(ties: the heavier point first). A calibration design measures distinct configurations, and the
support of the approximate design is usually larger than ``n`` (the candidates near one optimal
pose share its weight): the start is the points with ``n_i >= 1``, completed by the heaviest
remaining candidates when a point got several runs.

The start is then **polished** by remove-and-replace (:func:`pipeline.calibration.design.remove_and_replace`:
rank-one exchanges on the same criterion until no exchange improves it), and the best of the
polished start and ``restarts`` remove-and-replace runs from the selector's own random start is
kept. With the same random stream the first of those runs is exactly the plain remove-and-replace,
so the result is never worse than it, never worse than the rounded start, and never better than the
bound ``V*/n``. Only the trace criteria (``A``, ``tcp_A``, ``tcp_A_mixed``, ``V``) have a weighting
``W`` for the approximate design; other indices get plain remove-and-replace, and so does a trace
index whose multiplicative algorithm stops being monotone (the start is a heuristic; the random-start
runs stand on their own).

The result carries the rounded start's value and the approximate design's certified bound ``V*/n``
(``start_value``, ``bound_value`` of :class:`pipeline.calibration.design.SelectionResult`; the bound
at the start's equivalence-theorem gap :data:`START_TOL`, so ``index_value / bound_value`` overstates
the distance to the best exact design by at most that factor). On the default run's pool (20488 grid
candidates, 29 parameters, n = 50) the polished design is 1.018-1.020 times the bound (at a gap of
1e-3) on seeds 1-5, and an iterated local search (perturbations of 3-9 exchanges towards the support
of the approximate design, each polished) finds at most 0.2 % of V below it: the exchanges are at a
local optimum next to the exact optimum, and the rest is the bound's own gap (the approximate design
spreads its weight over 160-370 candidates, an exact design of 50 cannot).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from typing import cast

import numpy as np

from pipeline.calibration import design as ds
from pipeline.calibration import design_bound as db
from pipeline.calibration import indices as ix
from pipeline.calibration.design_state import is_regular
from pipeline.core.forks import fork_map

#: equivalence-theorem gap at which the approximate design is good enough as a start (the exchanges
#: do the rest; the bound itself is computed to 1e-4 by the benchmark)
START_TOL = 1e-2
#: iteration cap of the multiplicative algorithm for the start (160-310 iterations reach START_TOL on the
#: calib-design pools; one iteration costs about one accepted exchange of remove-and-replace, ~1 ms per
#: 1500 candidates)
START_MAX_ITERATIONS = 500
#: weights below this fraction of the largest are not support points
SUPPORT_THRESHOLD = 1e-3
#: candidate Jacobian entries (N m p) from which the two kinds of runs go to forked processes: below it
#: the whole selection takes under a second (measured, n = 50, p = 31: 93 k entries 0.6 s, 279 k 1.8 s
#: CPU) and forking the stage's process 0.1-0.3 s
SIDE_BY_SIDE_MIN_ENTRIES = 200_000


def efficient_rounding(weights: np.ndarray, n: int, threshold: float = SUPPORT_THRESHOLD) -> np.ndarray:
    """Multiplicities ``n_i`` (N,) summing to ``n`` on the support of ``weights`` (module docstring,
    Pukelsheim & Rieder 1992 §2)."""
    w = np.asarray(weights, float)
    if n < 1 or w.ndim != 1 or not np.all(np.isfinite(w)) or np.any(w < 0) or w.max() <= 0:
        raise ValueError("efficient rounding needs n >= 1 and non-negative weights with a positive one")
    sup = np.flatnonzero(w > threshold * w.max())
    ws = w[sup] / w[sup].sum()
    k = np.ceil(max(n - sup.size / 2.0, 0.0) * ws - 1e-12).astype(int)
    while k.sum() < n:
        k[np.lexsort((-ws, k / ws))[0]] += 1
    while k.sum() > n:
        r = np.where(k > 0, (k - 1) / ws, -np.inf)
        k[np.lexsort((ws, -r))[0]] -= 1
    out = np.zeros(w.size, int)
    out[sup] = k
    return out


def rounded_start(weights: np.ndarray, n: int) -> np.ndarray:
    """``n`` distinct candidates from the efficient rounding of ``weights``: the points with a run,
    heaviest first, completed by the heaviest remaining candidates."""
    w = np.asarray(weights, float)
    if n > w.size:
        raise ValueError(f"{n} configurations from {w.size} candidates")
    counts = efficient_rounding(w, n)
    order = np.argsort(-w, kind="stable")
    chosen = order[counts[order] > 0]
    rest = order[counts[order] == 0]
    return np.concatenate([chosen, rest])[:n]


def approximate_remove_and_replace(G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
                                   positions: np.ndarray | None = None, restarts: int = 1,
                                   n_initial: int | None = None,
                                   approximate: db.ApproximateDesign | None = None) -> ds.SelectionResult:
    """Remove-and-replace from the rounded optimal approximate design and from ``restarts`` random
    starts (module docstring); the best design on the criterion. ``restarts = 0``: the rounded start
    only. ``approximate``: the optimal approximate design of ``G`` and ``spec`` when already computed
    (it does not depend on ``n``).

    The random-start runs and the rounded start's run are independent (only the random starts
    draw from ``rng``): with two cores and at least :data:`SIDE_BY_SIDE_MIN_ENTRIES` Jacobian
    entries they run side by side in forked processes
    (:func:`pipeline.core.forks.fork_map`), ``rng`` taking the state the random starts left, so the
    result is the one of running them one after the other."""
    if restarts < 0:
        raise ValueError("restarts must be >= 0")
    t0 = time.perf_counter()
    G = np.asarray(G, float)

    def random_runs() -> list[ds.SelectionResult]:
        return [ds.remove_and_replace(G, spec, n, rng, n_initial=n_initial, positions=positions)
                for _ in range(restarts)]

    def rounded_run() -> ds.SelectionResult | None:
        return _rounded_start_run(G, spec, n, rng, positions, approximate)

    if spec.name in ix.TRACE_INDICES and restarts > 0 and G.size >= SIDE_BY_SIDE_MIN_ENTRIES:
        runs, rounded = _side_by_side(random_runs, rounded_run, rng)
    else:
        runs, rounded = random_runs(), (rounded_run() if spec.name in ix.TRACE_INDICES else None)
    if rounded is not None:
        runs.append(rounded)
    if not runs:
        runs.append(ds.remove_and_replace(G, spec, n, rng, n_initial=n_initial, positions=positions))
    best = min(runs, key=lambda r: r.index_value if spec.minimised else -r.index_value)
    if not math.isfinite(best.index_value):
        return best
    return ds.SelectionResult("remove_and_replace", spec.name, best.selected, best.index_value,
                              time.perf_counter() - t0, sum(r.evaluations for r in runs), best.history,
                              start_value=None if rounded is None else rounded.start_value,
                              bound_value=None if rounded is None else rounded.bound_value)


def _rounded_start_run(G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
                       positions: np.ndarray | None, approximate: db.ApproximateDesign | None
                       ) -> ds.SelectionResult | None:
    """Remove-and-replace from the efficient rounding of the optimal approximate design (a trace
    index), with the rounded start's value and the certified bound ``V*/n`` of the approximate
    design (``start_value``, ``bound_value``); None when the pool is singular, the multiplicative
    algorithm lost monotonicity or the rounded start is singular. Draws nothing from ``rng``."""
    W = spec.weight_matrix(G.shape[2])
    try:
        opt = approximate or db.optimal_approximate_design(G, W, tol=START_TOL, max_iterations=START_MAX_ITERATIONS)
        start = rounded_start(opt.weights, n)
    except (ValueError, RuntimeError):  # a singular pool (the random starts say why), or the
        return None                     # multiplicative algorithm lost monotonicity: no second start
    if not is_regular(db.exact_information(G, start)):
        return None
    polished = ds.remove_and_replace(G, spec, n, rng, positions=positions, initial=start)
    return dataclasses.replace(polished, start_value=db.design_value(G, W, start), bound_value=opt.exact_bound(n))


def _side_by_side(random_runs: Callable[[], list[ds.SelectionResult]],
                  rounded_run: Callable[[], ds.SelectionResult | None], rng: np.random.Generator
                  ) -> tuple[list[ds.SelectionResult], ds.SelectionResult | None]:
    """``(random_runs(), rounded_run())`` computed on up to two forked processes; ``rng`` ends in
    the state ``random_runs`` leaves. A part that raised is run again here, so its error is raised
    as it would be without the fork (errors with several fields do not survive pickling)."""
    def task(k: int) -> tuple[bool, object]:
        try:
            return True, ((random_runs(), rng.bit_generator.state) if k == 0 else rounded_run())
        except Exception:       # noqa: BLE001 - repeated in the caller, which raises it properly
            return False, None
    state = rng.bit_generator.state
    (ok_random, random_part), (ok_rounded, rounded_part) = fork_map(task, 2)
    if ok_random:
        runs, rng.bit_generator.state = cast(tuple[list[ds.SelectionResult], dict], random_part)
    else:
        rng.bit_generator.state = state     # one core: the failed part ran here and drew from rng
        runs = random_runs()
    rounded = cast(ds.SelectionResult | None, rounded_part) if ok_rounded else rounded_run()
    return runs, rounded
