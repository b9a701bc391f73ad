"""Information matrix of a design under construction and exact searches over all candidates.

The selection algorithms (:mod:`pipeline.calibration.design`) work on whitened per-configuration
Jacobian blocks ``G`` (N, m, p) and any :class:`~pipeline.calibration.indices.IndexSpec`; the
information matrix of a selection S is ``M_S = sum_{k in S} G_k^T G_k`` and is *updated* when a
configuration enters or leaves (paper 004 eqs. 15-17: ``Lambda_{i+1} = Lambda_i ± G_k^T G_k``),
never recomputed from the stacked Jacobian (except a periodic refresh against round-off).

Candidate searches (exhaustive, exact: the same choice as evaluating the index of every candidate
design, up to ties and round-off):

- A, tcp_A, tcp_A_mixed, V (``trace(W M^-1)``), D and O1 (``log det M``): Sherman-Morrison-Woodbury
  and determinant-lemma updates of every candidate at once for adding, removing and exchanging
  (remove one, add one) configurations (:mod:`pipeline.calibration.trace_updates`; O(N m p^2) per
  accepted change, O(N m^2 p) per search).
- O3, E (paper 004's ``B = sigma_min(Lambda)``): Cauchy interlacing / Rayleigh bound
  ``lambda_min(M + G^T G) <= lambda_min(V^T (M + G^T G) V)`` for the k smallest eigenvectors V of M;
  candidates are evaluated exactly in order of decreasing bound until the bound falls below the best
  exact value (branch and bound: same result as evaluating every candidate).
- others: batched eigenvalues.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack

from pipeline.calibration import indices as ix
from pipeline.calibration import trace_updates as tu

#: indices whose candidate searches use the low-rank update caches
UPDATE_INDICES = ix.TRACE_INDICES + ("D", "O1")


def is_regular(M: np.ndarray) -> bool:
    """Smallest eigenvalue of ``M`` above 1e-12 of the largest (the indices' own test)."""
    ev = np.linalg.eigvalsh(M)
    return bool(ev[0] > 1e-12 * max(ev[-1], 1e-300))


#: margin of :func:`above` relative to ``trace(A)``: Cholesky's backward error is about
#: ``p^1.5 eps ||A||`` (Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., §10.1),
#: ~3e-14 ||A|| for p = 40, and ``eigvalsh``'s is ``~p eps ||A||``: 1e-10 leaves a factor >1000
ABOVE_MARGIN = 1e-10


def above(A: np.ndarray, level: float) -> np.ndarray:
    """(n,) bool for a stack of symmetric matrices ``A`` (n, p, p): False only where
    ``lambda_min(A_k) <= level`` for certain, i.e. where ``A_k - s_k I`` with
    ``s_k = level - ABOVE_MARGIN trace(A_k)`` is not positive definite (its Cholesky factorisation
    fails). Every ``A_k`` whose computed smallest eigenvalue exceeds ``level`` is True (the margin
    covers the round-off of both); a True may still be below ``level`` by up to the margin."""
    n = A.shape[0]
    if not math.isfinite(level):
        return np.full(n, level < 0)
    shifted = A - (level - ABOVE_MARGIN * np.trace(A, axis1=1, axis2=2))[:, None, None] * np.eye(A.shape[1])
    return np.array([lapack.dpotrf(a, lower=1, clean=0)[1] == 0 for a in shifted], bool)


class DesignState:
    """Information matrix of the current selection with incremental updates and candidate searches."""

    def __init__(self, G: np.ndarray, spec: ix.IndexSpec, positions: np.ndarray | None,
                 selected: np.ndarray) -> None:
        self.G = G
        self.spec = spec
        self.positions = positions
        self.p = G.shape[2]
        self.selected = list(int(i) for i in selected)
        self.in_set = np.zeros(G.shape[0], bool)
        self.in_set[self.selected] = True
        self.evaluations = 0
        self.updates = 0
        self._cache: tu.LowRankCache | None = None
        self._Gq: np.ndarray | None = None   # parameter-major G (p, m, N) of the update caches
        self.refresh()

    # -- bookkeeping ---------------------------------------------------------------------------
    def refresh(self) -> None:
        Gs = self.G[self.selected]
        self.M = np.einsum("kmi,kmj->ij", Gs, Gs)
        self._cache = None

    def add(self, j: int) -> None:
        g = self.G[j]
        self.M = self.M + g.T @ g
        self.selected.append(int(j))
        self.in_set[j] = True
        self._cache = None
        self._count_update()

    def remove(self, k: int) -> None:
        g = self.G[k]
        self.M = self.M - g.T @ g
        self.selected.remove(int(k))
        self.in_set[k] = False
        self._cache = None
        self._count_update()

    def _count_update(self) -> None:
        self.updates += 1
        if self.updates % 200 == 0:
            self.refresh()

    @property
    def n(self) -> int:
        return len(self.selected)

    def sel_positions(self) -> np.ndarray | None:
        return None if self.positions is None else self.positions[self.selected]

    def score(self) -> float:
        self.evaluations += 1
        return ix.score(self.spec, self.M, self.n, self.sel_positions())

    def value(self) -> float:
        return ix.evaluate(self.spec, self.M, self.n, self.sel_positions())

    # -- candidate searches ----------------------------------------------------------------------
    def update_cache(self) -> tu.LowRankCache | None:
        """Low-rank update blocks at the current ``M`` (None: an index without them or a singular M)."""
        if self.spec.name not in UPDATE_INDICES:
            return None
        if self._cache is None:
            if not is_regular(self.M):
                return None
            if self._Gq is None:
                self._Gq = np.ascontiguousarray(self.G.transpose(2, 1, 0))
            if self.spec.name in ix.TRACE_INDICES:
                self._cache = tu.TraceCache(self._Gq, self.spec.weight_matrix(self.p), self.M)
            else:
                self._cache = tu.LogDetCache(self._Gq, self.M)
        return self._cache

    def _cache_scores(self, values: np.ndarray, n: int) -> np.ndarray:
        """Scores of designs of ``n`` configurations from the cache's values (``trace(W M^-1)``,
        or ``log det M`` for D = ``det(M)^(1/p)`` and O1 = ``det(M)^(1/(2p)) / sqrt(n)``)."""
        if self.spec.name == "D":
            return np.exp(values / self.p)
        if self.spec.name == "O1":
            return np.exp(values / (2 * self.p)) / math.sqrt(max(n, 1))
        return -values

    def remove_scores(self) -> np.ndarray:
        """Score after removing each selected configuration (order of ``self.selected``)."""
        sel = np.array(self.selected)
        self.evaluations += len(sel)
        cache = self.update_cache()
        if cache is None:
            return self._direct_remove_scores(sel)
        out = self._cache_scores(cache.remove_values(sel), self.n - 1)
        bad = np.isnan(out)             # an untrusted update: evaluate those designs directly
        if bad.any():
            out[bad] = self._direct_remove_scores(sel)[bad]
        return out

    def _direct_remove_scores(self, sel: np.ndarray) -> np.ndarray:
        Gs = self.G[sel]
        Ms = self.M[None] - np.einsum("kmi,kmj->kij", Gs, Gs)
        pos = None
        if self.spec.needs_positions:
            P = self.positions[sel]
            pos = np.stack([np.delete(P, i, axis=0) for i in range(len(sel))])
        return ix.scores_of_matrices(self.spec, Ms, self.n - 1, pos)

    def best_add(self, exclude: np.ndarray | None = None) -> tuple[int, float]:
        """Exhaustive search for the candidate whose addition maximises the score."""
        allowed = ~self.in_set
        if exclude is not None:
            allowed = allowed.copy()
            allowed[exclude] = False
        cand = np.flatnonzero(allowed)
        if cand.size == 0:
            return -1, -np.inf
        cache = self.update_cache()
        if cache is not None:
            sc = self._cache_scores(cache.add_values()[cand], self.n + 1)
        elif self.spec.name in ("O3", "E") and is_regular(self.M):
            return self._bound_and_prune(cand)
        else:
            sc = self._generic_scores(cand)
        self.evaluations += cand.size
        i = int(np.argmax(sc))
        return int(cand[i]), float(sc[i])

    def best_exchange(self, k: int) -> tuple[int, float]:
        """Best unselected candidate to replace selected ``k`` and the score of the exchanged design;
        the state is unchanged. Update indices: all candidates at once by the exchange update
        (:mod:`pipeline.calibration.trace_updates`); other indices and untrusted updates (removing
        ``k`` leaves M nearly singular): remove, :meth:`best_add`, put back."""
        cache = self.update_cache()
        values = None if cache is None else cache.exchange_values(k)
        if values is not None:
            cand = np.flatnonzero(~self.in_set)
            if cand.size == 0:
                return -1, -np.inf
            sc = self._cache_scores(values[cand], self.n)
            self.evaluations += cand.size
            i = int(np.argmax(sc))
            return int(cand[i]), float(sc[i])
        M, selected = self.M, list(self.selected)
        self.remove(k)
        j, s_new = self.best_add(exclude=np.array([k]))
        self.add(k)
        self.M, self.selected, self._cache = M, selected, cache
        return j, s_new

    def _generic_scores(self, cand: np.ndarray) -> np.ndarray:
        out = np.empty(cand.size)
        P = self.sel_positions()
        for s in range(0, cand.size, 4096):
            c = cand[s : s + 4096]
            Gc = self.G[c]
            Ms = self.M[None] + np.einsum("kmi,kmj->kij", Gc, Gc)
            if self.spec.needs_positions:
                ev = np.linalg.eigvalsh(Ms)
                od = ix.od_index_batch(P, self.positions[c], self.spec.knn)
                if self.spec.name == "Od":
                    out[s : s + c.size] = od
                else:
                    o1 = ix._values_from_eigs("O1", ev, self.n + 1)
                    o3 = ix._values_from_eigs("O3", ev, self.n + 1)
                    out[s : s + c.size] = ix.oc_combine(self.spec, o1, o3, od)
            else:
                out[s : s + c.size] = ix.scores_of_matrices(self.spec, Ms, self.n + 1)
        return out

    def _bound_and_prune(self, cand: np.ndarray, k_sub: int = 4, chunk: int = 16,
                         block: int = 512) -> tuple[int, float]:
        """Exact best addition for lambda_min by branch and bound.

        Two nested upper bounds of ``lambda_min(M + G^T G)`` (Rayleigh / Cauchy interlacing on the
        eigenvectors V of the smallest eigenvalues of M): ``ub1 = lambda_1 + |G v_1|^2`` (cheap) and
        ``ub4 = lambda_min(diag(lambda_1..4) + (G V_4)^T (G V_4)) <= ub1``. Candidates are visited in
        order of decreasing ub1; ub4 is computed per block, exact eigenvalues only for candidates
        whose ub4 beats the best exact value so far; the search stops when ub1 falls below it.
        Of those, only the ones :func:`above` passes (a Cholesky factorisation, several times
        cheaper than the eigenvalues) get their exact eigenvalues: the others cannot beat the best.
        """
        ev, V = np.linalg.eigh(self.M)
        k = min(k_sub, self.p)
        Vk = V[:, :k]
        G = self.G
        g1 = np.einsum("nmi,i->nm", G, V[:, 0])
        ub1_all = ev[0] + np.einsum("nm,nm->n", g1, g1)
        ub1 = ub1_all[cand]
        order = cand[np.argsort(-ub1)]
        ub1_sorted = ub1_all[order]
        best_j, best_lam = -1, -np.inf
        n_eval = 0
        D = np.diag(ev[:k])[None]
        for s in range(0, order.size, block):
            if ub1_sorted[s] <= best_lam:
                break
            blk = order[s : s + block]
            GV = G[blk] @ Vk
            ub4 = np.linalg.eigvalsh(np.einsum("nmi,nmj->nij", GV, GV) + D)[:, 0]
            o4 = np.argsort(-ub4)
            for t in range(0, o4.size, chunk):
                idx = o4[t : t + chunk]
                if ub4[idx[0]] <= best_lam:
                    break
                Gc = G[blk[idx]]
                Ms = self.M[None] + np.einsum("kmi,kmj->kij", Gc, Gc)
                lam = np.full(idx.size, -np.inf)
                live = above(Ms, best_lam)
                if live.any():
                    lam[live] = np.linalg.eigvalsh(Ms[live])[:, 0]
                n_eval += idx.size
                i = int(np.argmax(lam))
                if lam[i] > best_lam:
                    best_lam, best_j = float(lam[i]), int(blk[idx[i]])
        self.evaluations += n_eval
        lam = max(best_lam, 0.0)
        return best_j, (math.sqrt(lam) if self.spec.name == "O3" else lam)
