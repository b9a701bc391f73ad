"""Paper 003's indices and searches with incremental updates (study calib-003).

Paper ``003_16198f1660ab3739.txt`` §3.1: for the stacked position Jacobian ``J`` (3m x p) of the m
selected poses, singular values ``s_1 >= ... >= s_p``,

- ``O1 = (s_1 ... s_p)^(1/p) / sqrt(m)`` (eq. 30), ``O2 = s_p / s_1`` (eq. 31), ``O3 = s_p`` (eq. 32);
- ``Od = 1 / var(d_i)`` (eq. 33), ``d_i`` the mean distance of point i to its K nearest selected points;
- ``Oc = (2/pi) (atan O1 + atan O3 + atan Od)`` (eq. 35, arctangent normalisation eq. 34).

Eq. 34 maps any positive number into [0, 1], but ``atan`` only discriminates values of order one:
in the paper's units (mm, rad) O1 and O3 of a few hundred poses are large (atan saturates) and Od
(1/mm^2) is tiny, so the three terms do not count alike. :class:`OcScale` divides each term by a
reference value first (``x / x_ref``: the median over random subsets of the same size, so a random
design sits at atan(1) = pi/4 on every term); ``OcScale.literal()`` keeps the paper's units.

State (:class:`SubsetState`): the information matrix ``M = sum G_k^T G_k`` of the selection is
updated by rank-3 terms when a pose enters or leaves (one ``eigvalsh`` of p x p per evaluation),
and the K+1 nearest selected distances of every selected point are kept, so that

- adding candidate j changes point i's K-NN mean by ``min(d_ij - kth_i, 0) / K``;
- removing s changes it by ``(k+1th_i - d_is) / K`` where s is among i's K nearest;

which scores every addition / removal at once (vectorised) and a BSAA swap in O(n).
Searches: :func:`detmax` (Mitchell 1974 excursions, as :func:`pipeline.calibration.design.detmax`)
and :func:`bsaa` (paper 003 §3.2: swap one selected and one unselected pose, Metropolis rule,
T from 1e20 to 1e-50, cooling 0.98, Markov chain length 1; the best state visited is returned).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from pipeline.core.blas import single_thread_blas

INDICES = ("O1", "O2", "O3", "Od", "Oc")


@dataclass(frozen=True)
class OcScale:
    """Reference values of O1, O3 and Od inside Oc (``atan(x / x_ref)``); 1 = the paper's units."""

    o1: float = 1.0
    o3: float = 1.0
    od: float = 1.0

    @classmethod
    def literal(cls) -> OcScale:
        return cls()


def oc_terms(o1: np.ndarray, o3: np.ndarray, od: np.ndarray, scale: OcScale) -> np.ndarray:
    """The three normalised terms ``(2/pi) atan(x / x_ref)`` (..., 3), each in [0, 1]."""
    return 2.0 / np.pi * np.arctan(np.stack([np.asarray(o1) / scale.o1, np.asarray(o3) / scale.o3,
                                             np.asarray(od) / scale.od], axis=-1))


def _spectral(ev: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """O1, O2, O3 from ascending eigenvalues of M (batched)."""
    ev = np.maximum(ev, 1e-300)
    s = np.sqrt(ev)
    o1 = np.exp(np.mean(np.log(s), axis=-1)) / math.sqrt(max(m, 1))
    return o1, s[..., 0] / s[..., -1], s[..., 0]


def _od_from_means(means: np.ndarray) -> np.ndarray:
    """``1 / var`` over the last axis (inf without spread); the variance by the operations of ``np.var``
    (sum / n, the squared deviations summed / n) without its wrapper: the search's inner loop."""
    n = means.shape[-1]
    dev = means - np.add.reduce(means, axis=-1, keepdims=True) / n
    var = np.add.reduce(dev * dev, axis=-1) / n
    return np.where(var > 0, 1.0 / np.maximum(var, 1e-300), np.inf)


class SubsetState:
    """Selection of ``n`` poses of a pool with incremental index updates (module docstring).

    ``J``: (N, 3, p) position Jacobian blocks in the index's units; ``positions``: (N, 3) points
    for Od (same length unit as the intended Od); ``name``: O1, O2, O3, Od or Oc.
    """

    def __init__(self, J: np.ndarray, positions: np.ndarray, selected: np.ndarray, name: str, knn: int = 3,
                 scale: OcScale | None = None) -> None:
        if name not in INDICES:
            raise ValueError(f"unknown index {name!r}; choose from {INDICES}")
        self.name = name
        self.J = np.asarray(J, float)
        self.A = np.einsum("kmi,kmj->kij", self.J, self.J)          # per-pose information
        P = np.asarray(positions, float)
        self.D = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=-1)
        np.fill_diagonal(self.D, np.inf)
        self.K = knn
        self.scale = scale or OcScale()
        #: the K-NN rows are kept only for the indices that use them
        self.track_knn = name in ("Od", "Oc")
        N = len(P)
        self.sel = np.zeros(N, bool)
        self.sel[np.asarray(selected, int)] = True
        self._selected: np.ndarray | None = None
        self.near = np.full((N, knn + 1), np.inf)                     # K+1 nearest selected distances
        self.updates = 0
        self.evaluations = 0
        self.refresh()

    # -- bookkeeping ---------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return int(self.selected.size)

    @property
    def selected(self) -> np.ndarray:
        if self._selected is None:
            self._selected = np.flatnonzero(self.sel)
        return self._selected

    def _set(self, i: int, value: bool) -> None:
        self.sel[i] = value
        self._selected = None

    def refresh(self) -> None:
        self._selected = None
        idx = self.selected
        self.M = self.A[idx].sum(axis=0)
        if self.track_knn:
            self._rows(idx)

    def _rows(self, rows: np.ndarray) -> None:
        """Recompute the K+1 nearest selected distances of ``rows``."""
        if rows.size == 0 or not self.track_knn:
            return
        idx = self.selected
        d = self.D[rows[:, None], idx]
        k1 = self.K + 1
        if d.shape[1] > k1:
            d = np.partition(d, k1 - 1, axis=1)[:, :k1]
        d = np.sort(d, axis=1)
        if d.shape[1] < k1:
            d = np.concatenate([d, np.full((rows.size, k1 - d.shape[1]), np.inf)], axis=1)
        self.near[rows] = d

    def _touch(self) -> None:
        self.updates += 1
        if self.updates % 500 == 0:
            self.refresh()

    def add(self, j: int) -> None:
        idx = self.selected
        affected = idx[self.D[idx, j] < self.near[idx, self.K]] if self.track_knn else idx[:0]
        self._set(j, True)
        self.M = self.M + self.A[j]
        self._rows(np.append(affected, j))
        self._touch()

    def remove(self, s: int) -> None:
        self._set(s, False)
        idx = self.selected
        affected = idx[self.D[idx, s] <= self.near[idx, self.K]] if self.track_knn else idx[:0]
        self.M = self.M - self.A[s]
        self._rows(affected)
        self._touch()

    def swap(self, s: int, j: int) -> tuple:
        """Remove ``s`` and add ``j``; returns what :meth:`undo` needs to restore the state exactly."""
        before = self._selected
        self._set(s, False)
        idx = self.selected
        if self.track_knn:    # D is symmetric: its rows s and j are read (contiguous)
            kth = self.near[idx, self.K]
            rows = idx[(self.D[s, idx] <= kth) | (self.D[j, idx] < kth)]
        else:
            rows = idx[:0]
        token = (s, j, self.M, rows, self.near[rows], self.near[j].copy(), before)
        self._set(j, True)
        self.M = self.M - self.A[s] + self.A[j]
        self._rows(np.concatenate([rows, [j]]))
        self.updates += 1
        return token

    def undo(self, token: tuple) -> None:
        s, j, M, rows, near_rows, near_j, before = token
        self._set(j, False)
        self._set(s, True)
        self._selected = before      # the selection of before the swap (None: not listed then)
        self.M = M
        self.near[rows] = near_rows
        self.near[j] = near_j

    # -- values --------------------------------------------------------------------------------
    def knn_means(self) -> np.ndarray:
        """Mean of the K nearest selected distances of each selected point (``mean(axis=1)``'s operations)."""
        return np.add.reduce(self.near[self.selected, : self.K], axis=1) / self.K

    def all_values(self) -> dict[str, float]:
        """O1, O2, O3, Od, Oc of the current selection (natural values; Oc with this state's scale)."""
        o1, o2, o3 = _spectral(np.linalg.eigvalsh(self.M), self.n)
        od = float(_od_from_means(self.knn_means()))
        oc = float(oc_terms(o1, o3, od, self.scale).sum())
        return {"O1": float(o1), "O2": float(o2), "O3": float(o3), "Od": od, "Oc": oc}

    # O1 from log-determinants (Cholesky), O2 / O3 from eigenvalues, Od from the K-NN rows
    def _o1(self, logdet: np.ndarray, m: int) -> np.ndarray:
        return np.exp(logdet / (2 * self.J.shape[2])) / math.sqrt(max(m, 1))

    def _value_of(self, o1: np.ndarray | None, o3: np.ndarray | None, od: np.ndarray | None,
                  o2: np.ndarray | None = None) -> np.ndarray:
        if self.name == "O1":
            return o1
        if self.name == "O2":
            return o2
        if self.name == "O3":
            return o3
        if self.name == "Od":
            return od
        return oc_terms(o1, o3, od, self.scale).sum(axis=-1)

    def value(self) -> float:
        self.evaluations += 1
        o1 = o2 = o3 = od = None
        if self.name in ("O1", "Oc"):
            o1 = self._o1(np.linalg.slogdet(self.M)[1], self.n)
        if self.name in ("O2", "O3", "Oc"):
            ev = np.sqrt(np.maximum(np.linalg.eigvalsh(self.M), 1e-300))
            o2, o3 = ev[0] / ev[-1], ev[0]
        if self.name in ("Od", "Oc"):
            od = _od_from_means(self.knn_means())
        return float(self._value_of(o1, o3, od, o2))

    def _od_add(self, cand: np.ndarray) -> np.ndarray:
        idx = self.selected
        base = self.near[idx, : self.K].mean(axis=1)                      # (n,)
        kth = self.near[idx, self.K - 1]
        d = self.D[cand][:, idx]                                          # (C, n)
        means = base[None] + np.minimum(d - kth[None], 0.0) / self.K
        own = np.partition(d, min(self.K, d.shape[1]) - 1, axis=1)[:, : self.K].mean(axis=1)
        return _od_from_means(np.concatenate([means, own[:, None]], axis=1))

    def _od_remove(self) -> np.ndarray:
        idx = self.selected
        base = self.near[idx, : self.K].mean(axis=1)
        kth = self.near[idx, self.K - 1]
        k1th = self.near[idx, self.K]
        d = self.D[idx][:, idx]                                           # d[s, i]; diagonal inf
        means = base[None] + np.where(d <= kth[None], (k1th[None] - d) / self.K, 0.0)   # (S, n)
        n = idx.size
        off = ~np.eye(n, dtype=bool)
        mu = (means * off).sum(axis=1) / (n - 1)
        var = ((means - mu[:, None]) ** 2 * off).sum(axis=1) / (n - 1)
        return np.where(var > 0, 1.0 / np.maximum(var, 1e-300), np.inf)

    def _scores(self, rows: np.ndarray, sign: float, exact: bool) -> tuple[int, float, np.ndarray | None]:
        """Best of ``M + sign A_r`` over ``rows`` (and every value when ``exact``).

        O1: ``log det(M + sign G^T G) = log det M + log det(I + sign G M^-1 G^T)`` (3 x 3 per row).
        O3 and Oc: Rayleigh-Ritz bound ``lambda_min(M') <= lambda_min(V^T M' V)`` on the 4 eigenvectors
        of the smallest eigenvalues of M; rows are evaluated exactly in order of decreasing bound until
        the bound falls below the best exact value (same result as evaluating every row).
        """
        m = self.n + (1 if sign > 0 else -1)
        self.evaluations += rows.size
        G = self.J[rows]
        o1 = od = None
        if self.name in ("O1", "Oc"):
            Minv = np.linalg.inv(self.M)
            S = np.eye(3)[None] + sign * np.einsum("bmi,ij,bnj->bmn", G, Minv, G)
            o1 = self._o1(np.linalg.slogdet(self.M)[1] + np.linalg.slogdet(S)[1], m)
        if self.name in ("Od", "Oc"):
            od = self._od_add(rows) if sign > 0 else self._od_remove()
        if self.name in ("O1", "Od"):
            v = self._value_of(o1, None, od)
            i = int(np.argmax(v))
            return i, float(v[i]), v
        Ms = self.M[None] + sign * self.A[rows]
        if self.name == "O2" or exact:
            ev = np.sqrt(np.clip(np.linalg.eigvalsh(Ms), 1e-300, None))
            v = self._value_of(o1, ev[:, 0], od, ev[:, 0] / ev[:, -1])
            i = int(np.argmax(v))
            return i, float(v[i]), v
        ev, V = np.linalg.eigh(self.M)
        k = min(4, V.shape[1])
        GV = G @ V[:, :k]
        ub = np.linalg.eigvalsh(np.diag(ev[:k])[None] + sign * np.einsum("bmi,bmj->bij", GV, GV))[:, 0]
        ub_v = self._value_of(o1, np.sqrt(np.clip(ub, 1e-300, None)), od)
        order = np.argsort(-ub_v)
        best_i, best_v = -1, -np.inf
        for s in range(0, order.size, 8):
            chunk = order[s : s + 8]
            if ub_v[chunk[0]] <= best_v:
                break
            o3 = np.sqrt(np.clip(np.linalg.eigvalsh(Ms[chunk])[:, 0], 1e-300, None))
            v = self._value_of(None if o1 is None else o1[chunk], o3, None if od is None else od[chunk])
            j = int(np.argmax(v))
            if v[j] > best_v:
                best_i, best_v = int(chunk[j]), float(v[j])
        return best_i, best_v, None

    def add_scores(self, cand: np.ndarray) -> np.ndarray:
        """Index value after adding each candidate (not selected)."""
        return self._scores(cand, 1.0, True)[2]

    def remove_scores(self) -> np.ndarray:
        """Index value after removing each selected pose (order of :attr:`selected`)."""
        return self._scores(self.selected, -1.0, True)[2]

    def best_add(self, cand: np.ndarray) -> tuple[int, float]:
        """Candidate whose addition gives the largest index, and that value."""
        i, v, _ = self._scores(cand, 1.0, False)
        return int(cand[i]), v

    def best_remove(self) -> tuple[int, float]:
        """Selected pose whose removal leaves the largest index, and that value."""
        idx = self.selected
        i, v, _ = self._scores(idx, -1.0, False)
        return int(idx[i]), v


@dataclass
class SearchResult:
    method: str
    index_name: str
    selected: np.ndarray
    index_value: float
    run_time_s: float
    evaluations: int


def _regular_start(A: np.ndarray, n: int, rng: np.random.Generator, tries: int = 100) -> np.ndarray:
    for _ in range(tries):
        S = rng.choice(len(A), size=n, replace=False)
        ev = np.linalg.eigvalsh(A[S].sum(axis=0))
        if ev[0] > 1e-10 * ev[-1]:
            return S
    raise ValueError(f"no regular random subset of {n} poses in {tries} tries")


def random_subset(J: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Paper 003's 'none': a random (regular) subset of the pool."""
    return _regular_start(np.einsum("kmi,kmj->kij", J, J), n, rng)


def detmax(J: np.ndarray, positions: np.ndarray, name: str, n: int, rng: np.random.Generator,
           scale: OcScale | None = None, knn: int = 3, max_depth: int = 3, max_iterations: int = 500,
           rel_tol: float = 1e-9) -> SearchResult:
    """DETMAX (Mitchell 1974): an excursion adds the ``d`` best poses one by one, then removes the ``d``
    worst; kept when the index improved (depth back to 1), else undone and the depth grows to ``max_depth``."""
    t0 = time.perf_counter()
    with single_thread_blas():
        st = SubsetState(J, positions, random_subset(J, n, rng), name, knn, scale)
        cur = st.value()
        depth, it = 1, 0
        while depth <= max_depth and it < max_iterations:
            before = st.selected.copy()
            for _ in range(depth):
                cand = np.flatnonzero(~st.sel)
                if cand.size == 0:
                    break
                st.add(st.best_add(cand)[0])
            while st.n > n:
                st.remove(st.best_remove()[0])
            new = st.value()
            if new > cur + rel_tol * max(abs(cur), 1e-300):
                cur, depth, it = new, 1, it + 1
            else:
                st.sel[:] = False
                st.sel[before] = True
                st.refresh()
                depth += 1
        return SearchResult("detmax", name, st.selected, cur, time.perf_counter() - t0, st.evaluations)


def bsaa(J: np.ndarray, positions: np.ndarray, name: str, n: int, rng: np.random.Generator,
         scale: OcScale | None = None, knn: int = 3, t_initial: float = 1e20, t_final: float = 1e-50,
         cooling: float = 0.98, chain_length: int = 1) -> SearchResult:
    """Binary simulated annealing, paper 003 §3.2 (module docstring); each move is a swap updated in place
    (rank-3 update of M and the K-NN rows it touches) and undone the same way when rejected."""
    t0 = time.perf_counter()
    with single_thread_blas():
        st = SubsetState(J, positions, random_subset(J, n, rng), name, knn, scale)
        cur = st.value()
        best, best_sel = cur, st.selected.copy()
        T = t_initial
        n_steps = int(math.ceil(math.log(t_final / t_initial) / math.log(cooling)))
        for _ in range(n_steps):
            for _c in range(chain_length):
                sel = st.selected
                free = np.flatnonzero(~st.sel)
                k_out = int(sel[rng.integers(sel.size)])
                j_in = int(free[rng.integers(free.size)])
                token = st.swap(k_out, j_in)
                new = st.value()
                d = new - cur
                if d >= 0 or (np.isfinite(d) and rng.random() < math.exp(max(d / T, -700.0))):
                    cur = new
                    if cur > best:
                        best, best_sel = cur, st.selected.copy()
                else:
                    st.undo(token)
            T *= cooling
            if st.updates % 500 == 0:
                st.refresh()
        return SearchResult("bsaa", name, best_sel, best, time.perf_counter() - t0, st.evaluations)


def index_values(J: np.ndarray, positions: np.ndarray, selected: np.ndarray, knn: int = 3,
                 scale: OcScale | None = None) -> dict[str, float]:
    """Every index of one selection (a report row)."""
    return SubsetState(J, positions, selected, "Oc", knn, scale).all_values()


def reference_scale(J: np.ndarray, positions: np.ndarray, n: int, rng: np.random.Generator, samples: int = 20,
                    knn: int = 3) -> OcScale:
    """Medians of O1, O3 and Od over ``samples`` random subsets of size n (module docstring)."""
    vals = [index_values(J, positions, random_subset(J, n, rng), knn) for _ in range(samples)]
    return OcScale(*(float(np.median([v[k] for v in vals])) for k in ("O1", "O3", "Od")))
