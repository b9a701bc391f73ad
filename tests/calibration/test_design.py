"""Selection algorithms and indices on synthetic Jacobians (no robot needed)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.calibration import design as ds
from pipeline.calibration import indices as ix
from pipeline.calibration.design_state import DesignState, above
from pipeline.core.errors import InfeasibleError


def _cands(N=300, m=3, p=12, seed=0):
    rng = np.random.default_rng(seed)
    scale = rng.uniform(0.2, 3.0, size=p)
    return rng.normal(size=(N, m, p)) * scale, rng.normal(size=(N, 3))


def test_indices_match_svd_of_stacked_jacobian():
    G, P = _cands(40)
    J = G.reshape(-1, G.shape[2])
    s = np.linalg.svd(J, compute_uv=False)
    M = J.T @ J
    n = G.shape[0]
    assert ix.evaluate(ix.IndexSpec("O1"), M, n) == pytest.approx(np.prod(s) ** (1 / s.size) / np.sqrt(n))
    assert ix.evaluate(ix.IndexSpec("O2"), M, n) == pytest.approx(s[-1] / s[0])
    assert ix.evaluate(ix.IndexSpec("O3"), M, n) == pytest.approx(s[-1])
    assert ix.evaluate(ix.IndexSpec("O4"), M, n) == pytest.approx(s[-1] ** 2 / s[0])
    assert ix.evaluate(ix.IndexSpec("O5"), M, n) == pytest.approx(1 / np.sum(1 / s))
    assert ix.evaluate(ix.IndexSpec("A"), M, n) == pytest.approx(np.trace(np.linalg.inv(M)))
    Jw = np.random.default_rng(3).normal(size=(6, G.shape[2]))
    v = ix.evaluate(ix.IndexSpec("tcp_A", working_jacobian=Jw, n_working=2), M, n)
    assert v == pytest.approx(np.trace(Jw @ np.linalg.inv(M) @ Jw.T) / 2)
    oc = ix.evaluate(ix.IndexSpec("Oc"), M, n, P[:n])
    assert 0 < oc < 1
    # a singular design scores worst
    assert ix.evaluate(ix.IndexSpec("O3"), M[:, :1] @ M[:1, :], n) == 0.0


@pytest.mark.parametrize("name", ["A", "tcp_A", "tcp_A_mixed", "D", "O1", "O3", "E", "O2", "Oc"])
def test_fast_best_add_equals_brute_force(name):
    G, P = _cands(400)
    Jw = np.random.default_rng(5).normal(size=(3, G.shape[2]))
    spec = ix.IndexSpec(name, working_jacobian=Jw)
    st = DesignState(G, spec, P, np.arange(8))
    j, s = st.best_add()
    brute = [ix.score(spec, st.M + G[c].T @ G[c], st.n + 1, np.vstack([P[:8], P[c]])) for c in range(8, 400)]
    assert j == 8 + int(np.argmax(brute))
    assert s == pytest.approx(max(brute), rel=1e-8)


@pytest.mark.parametrize("method", ["remove_and_replace", "detmax", "bsaa"])
def test_algorithms_beat_random(method):
    G, P = _cands(250)
    spec = ix.IndexSpec("O3")
    rnd = [ds.random_design(G, spec, 10, np.random.default_rng(s)).index_value for s in range(20)]
    kw = {"t_initial": 1.0, "t_final": 1e-4} if method == "bsaa" else {}
    res = ds.select(method, G, spec, 10, np.random.default_rng(1), **kw)
    assert len(res.selected) == 10 and len(set(res.selected.tolist())) == 10
    assert res.index_value > max(rnd)
    assert res.evaluations > 0 and res.run_time_s >= 0
    # the reported value is the value of the returned set
    Gs = G[res.selected]
    assert res.index_value == pytest.approx(ix.evaluate(spec, np.einsum("kmi,kmj->ij", Gs, Gs), 10))


def test_remove_and_replace_is_locally_optimal():
    G, _ = _cands(120, p=8)
    spec = ix.IndexSpec("D")
    res = ds.remove_and_replace(G, spec, 8, np.random.default_rng(2), n_initial=6, rel_tol=1e-12)
    S = list(res.selected)
    assert len(S) == 8
    base = res.index_value
    for k in S:
        for j in range(120):
            if j in S:
                continue
            T = [x for x in S if x != k] + [j]
            Gs = G[T]
            assert ix.evaluate(spec, np.einsum("kmi,kmj->ij", Gs, Gs), 8) <= base * (1 + 1e-9)


def test_singular_candidate_set_raises():
    G, _ = _cands(100, p=6)
    G[:, :, 5] = 0.0  # one parameter never excited
    with pytest.raises(InfeasibleError, match="regular"):
        ds.remove_and_replace(G, ix.IndexSpec("O3"), 10, np.random.default_rng(0))
    with pytest.raises(InfeasibleError):
        ds.bsaa(G, ix.IndexSpec("O3"), 1, np.random.default_rng(0))


def test_weighted_a_criterion_fast_path_matches_brute_force():
    G, P = _cands(300)
    w = (np.arange(G.shape[2]) % 2).astype(float)
    spec = ix.IndexSpec("A", parameter_weights=w)
    st = DesignState(G, spec, P, np.arange(8))
    j, s = st.best_add()
    brute = [ix.score(spec, st.M + G[c].T @ G[c], 9) for c in range(8, 300)]
    assert j == 8 + int(np.argmax(brute)) and s == pytest.approx(max(brute), rel=1e-8)
    M = st.M
    assert ix.evaluate(spec, M, 8) == pytest.approx(np.sum(w * np.diag(np.linalg.inv(M))))


def test_cholesky_screen_keeps_every_matrix_above_the_level():
    rng = np.random.default_rng(4)
    B = rng.normal(size=(400, 12, 30)) * rng.uniform(0.1, 10.0, size=(400, 1, 1))
    A = B @ B.transpose(0, 2, 1)
    lam = np.linalg.eigvalsh(A)[:, 0]
    for level in np.quantile(lam, [0.1, 0.5, 0.9]):
        keep = above(A, float(level))
        assert np.all(keep[lam > level])                    # never drops a matrix above the level
        clearly_below = lam < level - 1e-8 * np.trace(A, axis1=1, axis2=2)
        assert clearly_below.any() and not np.any(keep[clearly_below])
    assert above(A, -np.inf).all()
    # a matrix just above the level, by much less than the margin, is kept
    edge = np.diag([1.0, 2.0, 3.0])[None]
    assert above(edge, 1.0 - 1e-15)[0]
