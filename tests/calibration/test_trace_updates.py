"""Low-rank candidate updates (add / remove / exchange) against brute-force evaluation of the index."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration import design as ds
from pipeline.calibration import indices as ix
from pipeline.calibration.design_state import DesignState

UPDATE_NAMES = ["A", "A_weighted", "tcp_A", "tcp_A_mixed", "V", "D", "O1"]


def _problem(N: int = 150, m: int = 3, p: int = 8, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(N, m, p)) * rng.uniform(0.2, 3.0, size=p)
    return G, rng.normal(size=(3 * 20, p))        # candidate blocks, TCP rows of 20 working poses


def _spec(name: str, Jw: np.ndarray) -> ix.IndexSpec:
    if name == "A_weighted":
        return ix.IndexSpec("A", parameter_weights=(np.arange(Jw.shape[1]) % 3 > 0).astype(float))
    return ix.IndexSpec(name, working_jacobian=Jw, n_working=20)


class BruteForceState(DesignState):
    """Every candidate design's index evaluated from its information matrix (no update cache)."""

    def update_cache(self) -> None:
        return None


def _brute(spec: ix.IndexSpec, M: np.ndarray, n: int) -> float:
    return ix.score(spec, M, n)


@pytest.mark.parametrize("m", [1, 2, 3, 4])
@pytest.mark.parametrize("name", UPDATE_NAMES)
def test_updated_scores_equal_direct_evaluation(name, m):
    G, Jw = _problem(N=60, m=m, p=7, seed=m)
    spec = _spec(name, Jw)
    sel = np.arange(10)
    st = DesignState(G, spec, None, sel)
    cache = st.update_cache()
    assert cache is not None
    cand = np.arange(10, 60)
    add = st._cache_scores(cache.add_values()[cand], 11)
    assert np.allclose(add, [_brute(spec, st.M + G[j].T @ G[j], 11) for j in cand], rtol=1e-9, atol=0)
    rm = st.remove_scores()
    assert np.allclose(rm, [_brute(spec, st.M - G[k].T @ G[k], 9) for k in sel], rtol=1e-9, atol=0)
    for k in (0, 7):
        ex = st._cache_scores(cache.exchange_values(k)[cand], 10)
        direct = [_brute(spec, st.M - G[k].T @ G[k] + G[j].T @ G[j], 10) for j in cand]
        assert np.allclose(ex, direct, rtol=1e-9, atol=0)


@pytest.mark.parametrize("name", ["A", "V", "D"])
def test_searches_pick_the_brute_force_candidate(name):
    G, Jw = _problem(seed=1)
    spec = _spec(name, Jw)
    fast = DesignState(G, spec, None, np.arange(12))
    slow = BruteForceState(G, spec, None, np.arange(12))
    j, s = fast.best_add()
    j_b, s_b = slow.best_add()
    assert j == j_b and s == pytest.approx(s_b, rel=1e-9)
    assert np.allclose(fast.remove_scores(), slow.remove_scores(), rtol=1e-9, atol=0)
    for k in range(12):
        M, selected = fast.M.copy(), list(fast.selected)
        j, s = fast.best_exchange(k)
        j_b, s_b = slow.best_exchange(k)
        assert j == j_b and s == pytest.approx(s_b, rel=1e-9)
        assert fast.selected == selected and np.array_equal(fast.M, M)   # the state is unchanged


def test_exchange_that_would_make_the_design_singular_falls_back():
    G, Jw = _problem(seed=2)
    G[:, :, -1] = 0.0
    G[0, 0, -1] = G[1, 1, -1] = 1.0         # only candidates 0 and 1 excite the last parameter
    spec = _spec("V", Jw)
    st = DesignState(G, spec, None, np.r_[0, 2:13])   # 0 selected, 1 not
    assert st.update_cache() is not None and st.update_cache().exchange_values(0) is None
    j, s = st.best_exchange(0)
    assert j == 1 and np.isfinite(s)
    assert s == pytest.approx(_brute(spec, st.M - G[0].T @ G[0] + G[1].T @ G[1], 12), rel=1e-9)
    assert st.remove_scores()[0] == -np.inf             # removing 0 alone: singular, worst score


@pytest.mark.parametrize("name", ["A", "V", "D"])
def test_remove_and_replace_selects_the_brute_force_design(name, monkeypatch):
    G, Jw = _problem(seed=3)
    spec = _spec(name, Jw)
    fast = ds.remove_and_replace(G, spec, 14, np.random.default_rng(4), n_initial=10)
    monkeypatch.setattr(ds, "DesignState", BruteForceState)
    slow = ds.remove_and_replace(G, spec, 14, np.random.default_rng(4), n_initial=10)
    assert len(fast.history) > 3                     # the search did exchange configurations
    assert sorted(fast.selected.tolist()) == sorted(slow.selected.tolist())
    assert fast.index_value == pytest.approx(slow.index_value, rel=1e-9)
    assert [h[0] for h in fast.history] == [h[0] for h in slow.history]
