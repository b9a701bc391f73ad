"""Exact low-rank updates of the trace and log-det criteria for every candidate at once.

A configuration entering or leaving a design changes the information matrix
``M = sum_k G_k^T G_k`` (whitened blocks ``G_k``, m x p) by ``± G^T G`` (paper 004 eqs. 15-17).
With ``P_j = G_j M^-1 G_j^T`` (m x m) the Sherman-Morrison-Woodbury identity and the matrix
determinant lemma (Golub & Van Loan, *Matrix Computations*, 4th ed., §2.1.4) give every candidate's
criterion from m x m algebra.

Trace criteria ``V(M) = trace(W M^-1)`` (``A``, ``tcp_A``, ``tcp_A_mixed``, the task-space ``V``,
:mod:`pipeline.calibration.indices`), with ``T_j = G_j M^-1 W M^-1 G_j^T``:

- adding ``j``:   ``V(M + G_j^T G_j) = V - trace((I + P_j)^-1 T_j)``;
- removing ``k``: ``V(M - G_k^T G_k) = V + trace(R^-1 T_k)``, ``R = I - P_k``;
- exchanging (remove ``k``, add ``j``): ``M_k^-1 = M^-1 + a R^-1 a^T`` with ``a = M^-1 G_k^T``;
  with the cross terms ``c_j = G_j a = G_j M^-1 G_k^T`` and ``d_j = G_j M^-1 W a``:
  ``P'_j = P_j + c_j R^-1 c_j^T``,
  ``T'_j = T_j + c_j R^-1 d_j^T + d_j R^-1 c_j^T + c_j R^-1 T_k R^-1 c_j^T`` and
  ``V(M_k + G_j^T G_j) = V + trace(R^-1 T_k) - trace((I + P'_j)^-1 T'_j)``.

Log-det criteria (``D = det(M)^(1/p)``, ``O1``): ``log det(M + G_j^T G_j) = log det M + log det(I + P_j)``,
``log det(M - G_k^T G_k) = log det M + log det R`` and the exchange
``log det M + log det R + log det(I + P'_j)``.

A cache holds ``M^-1`` and the blocks ``P_j`` (and ``T_j``) of all N candidates at the current
``M``: O(N m p^2) once per accepted change. One exchange search (one removal, all additions) is
then one (2m x p) @ (p x N m) product (``c_j`` and ``d_j`` of every candidate) and batched m x m
algebra, O(N m^2 p), with no Python loop over candidates (the batched m x m algebra is a few
contiguous length-N vector operations per matrix entry).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: largest condition number of ``R = I - P_k`` for which a removal or exchange update is trusted:
#: the updates' relative round-off grows like 1e-16 cond(R) (Higham, *Accuracy and Stability of
#: Numerical Algorithms*, 2nd ed., §7), here <= 1e-10, far below the selections' relative tolerance
#: (1e-6); above it (the configuration is nearly alone in exciting a direction) the caller evaluates
#: those designs directly
MAX_CONDITION = 1e6


def _cofactors3(S: np.ndarray) -> tuple[np.ndarray, ...]:
    """Cofactors ``c00, c01, c02, c11, c12, c22`` and the determinant of stacks of symmetric 3 x 3
    matrices (3, 3, N)."""
    c00 = S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1]
    c01 = S[0, 2] * S[2, 1] - S[0, 1] * S[2, 2]
    c02 = S[0, 1] * S[1, 2] - S[0, 2] * S[1, 1]
    c11 = S[0, 0] * S[2, 2] - S[0, 2] * S[2, 0]
    c12 = S[0, 2] * S[1, 0] - S[0, 0] * S[1, 2]
    c22 = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    det = S[0, 0] * c00 + S[1, 0] * c01 + S[2, 0] * c02
    return c00, c01, c02, c11, c12, c22, det


def trace_solve(S: np.ndarray, T: np.ndarray) -> np.ndarray:
    """``trace(S_n^-1 T_n)`` for stacks of symmetric m x m matrices (m, m, N); explicit cofactors
    for m <= 3 (no per-matrix LAPACK call), inf where ``S_n`` is singular."""
    m = S.shape[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        if m == 1:
            out = T[0, 0] / S[0, 0]
        elif m == 2:
            det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
            out = (S[1, 1] * T[0, 0] + S[0, 0] * T[1, 1] - S[0, 1] * T[1, 0] - S[1, 0] * T[0, 1]) / det
        elif m == 3:
            c00, c01, c02, c11, c12, c22, det = _cofactors3(S)
            out = (c00 * T[0, 0] + c11 * T[1, 1] + c22 * T[2, 2]
                   + c01 * (T[1, 0] + T[0, 1]) + c02 * (T[2, 0] + T[0, 2]) + c12 * (T[2, 1] + T[1, 2])) / det
        else:
            Sn, Tn = S.transpose(2, 0, 1), T.transpose(2, 0, 1)
            out = np.full(S.shape[2], np.inf)
            ok = np.linalg.cond(Sn) < 1e14
            out[ok] = np.trace(np.linalg.solve(Sn[ok], Tn[ok]), axis1=1, axis2=2)
    return np.where(np.isfinite(out), out, np.inf)


def logdet(S: np.ndarray) -> np.ndarray:
    """``log det S_n`` for stacks of symmetric m x m matrices (m, m, N); -inf where ``det <= 0``."""
    m = S.shape[0]
    if m == 1:
        det = S[0, 0]
    elif m == 2:
        det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    elif m == 3:
        det = _cofactors3(S)[-1]
    else:
        sign, ld = np.linalg.slogdet(S.transpose(2, 0, 1))
        return np.where(sign > 0, ld, -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(det > 0, np.log(np.maximum(det, 1e-300)), -np.inf)


def _gram(U: np.ndarray, V: np.ndarray | None = None) -> np.ndarray:
    """``X[a, b, n] = sum_g U[g, a, n] V[g, b, n]`` for stacks (q, m, N) whose products are
    symmetric (V = U, or ``U_n^T V_n`` symmetric); with ``V = None`` the Gram matrices of U. The
    upper triangle is computed and mirrored."""
    V = U if V is None else V
    m = U.shape[1]
    out = np.empty((m, m, U.shape[2]))
    for a in range(m):
        for b in range(a, m):
            out[a, b] = out[b, a] = np.einsum("gn,gn->n", U[:, a], V[:, b])
    return out


def _sym_pair(U: np.ndarray, V: np.ndarray) -> np.ndarray:
    """``U_n^T V_n + V_n^T U_n`` of stacks (q, m, N) (symmetric by construction)."""
    m = U.shape[1]
    out = np.empty((m, m, U.shape[2]))
    for a in range(m):
        for b in range(a, m):
            out[a, b] = out[b, a] = (np.einsum("gn,gn->n", U[:, a], V[:, b])
                                     + np.einsum("gn,gn->n", V[:, a], U[:, b]))
    return out


def _plus_identity(S: np.ndarray) -> np.ndarray:
    """``S_n + I`` in place for a stack (m, m, N)."""
    for a in range(S.shape[0]):
        S[a, a] += 1.0
    return S


class LowRankCache:
    """``M^-1`` and ``P_j = G_j M^-1 G_j^T`` of all candidates at one regular ``M``.

    Candidate stacks are parameter-major, ``Gq[i, a, n] = G_n[a, i]`` (p, m, N): a product with a
    p x q matrix is one matrix product over all candidates; an m x m result is stored ``X[a, b, n]``.
    """

    def __init__(self, Gq: np.ndarray, M: np.ndarray) -> None:
        self.Gq = Gq
        p, self.m, self.N = Gq.shape
        Minv = np.linalg.inv(M)
        self.Minv = 0.5 * (Minv + Minv.T)
        self.Hq = self.products(self.Minv)                                # (M^-1 G_n^T)[i, a]
        self.P = _gram(self.Hq, Gq)

    def products(self, Z: np.ndarray) -> np.ndarray:
        """``U[g, a, n] = (G_n Z)[a, g]`` (q, m, N) for every candidate: one (q x p) @ (p x m N)
        product."""
        return (Z.T @ self.Gq.reshape(self.Gq.shape[0], -1)).reshape(Z.shape[1], self.m, self.N)

    def removal(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Eigenvalues ``r`` of ``R = I - P_k``, ``L = Q diag(r)^-1/2`` (``R^-1 = L L^T``) and
        ``a L = M^-1 G_k^T L`` (p, m); None when the update is not trusted (:data:`MAX_CONDITION`)."""
        r, Q = np.linalg.eigh(np.eye(self.m) - self.P[:, :, k])
        if not (r[0] > 0 and r[-1] < MAX_CONDITION * r[0]):
            return None
        L = Q / np.sqrt(r)
        return r, L, self.Minv @ (self.Gq[:, :, k] @ L)

    def removal_ok(self, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``R_k = I - P_k`` (len(sel), m, m) of the configurations ``sel`` and where it is trusted."""
        R = np.eye(self.m)[None] - self.P[:, :, sel].transpose(2, 0, 1)
        r = np.linalg.eigvalsh(R)
        return R, (r[:, 0] > 0) & (r[:, -1] < MAX_CONDITION * r[:, 0])

    def trusted_removals(self, sel: np.ndarray, value_of: Callable[[np.ndarray, np.ndarray], np.ndarray]
                         ) -> np.ndarray:
        """``value_of(R_k, trusted mask)`` for the trusted removals of ``sel``, NaN elsewhere."""
        R, ok = self.removal_ok(sel)
        out = np.full(len(sel), np.nan)
        if ok.any():
            out[ok] = value_of(R[ok], ok)
        return out


class TraceCache(LowRankCache):
    """``trace(W M^-1)`` after adding, removing or exchanging configurations (module docstring).

    The exchange uses ``R^-1 = L L^T``, ``u_j = c_j L = G_j (a L)``, ``v_j = d_j L = G_j (M^-1 W a L)``
    (one product of all candidates with the p x 2m matrix ``[a L, M^-1 W a L]``) and
    ``T'_k = L^T T_k L``: ``P'_j = P_j + u_j u_j^T``, ``T'_j = T_j + u_j w_j^T + w_j u_j^T`` with
    ``w_j = v_j + u_j T'_k / 2``.
    """

    def __init__(self, Gq: np.ndarray, W: np.ndarray, M: np.ndarray) -> None:
        super().__init__(Gq, M)
        p = Gq.shape[0]
        self.W = W
        self.value = float(np.sum(self.Minv * W.T))                       # trace(W M^-1)
        HWq = (W.T @ self.Hq.reshape(p, -1)).reshape(Gq.shape)           # (G_n M^-1 W)^T
        self.T = _gram(HWq, self.Hq)                                      # G M^-1 W M^-1 G^T
        del self.Hq

    def add_values(self) -> np.ndarray:
        """Criterion after adding each candidate (N,)."""
        return self.value - trace_solve(_plus_identity(self.P.copy()), self.T)

    def remove_values(self, sel: np.ndarray) -> np.ndarray:
        """Criterion after removing each configuration of ``sel`` (NaN where the update is not
        trusted, :data:`MAX_CONDITION`)."""
        return self.trusted_removals(sel, lambda R, ok: self.value + np.trace(
            np.linalg.solve(R, self.T[:, :, sel].transpose(2, 0, 1)[ok]), axis1=1, axis2=2))

    def exchange_values(self, k: int) -> np.ndarray | None:
        """Criterion after removing selected ``k`` and adding each candidate (N,); None when
        the update is not trusted (:data:`MAX_CONDITION`)."""
        rem = self.removal(k)
        if rem is None:
            return None
        _, L, aL = rem
        m = self.m
        Tk = L.T @ self.T[:, :, k] @ L
        UV = self.products(np.hstack([aL, self.Minv @ (self.W @ aL)]))
        u, w = UV[:m], UV[m:]
        w += 0.5 * (Tk @ u.reshape(m, -1)).reshape(u.shape)
        S = _plus_identity(_gram(u))
        S += self.P
        value_k = self.value + float(np.trace(Tk))                        # trace(R^-1 T_k)
        return value_k - trace_solve(S, self.T + _sym_pair(u, w))


class LogDetCache(LowRankCache):
    """``log det M`` after adding, removing or exchanging configurations (module docstring)."""

    def __init__(self, Gq: np.ndarray, M: np.ndarray) -> None:
        super().__init__(Gq, M)
        del self.Hq
        self.value = float(np.linalg.slogdet(M)[1])

    def add_values(self) -> np.ndarray:
        """``log det`` after adding each candidate (N,)."""
        return self.value + logdet(_plus_identity(self.P.copy()))

    def remove_values(self, sel: np.ndarray) -> np.ndarray:
        """``log det`` after removing each configuration of ``sel`` (NaN where the update is not
        trusted, :data:`MAX_CONDITION`)."""
        return self.trusted_removals(sel, lambda R, ok: self.value + logdet(R.transpose(1, 2, 0)))

    def exchange_values(self, k: int) -> np.ndarray | None:
        """``log det`` after removing selected ``k`` and adding each candidate (N,); None when
        the update is not trusted (:data:`MAX_CONDITION`)."""
        rem = self.removal(k)
        if rem is None:
            return None
        r, _, aL = rem
        S = _plus_identity(_gram(self.products(aL)))
        S += self.P
        return self.value + float(np.sum(np.log(r))) + logdet(S)
