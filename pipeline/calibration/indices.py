"""Observability indices of a calibration experiment.

Conventions. A configuration k contributes a whitened Jacobian block ``G_k`` (m x p, usually m = 3
reflector coordinates, rows divided by the measurement sigma), so the stacked Jacobian is
``J = [G_1; ...; G_n]`` and the information matrix is ``M = J^T J = sum_k G_k^T G_k``
(paper 004 eq. 14: ``Lambda = Theta^T Theta``). The parameter covariance is ``C = M^-1``.

Indices (singular values ``s_1 >= ... >= s_p`` of J, ``s_i = sqrt(eig_i(M))``):

- ``O1`` Borm-Menq: ``(s_1 ... s_p)^(1/p) / sqrt(n)`` (paper 003 eq. 30).
- ``O2`` Driels-Pathre: ``s_p / s_1`` (paper 003 eq. 31).
- ``O3`` minimum singular value ``s_p`` (paper 003 eq. 32; paper 004 §3.3.1 uses
  ``B = sigma_min(Lambda) = s_p^2``, a monotone transform, so both select the same sets).
- ``O4`` noise amplification (Nahvi-Hollerbach): ``s_p^2 / s_1``.
- ``O5`` Sun-Hollerbach: ``1 / sum_i (1 / s_i)``.
- ``D``: ``det(M)^(1/p)``; ``A``: ``trace(M^-1)`` (minimised); ``E``: ``lambda_min(M)``.
- ``Od`` (paper 003 §3.1.1): ``1 / var(d_kNN)``, d_kNN the mean distance of each measured point
  to its K nearest neighbours.
- ``Oc`` (paper 003 eq. 35): ``(2/pi) * mean(atan O1, atan O3, atan Od)`` in [0, 1].
- ``tcp_A`` (paper 000 §2.3, eq. 24a with ``C_s``): ``trace(J_w C J_w^T) / n_w``, the mean variance
  of the TCP position over working configurations (J_w: TCP-position Jacobian rows of the working
  configurations wrt the same parameters), minimised; ``tcp_A_mixed`` adds
  ``mix_weight * trace(C) / p`` (the parameter-covariance A-criterion, paper 000 eq. 25).
- ``V`` (task-space V-/I-optimality, Atkinson, Donev & Tobias, *Optimum Experimental Designs, with
  SAS*, 2007, §10.6; the continuous form of paper 000's KPI): ``trace(W C)`` with
  ``W = sum_w J_w^T J_w / n_w`` over *many* working configurations of the working region (the
  ISO 9283 cube, a box or the user's poses; :mod:`pipeline.calibration.task_space`), i.e. the
  predicted TCP position variance averaged over where the arm works, minimised. Same algebra as
  ``tcp_A`` (rank-one / Sherman-Morrison updates), different working set.

Every index has a *score* (larger is better) used by the selection algorithms:
``score = value`` for maximised indices and ``-value`` for minimised ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MAXIMISED = ("O1", "O2", "O3", "O4", "O5", "D", "E", "Od", "Oc")
MINIMISED = ("A", "tcp_A", "tcp_A_mixed", "V")
#: indices of the form trace(W M^-1) with W from TCP Jacobians at working configurations
TASK_INDICES = ("tcp_A", "tcp_A_mixed", "V")
#: indices of the form trace(W M^-1) (Sherman-Morrison updates, gradient design)
TRACE_INDICES = ("A",) + TASK_INDICES
INDEX_NAMES = MAXIMISED + MINIMISED

_REL_EIG_TOL = 1e-12


@dataclass
class IndexSpec:
    """Which index to use and the data some indices need.

    ``working_jacobian``: (r, p) stacked TCP-position Jacobian rows at the working configurations
    (needed by ``tcp_A*``); ``n_working`` the number of working configurations.
    ``knn``: K of ``Od``. ``mix_weight``: weight of ``trace(C)/p`` in ``tcp_A_mixed``.
    """

    name: str = "O3"
    working_jacobian: np.ndarray | None = None
    n_working: int = 1
    knn: int = 3
    mix_weight: float = 1.0
    #: ``A`` only: diagonal weights of the parameters (paper 000 eq. 25 projection P onto a subset,
    #: e.g. the robot's own parameters without the tracker pose); None = all ones
    parameter_weights: np.ndarray | None = None
    #: ``Oc`` only: O1 and O3 are multiplied by ``oc_jacobian_scale`` and Od by ``oc_od_scale`` before
    #: the arctan normalisation (paper 003 eq. 34 is unit dependent: e.g. the tracker sigma in m
    #: un-whitens the Jacobian, 1e-6 turns Od from 1/m^2 into 1/mm^2)
    oc_jacobian_scale: float = 1.0
    oc_od_scale: float = 1.0
    _W: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.name not in INDEX_NAMES:
            raise ValueError(f"unknown observability index {self.name!r}; choose from {INDEX_NAMES}")
        if self.name in TASK_INDICES:
            if self.working_jacobian is None:
                raise ValueError(f"index {self.name} needs working_jacobian")

    @property
    def minimised(self) -> bool:
        return self.name in MINIMISED

    @property
    def needs_positions(self) -> bool:
        return self.name in ("Od", "Oc")

    def weight_matrix(self, p: int) -> np.ndarray:
        """W with ``index = trace(W M^-1)`` for the A-type indices."""
        if self._W is None or self._W.shape[0] != p:
            if self.name == "A":
                W = np.eye(p) if self.parameter_weights is None else np.diag(np.asarray(self.parameter_weights, float))
            else:
                Jw = np.asarray(self.working_jacobian, float)
                W = Jw.T @ Jw / max(self.n_working, 1)
                if self.name == "tcp_A_mixed":
                    W = W + self.mix_weight * np.eye(p) / p
            self._W = W
        return self._W


def singular_values(M: np.ndarray) -> np.ndarray:
    """Singular values of J from ``M = J^T J`` (descending; batched over leading axes)."""
    ev = np.linalg.eigvalsh(M)
    return np.sqrt(np.clip(ev[..., ::-1], 0.0, None))


def od_index(positions: np.ndarray, knn: int = 3) -> float:
    """Paper 003 §3.1.1: ``Od = 1 / var(mean distance to the K nearest neighbours)``."""
    P = np.asarray(positions, float)
    n = P.shape[0]
    if n < 2:
        return 0.0
    k = min(knn, n - 1)
    D = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=-1)
    Ds = np.sort(D, axis=1)[:, 1 : k + 1]
    var = float(np.var(Ds.mean(axis=1)))
    return 1.0 / var if var > 0 else float("inf")


def od_index_batch(base: np.ndarray, extra: np.ndarray, knn: int = 3) -> np.ndarray:
    """Od of ``base ∪ {extra_j}`` for each row j of ``extra`` (vectorised)."""
    base = np.asarray(base, float)
    extra = np.atleast_2d(np.asarray(extra, float))
    n = base.shape[0] + 1
    k = min(knn, n - 1)
    Dbb = np.linalg.norm(base[:, None, :] - base[None, :, :], axis=-1)  # (b,b)
    Dbe = np.linalg.norm(base[None, :, :] - extra[:, None, :], axis=-1)  # (N,b)
    N = extra.shape[0]
    out = np.empty(N)
    # rows of the base points: their sorted neighbour lists plus the new distance
    Dbb_s = np.sort(Dbb, axis=1)[:, 1 : k + 1]  # (b,k) without self
    for s in range(0, N, 2048):
        e = slice(s, s + 2048)
        rows = np.concatenate([np.broadcast_to(Dbb_s, (Dbe[e].shape[0],) + Dbb_s.shape),
                               Dbe[e][:, :, None]], axis=2)
        rows = np.sort(rows, axis=2)[:, :, :k].mean(axis=2)  # (B,b)
        new = np.sort(Dbe[e], axis=1)[:, :k].mean(axis=1)  # (B,)
        allk = np.concatenate([rows, new[:, None]], axis=1)
        var = np.var(allk, axis=1)
        out[e] = np.where(var > 0, 1.0 / np.maximum(var, 1e-300), np.inf)
    return out


def oc_combine(spec: IndexSpec, o1, o3, od):
    """Paper 003 eq. 35: ``Oc = (2/pi) (atan O1 + atan O3 + atan Od) / 3`` (with the spec's unit scales)."""
    a, b = spec.oc_jacobian_scale, spec.oc_od_scale
    return 2.0 / np.pi * (np.arctan(a * o1) + np.arctan(a * o3) + np.arctan(b * od)) / 3.0


def _values_from_eigs(name: str, ev: np.ndarray, n: int) -> np.ndarray:
    """Index values from ascending eigenvalues of M (batched over leading axes)."""
    p = ev.shape[-1]
    lam_max = ev[..., -1]
    tol = _REL_EIG_TOL * np.maximum(lam_max, 1e-300)
    regular = ev[..., 0] > tol
    ev_c = np.clip(ev, 1e-300, None)
    s = np.sqrt(ev_c)
    if name == "O1":
        v = np.exp(np.mean(np.log(s), axis=-1)) / np.sqrt(max(n, 1))
    elif name == "O2":
        v = s[..., 0] / s[..., -1]
    elif name in ("O3",):
        v = s[..., 0]
    elif name == "O4":
        v = ev_c[..., 0] / s[..., -1]
    elif name == "O5":
        v = 1.0 / np.sum(1.0 / s, axis=-1)
    elif name == "D":
        v = np.exp(np.mean(np.log(ev_c), axis=-1))
    elif name == "E":
        v = ev_c[..., 0]
    elif name == "A":
        v = np.sum(1.0 / ev_c, axis=-1)
    else:
        raise ValueError(name)
    bad = np.inf if name == "A" else 0.0
    return np.where(regular, v, bad) if p else v


def evaluate(spec: IndexSpec, M: np.ndarray, n: int, positions: np.ndarray | None = None) -> float:
    """Natural value of the index for information matrix ``M`` of ``n`` configurations."""
    M = np.asarray(M, float)
    if spec.name == "Od":
        return od_index(positions, spec.knn)
    ev = np.linalg.eigvalsh(M)
    if spec.name in ("O1", "O2", "O3", "O4", "O5", "D", "E") or (spec.name == "A" and spec.parameter_weights is None):
        return float(_values_from_eigs(spec.name, ev, n))
    if spec.name == "Oc":
        o1 = float(_values_from_eigs("O1", ev, n))
        o3 = float(_values_from_eigs("O3", ev, n))
        od = od_index(positions, spec.knn)
        return float(oc_combine(spec, o1, o3, od))
    # TCP A-criterion
    if ev[0] <= _REL_EIG_TOL * max(ev[-1], 1e-300):
        return float("inf")
    W = spec.weight_matrix(M.shape[0])
    return float(np.trace(np.linalg.solve(M, W)))


def score(spec: IndexSpec, M: np.ndarray, n: int, positions: np.ndarray | None = None) -> float:
    """Larger-is-better version of :func:`evaluate`."""
    v = evaluate(spec, M, n, positions)
    return -v if spec.minimised else v


def scores_of_matrices(spec: IndexSpec, Ms: np.ndarray, n: int,
                       positions_sets: np.ndarray | None = None) -> np.ndarray:
    """Scores of a batch of information matrices (B, p, p), each with ``n`` configurations.

    ``positions_sets`` (B, n, 3) only for Od / Oc.
    """
    Ms = np.asarray(Ms, float)
    B = Ms.shape[0]
    out = np.empty(B)
    for s in range(0, B, 4096):
        e = slice(s, s + 4096)
        if spec.name == "Od":
            out[e] = [od_index(P, spec.knn) for P in positions_sets[e]]
            continue
        ev = np.linalg.eigvalsh(Ms[e])
        if spec.name == "Oc":
            o1 = _values_from_eigs("O1", ev, n)
            o3 = _values_from_eigs("O3", ev, n)
            od = np.array([od_index(P, spec.knn) for P in positions_sets[e]])
            out[e] = oc_combine(spec, o1, o3, od)
        elif spec.name in TASK_INDICES or (spec.name == "A" and spec.parameter_weights is not None):
            W = spec.weight_matrix(Ms.shape[1])
            reg = ev[:, 0] > _REL_EIG_TOL * np.maximum(ev[:, -1], 1e-300)
            v = np.full(ev.shape[0], np.inf)
            if reg.any():
                X = np.linalg.solve(Ms[e][reg], np.broadcast_to(W, (int(reg.sum()),) + W.shape))
                v[reg] = np.trace(X, axis1=1, axis2=2)
            out[e] = -v
        else:
            v = _values_from_eigs(spec.name, ev, n)
            out[e] = -v if spec.minimised else v
    return out


def tcp_covariance(C: np.ndarray, working_jacobian: np.ndarray) -> np.ndarray:
    """Linear error propagation (paper 000 eq. 16): ``C_s = J_w C J_w^T``."""
    Jw = np.asarray(working_jacobian, float)
    return Jw @ C @ Jw.T


def all_indices(M: np.ndarray, n: int, positions: np.ndarray | None = None,
                working_jacobian: np.ndarray | None = None, n_working: int = 1,
                knn: int = 3) -> dict[str, float]:
    """Every index for one design (a report row)."""
    out: dict[str, float] = {}
    for name in INDEX_NAMES:
        if name in ("Od", "Oc") and positions is None:
            continue
        if name in TASK_INDICES and working_jacobian is None:
            continue
        spec = IndexSpec(name, working_jacobian=working_jacobian, n_working=n_working, knn=knn)
        out[name] = evaluate(spec, M, n, positions)
    return out
