"""Selection of calibration configurations from a candidate set.

All algorithms work on whitened per-configuration Jacobian blocks ``G`` (N, m, p) and any
:class:`~pipeline.calibration.indices.IndexSpec`; the information matrix of a selection S is
``M_S = sum_{k in S} G_k^T G_k`` and is *updated* when a configuration enters or leaves
(paper 004 eqs. 15-17: ``Lambda_{i+1} = Lambda_i ± G_k^T G_k``), never recomputed from the stacked
Jacobian (except a periodic refresh against round-off).

Fast candidate searches (exhaustive, exact):

- A, tcp_A, tcp_A_mixed, V: Sherman-Morrison-Woodbury, ``trace(W (M + G^T G)^-1) = trace(W M^-1)
  - trace(S^-1 H W H^T)`` with ``H = G M^-1``, ``S = I + H G^T`` (O(p^2) per candidate).
- D, O1: ``log det(M + G^T G) = log det M + log det S``.
- O3, E (paper 004's ``B = sigma_min(Lambda)``): Cauchy interlacing / Rayleigh bound
  ``lambda_min(M + G^T G) <= lambda_min(V^T (M + G^T G) V)`` for the k smallest eigenvectors V of M;
  candidates are evaluated exactly in order of decreasing bound until the bound falls below the best
  exact value (branch and bound: same result as evaluating every candidate).
- others: batched eigenvalues.

Algorithms: :func:`remove_and_replace` (paper 004 §3.3.1 steps 1-4), :func:`detmax` (Mitchell's
excursion algorithm, as used in paper 003), :func:`bsaa` (paper 003 §3.2: swap one selected for one
unselected, Metropolis acceptance, geometric cooling 0.98, Markov chain length 1).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from pipeline.blas import single_thread_blas
from pipeline.calibration import indices as ix
from pipeline.errors import InfeasibleError


def _one_blas_thread(fn):
    """Run a selection algorithm with one OpenBLAS thread (many tiny factorisations)."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with single_thread_blas():
            return fn(*args, **kwargs)
    return wrapper


@dataclass
class SelectionResult:
    """A selected design and how it was found."""

    method: str
    index_name: str
    selected: np.ndarray            # indices into the candidate set
    index_value: float              # natural value of the index
    run_time_s: float
    evaluations: int                # number of index evaluations (candidate designs scored)
    history: list[tuple[int, float]] = field(default_factory=list)  # (iteration, index value)

    def as_dict(self) -> dict:
        return {"method": self.method, "index_name": self.index_name,
                "n_configurations": int(len(self.selected)), "index_value": float(self.index_value),
                "run_time_s": float(self.run_time_s), "evaluations": int(self.evaluations)}


class _State:
    """Information matrix of the current selection with incremental updates."""

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
        self.refresh()

    # -- bookkeeping ---------------------------------------------------------------------------
    def refresh(self) -> None:
        Gs = self.G[self.selected]
        self.M = np.einsum("kmi,kmj->ij", Gs, Gs)

    def add(self, j: int) -> None:
        g = self.G[j]
        self.M = self.M + g.T @ g
        self.selected.append(int(j))
        self.in_set[j] = True
        self._count_update()

    def remove(self, k: int) -> None:
        g = self.G[k]
        self.M = self.M - g.T @ g
        self.selected.remove(int(k))
        self.in_set[k] = False
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
    def remove_scores(self) -> np.ndarray:
        """Score after removing each selected configuration (order of ``self.selected``)."""
        sel = np.array(self.selected)
        Gs = self.G[sel]
        Ms = self.M[None] - np.einsum("kmi,kmj->kij", Gs, Gs)
        pos = None
        if self.spec.needs_positions:
            P = self.positions[sel]
            pos = np.stack([np.delete(P, i, axis=0) for i in range(len(sel))])
        self.evaluations += len(sel)
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
        name = self.spec.name
        ev = np.linalg.eigvalsh(self.M)
        regular = ev[0] > 1e-12 * max(ev[-1], 1e-300)
        if regular and name in ix.TRACE_INDICES + ("D", "O1"):
            sc = self._smw_scores(cand)
        elif regular and name in ("O3", "E"):
            return self._bound_and_prune(cand)
        else:
            sc = self._generic_scores(cand)
        self.evaluations += cand.size
        i = int(np.argmax(sc))
        return int(cand[i]), float(sc[i])

    def _smw_scores(self, cand: np.ndarray) -> np.ndarray:
        name = self.spec.name
        Minv = np.linalg.inv(self.M)
        Minv = 0.5 * (Minv + Minv.T)
        m = self.G.shape[1]
        out = np.empty(cand.size)
        if name in ("D", "O1"):
            _, logdet = np.linalg.slogdet(self.M)
        else:
            W = self.spec.weight_matrix(self.p)
            base = float(np.sum(Minv * W))  # trace(W M^-1) for symmetric W
            MWM = Minv @ W @ Minv
        eye = np.eye(m)
        for s in range(0, cand.size, 8192):
            c = cand[s : s + 8192]
            Gc = self.G[c]
            H = Gc @ Minv                                   # (B,m,p)
            S = eye + np.einsum("bmi,bni->bmn", H, Gc)      # I + G M^-1 G^T
            if name in ("D", "O1"):
                _, ld = np.linalg.slogdet(S)
                tot = logdet + ld
                if name == "D":
                    out[s : s + c.size] = np.exp(tot / self.p)
                else:
                    out[s : s + c.size] = np.exp(tot / (2 * self.p)) / math.sqrt(self.n + 1)
            else:
                T = np.einsum("bmi,ij,bnj->bmn", Gc, MWM, Gc)   # G M^-1 W M^-1 G^T
                red = np.einsum("bmn,bnm->b", np.linalg.inv(S), T)
                out[s : s + c.size] = -(base - red)
        return out

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
                lam = np.linalg.eigvalsh(Ms)[:, 0]
                n_eval += idx.size
                i = int(np.argmax(lam))
                if lam[i] > best_lam:
                    best_lam, best_j = float(lam[i]), int(blk[idx[i]])
        self.evaluations += n_eval
        lam = max(best_lam, 0.0)
        return best_j, (math.sqrt(lam) if self.spec.name == "O3" else lam)


def _random_regular_start(G: np.ndarray, n: int, rng: np.random.Generator, tries: int = 200,
                          candidates: np.ndarray | None = None) -> np.ndarray:
    """Paper 004 step 1: random subsets until the information matrix is regular."""
    N, m, p = G.shape
    pool = np.arange(N) if candidates is None else candidates
    if n * m < p:
        raise InfeasibleError(None, "calibration.n_configurations",
                              f"{n} configurations x {m} coordinates < {p} identifiable parameters")
    if pool.size < n:
        raise InfeasibleError(None, "calibration.candidates",
                              f"only {pool.size} feasible candidates for {n} configurations "
                              "(increase n_random_candidates or grid_per_axis)")
    ev_all = np.linalg.eigvalsh(np.einsum("kmi,kmj->ij", G[pool], G[pool]))
    if ev_all[0] <= 1e-10 * max(ev_all[-1], 1e-300):
        raise InfeasibleError(None, "calibration.candidates",
                              "the candidate set cannot make the information matrix regular "
                              f"(rank {int(np.sum(ev_all > 1e-10 * ev_all[-1]))} < {p} parameters)")
    for _ in range(tries):
        S = rng.choice(pool, size=n, replace=False)
        Gs = G[S]
        ev = np.linalg.eigvalsh(np.einsum("kmi,kmj->ij", Gs, Gs))
        if ev[0] > 1e-10 * max(ev[-1], 1e-300):
            return S
    raise InfeasibleError(None, "calibration.candidates",
                          f"no regular random subset of {n} configurations in {tries} tries")


def _check(G: np.ndarray) -> np.ndarray:
    G = np.asarray(G, float)
    if G.ndim != 3:
        raise ValueError("G must be (N, m, p)")
    if not np.all(np.isfinite(G)):
        raise InfeasibleError(None, "calibration.candidates", "non-finite Jacobian entries")
    return G


@_one_blas_thread
def remove_and_replace(G: np.ndarray, spec: ix.IndexSpec, n_max: int, rng: np.random.Generator,
                       n_initial: int | None = None, positions: np.ndarray | None = None,
                       max_iterations: int = 500, rel_tol: float = 1e-6,
                       initial: np.ndarray | None = None) -> SelectionResult:
    """Paper 004 §3.3.1, steps 1-4.

    1. random regular start of ``n_initial`` configurations;
    2. remove the configuration whose removal decreases the index least, add the candidate that
       increases it most; repeat while the index improves;
    3. add the best single candidate while the index improves and ``n < n_max``;
    4. final remove-and-replace: try every selected configuration; execute any exchange that
       improves the index; stop when a full pass makes none.
    """
    t0 = time.perf_counter()
    G = _check(G)
    N, m, p = G.shape
    if n_initial is None:
        n_initial = max(min(n_max, math.ceil(p / m) + 2), (n_max * 2) // 3)
    n_initial = min(n_initial, n_max)
    start = initial if initial is not None else _random_regular_start(G, n_initial, rng)
    st = _State(G, spec, positions, start)
    cur = st.score()
    hist = [(0, st.value())]
    it = 0

    def step_exchange(remove_k: int) -> bool:
        nonlocal cur, it
        st.remove(remove_k)
        j, s_new = st.best_add()
        if j >= 0 and s_new > cur + rel_tol * max(abs(cur), 1e-300) and j != remove_k:
            st.add(j)
            cur = st.score()
            it += 1
            hist.append((it, st.value()))
            return True
        st.add(remove_k)
        return False

    # step 2
    while it < max_iterations:
        rs = st.remove_scores()
        k = st.selected[int(np.argmax(rs))]
        if not step_exchange(k):
            break
    # step 3
    while st.n < n_max:
        j, s_new = st.best_add()
        if j < 0 or not s_new > cur + rel_tol * max(abs(cur), 1e-300):
            break
        st.add(j)
        cur = st.score()
        it += 1
        hist.append((it, st.value()))
    # step 4
    improved = True
    while improved and it < max_iterations:
        improved = False
        rs = st.remove_scores()
        for k in [st.selected[i] for i in np.argsort(-rs)]:
            if step_exchange(k):
                improved = True
                break
    st.refresh()
    return SelectionResult("remove_and_replace", spec.name, np.array(st.selected), st.value(),
                           time.perf_counter() - t0, st.evaluations, hist)


@_one_blas_thread
def detmax(G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
           positions: np.ndarray | None = None, max_depth: int = 3, max_iterations: int = 500,
           rel_tol: float = 1e-9) -> SelectionResult:
    """DETMAX (Mitchell 1974): excursions that add ``d`` best points then remove ``d`` worst ones;
    an improving excursion is kept and the depth reset to 1, otherwise the depth grows up to
    ``max_depth``."""
    t0 = time.perf_counter()
    G = _check(G)
    st = _State(G, spec, positions, _random_regular_start(G, n, rng))
    cur = st.score()
    hist = [(0, st.value())]
    depth, it = 1, 0
    while depth <= max_depth and it < max_iterations:
        before = list(st.selected)
        for _ in range(depth):
            j, _s = st.best_add()
            if j < 0:
                break
            st.add(j)
        while st.n > n:
            rs = st.remove_scores()
            st.remove(st.selected[int(np.argmax(rs))])
        new = st.score()
        if new > cur + rel_tol * max(abs(cur), 1e-300):
            cur = new
            depth = 1
            it += 1
            hist.append((it, st.value()))
        else:
            st.selected = before
            st.in_set[:] = False
            st.in_set[before] = True
            st.refresh()
            depth += 1
    return SelectionResult("detmax", spec.name, np.array(st.selected), st.value(),
                           time.perf_counter() - t0, st.evaluations, hist)


@_one_blas_thread
def bsaa(G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
         positions: np.ndarray | None = None, t_initial: float = 1e20, t_final: float = 1e-50,
         cooling: float = 0.98, chain_length: int = 1) -> SelectionResult:
    """Binary simulated annealing (paper 003 §3.2).

    A state is a 0/1 selection vector with ``n`` ones. A move flips one random 1 and one random 0
    (swap), accepted by the Metropolis rule ``u < exp((F_new - F) / T)`` on the score F; the
    temperature is multiplied by ``cooling`` (0.98) after each Markov chain (length 1) until
    ``t_final``. Paper 003 gives T_init = 10^20, T_final = 10^-50 (signs of the exponents read from
    the garbled extraction). The best state visited is returned.
    """
    t0 = time.perf_counter()
    G = _check(G)
    N = G.shape[0]
    st = _State(G, spec, positions, _random_regular_start(G, n, rng))
    cur = st.score()
    best, best_sel = cur, list(st.selected)
    hist = [(0, st.value())]
    T = t_initial
    it = 0
    n_steps = int(math.ceil(math.log(t_final / t_initial) / math.log(cooling)))
    for _ in range(n_steps):
        for _c in range(chain_length):
            out_pos = int(rng.integers(st.n))
            k_out = st.selected[out_pos]
            while True:
                j_in = int(rng.integers(N))
                if not st.in_set[j_in]:
                    break
            st.remove(k_out)
            st.add(j_in)
            new = st.score()
            d = new - cur
            if d >= 0 or (np.isfinite(d) and rng.random() < math.exp(max(d / T, -700.0))):
                cur = new
                if cur > best:
                    best, best_sel = cur, list(st.selected)
            else:
                st.remove(j_in)
                st.add(k_out)
        it += 1
        if it % 50 == 0:
            hist.append((it, -best if spec.minimised else best))
        T *= cooling
    st.selected = best_sel
    st.in_set[:] = False
    st.in_set[best_sel] = True
    st.refresh()
    hist.append((it, st.value()))
    return SelectionResult("bsaa", spec.name, np.array(best_sel), st.value(),
                           time.perf_counter() - t0, st.evaluations, hist)


@_one_blas_thread
def random_design(G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
                  positions: np.ndarray | None = None) -> SelectionResult:
    """Heuristic baseline: a random regular subset (paper 000's 'heuristic', paper 003's 'none')."""
    t0 = time.perf_counter()
    G = _check(G)
    st = _State(G, spec, positions, _random_regular_start(G, n, rng))
    return SelectionResult("random", spec.name, np.array(st.selected), st.value(),
                           time.perf_counter() - t0, 1, [(0, st.value())])


@_one_blas_thread
def linear_scan_design(G: np.ndarray, spec: ix.IndexSpec, n: int,
                       positions: np.ndarray | None = None) -> SelectionResult:
    """Paper 004's comparison: ``n`` candidates equally spaced through the (grid-ordered) set."""
    t0 = time.perf_counter()
    G = _check(G)
    sel = np.unique(np.linspace(0, G.shape[0] - 1, n).round().astype(int))
    st = _State(G, spec, positions, sel)
    return SelectionResult("linear_scan", spec.name, sel, st.value(), time.perf_counter() - t0, 1,
                           [(0, st.value())])


METHODS = {"remove_and_replace": remove_and_replace, "detmax": detmax, "bsaa": bsaa,
           "random": random_design}


def select(method: str, G: np.ndarray, spec: ix.IndexSpec, n: int, rng: np.random.Generator,
           positions: np.ndarray | None = None, **kw) -> SelectionResult:
    """Dispatch to a selection algorithm by name."""
    if method == "remove_and_replace":
        return remove_and_replace(G, spec, n, rng, positions=positions, **kw)
    if method not in METHODS:
        raise ValueError(f"unknown selection method {method!r}; choose from {sorted(METHODS)}")
    return METHODS[method](G, spec, n, rng, positions=positions, **kw)
