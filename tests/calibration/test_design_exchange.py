"""The stage's selector on the trace criterion V: a local optimum of single exchanges over the whole
pool, close to the exact optimum of a pool small enough to enumerate, and bracketed by its start
and its certified bound."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.calibration import design_bound as db
from pipeline.calibration import design_rounding as dr
from pipeline.calibration import indices as ix


def _pool(seed: int, N: int, m: int = 3, p: int = 6) -> tuple[np.ndarray, ix.IndexSpec, np.ndarray]:
    """Whitened blocks of unequal strength and a singular working weighting (the TCP's kind)."""
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((N, m, p)) * rng.uniform(0.2, 2.0, size=(N, 1, 1))
    spec = ix.IndexSpec("V", working_jacobian=rng.standard_normal((4, p)), n_working=1)
    return G, spec, spec.weight_matrix(p)


def _brute_force_optimum(G: np.ndarray, W: np.ndarray, n: int) -> float:
    return min(db.design_value(G, W, np.array(S)) for S in itertools.combinations(range(len(G)), n))


@pytest.mark.parametrize("seed", range(4))
def test_selection_is_within_half_a_percent_of_the_exact_optimum_of_a_tiny_pool(seed):
    G, spec, W = _pool(seed, N=16)
    n = 4
    best = _brute_force_optimum(G, W, n)          # 1820 designs
    r = dr.approximate_remove_and_replace(G, spec, n, np.random.default_rng(seed))
    assert len(set(r.selected.tolist())) == n
    assert r.index_value >= best * (1 - 1e-9)
    assert r.index_value <= best * 1.005


@pytest.mark.parametrize("seed", range(3))
def test_no_single_exchange_improves_the_selection(seed):
    G, spec, W = _pool(seed, N=80)
    n = 8
    r = dr.approximate_remove_and_replace(G, spec, n, np.random.default_rng(seed))
    S = [int(i) for i in r.selected]
    v = db.design_value(G, W, np.array(S))
    swaps = [db.design_value(G, W, np.array([x for x in S if x != k] + [j]))
             for k in S for j in range(len(G)) if j not in S]
    # remove-and-replace stops when no exchange improves V by more than its rel_tol (1e-6)
    assert min(swaps) >= v * (1 - 1e-6)


@pytest.mark.parametrize("seed", range(3))
def test_start_and_bound_bracket_the_selection(seed):
    G, spec, W = _pool(seed, N=16)
    n = 5
    r = dr.approximate_remove_and_replace(G, spec, n, np.random.default_rng(seed))
    opt = db.optimal_approximate_design(G, W, tol=dr.START_TOL, max_iterations=dr.START_MAX_ITERATIONS)
    assert r.start_value == pytest.approx(db.design_value(G, W, dr.rounded_start(opt.weights, n)), rel=1e-10)
    assert r.bound_value == pytest.approx(opt.exact_bound(n), rel=1e-10)
    best = _brute_force_optimum(G, W, n)
    assert r.bound_value <= best * (1 + 1e-9)
    assert best <= r.index_value * (1 + 1e-9)
    assert r.index_value <= r.start_value * (1 + 1e-9)


def test_a_non_trace_index_reports_no_bound():
    G, _, _ = _pool(0, N=40)
    r = dr.approximate_remove_and_replace(G, ix.IndexSpec("D"), 6, np.random.default_rng(0))
    assert r.start_value is None and r.bound_value is None
