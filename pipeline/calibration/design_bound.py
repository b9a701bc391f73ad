"""How good can any calibration design be? A certified lower bound on the V criterion.

Setting (:mod:`pipeline.calibration.indices`, :mod:`pipeline.calibration.task_space`): candidate
``i`` contributes the whitened Jacobian block ``G_i`` (m x p, rows divided by the tracker sigma); an
exact design ``S`` of ``n`` configurations has the information matrix ``M_S = sum_{i in S} G_i^T G_i``
and the criterion ``V(S) = trace(W M_S^-1)`` (``W = J_w^T J_w / n_w`` the working-region weighting).

**Approximate (continuous) design** (Kiefer 1959; Atkinson, Donev & Tobias, *Optimum Experimental
Designs, with SAS*, Oxford 2007, ch. 9-10): weights ``w`` on the simplex of the candidates,
``M(w) = sum_i w_i G_i^T G_i`` and

    V*  = min_w  V(w),   V(w) = trace(W M(w)^-1).

**Bound for every exact design.** An exact ``n``-point design ``S`` (distinct candidates or repeats)
is the approximate design with weights ``1/n`` on its points, ``M_S = n M(w_S)``, so

    V(S) = trace(W M(w_S)^-1) / n  >=  V* / n       for every n-configuration design S.

**Certificate** (equivalence theorem of Kiefer & Wolfowitz 1960 in the form for linear criteria,
Atkinson et al. §10.6; Fedorov 1972 §2.9). With ``d_i(w) = trace(G_i M^-1 W M^-1 G_i^T)`` (``-d_i``
is the derivative of ``V`` in ``w_i``) and ``sum_i w_i d_i = V(w)``: ``w`` is optimal iff
``max_i d_i(w) = V(w)``. For *any* ``w`` and any design ``xi``, Cauchy-Schwarz on
``trace(L^T M^-1 L)`` (``W = L L^T``) gives ``V(w)^2 <= trace(M^-1 W M^-1 M(xi)) V(xi) <= max_i d_i V(xi)``:

    V* >= V(w)^2 / max_i d_i(w),

a rigorous lower bound from whatever weights the algorithm stops at, within a factor ``1 + tol`` of
``V*`` once ``max_i d_i <= V(w) (1 + tol)``.

The bound covers every design drawn from the candidate pool; configurations outside the pool are
not covered (a larger pool can only lower ``V*``; the benchmark ``bench_design_bound.py`` shows by
how much).

**Algorithm**: the multiplicative algorithm ``w_i <- w_i (d_i / V)^lambda``, normalised, from
uniform weights (Silvey, Titterington & Torsney 1978, *Commun. Stat. Theory Methods* 7, 1379-1389;
Yu 2010, "Monotonic convergence of a general algorithm for computing optimal designs", *Ann. Stat.*
38, 1593-1606, proves monotone convergence for a class of criteria including A-optimality with
``lambda = 1/2``, used here). The linear criterion with a singular ``W`` is checked rather than
assumed: an iteration that increases ``V`` raises ``RuntimeError``; the bound above does not need
convergence.

**Per-robot spread** (linearised model): the estimation error ``delta = theta_hat - theta ~ N(0, C)``,
``C = M_S^-1``, puts the working-region RMS at ``sqrt(delta^T W delta)``, a root of a weighted sum of
chi-square(1) variables with weights ``eig(L_C^T W L_C)`` (``C = L_C L_C^T``); its square has mean
``V(S)``. :func:`rms_samples` draws it; :func:`probability_below` compares two designs measured with
independent noise (each design its own tracker readings, as in the ``calib-design`` study).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from pipeline.calibration import candidates as cd
from pipeline.core.blas import single_thread_blas
from pipeline.robot.model import RobotModel


@dataclass
class ApproximateDesign:
    """Weights of the optimal approximate design and its certificate."""

    weights: np.ndarray             # (N,) on the simplex
    value: float                    # V(w) = trace(W M(w)^-1) (per unit weight: V_n = value / n)
    max_derivative: float           # max_i d_i(w)
    lower_bound: float              # V* >= value^2 / max_derivative (best over the iterations)
    iterations: int
    converged: bool                 # max_i d_i <= value (1 + tol)
    tol: float

    @property
    def gap(self) -> float:
        """Relative gap ``max_i d_i / V(w) - 1`` of the equivalence theorem (0 at the optimum)."""
        return self.max_derivative / self.value - 1.0

    def support(self, threshold: float = 1e-3) -> np.ndarray:
        """Candidates with a weight above ``threshold`` times the largest one, heaviest first."""
        w = self.weights
        idx = np.flatnonzero(w > threshold * w.max())
        return idx[np.argsort(-w[idx])]

    def exact_bound(self, n: int) -> float:
        """Lower bound on ``V`` of every exact design of ``n`` configurations: ``V* / n``."""
        return self.lower_bound / n


def information(G: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``M(w) = sum_i w_i G_i^T G_i`` for blocks ``G`` (N, m, p)."""
    Gs = G * np.sqrt(np.clip(w, 0.0, None))[:, None, None]
    Gs = Gs.reshape(-1, G.shape[2])
    return Gs.T @ Gs


def criterion(W: np.ndarray, M: np.ndarray) -> float:
    """``trace(W M^-1)`` (inf for a singular ``M``)."""
    ev = np.linalg.eigvalsh(M)
    if ev[0] <= 1e-12 * max(ev[-1], 1e-300):
        return math.inf
    return float(np.trace(np.linalg.solve(M, W)))


def exact_information(G: np.ndarray, selected: np.ndarray) -> np.ndarray:
    """``M_S = sum_{i in S} G_i^T G_i`` of the exact design ``selected`` (indices into the candidates)."""
    Gs = G[np.asarray(selected)].reshape(-1, G.shape[2])
    return Gs.T @ Gs


def design_value(G: np.ndarray, W: np.ndarray, selected: np.ndarray) -> float:
    """``V`` of the exact design ``selected``."""
    return criterion(W, exact_information(G, selected))


def derivatives(G: np.ndarray, W: np.ndarray, M: np.ndarray) -> tuple[float, np.ndarray]:
    """``V = trace(W M^-1)`` and ``d_i = trace(G_i M^-1 W M^-1 G_i^T)`` for every candidate."""
    c = cho_factor(M)
    Minv_W = cho_solve(c, W)
    B = cho_solve(c, Minv_W.T)                  # M^-1 W M^-1
    B = 0.5 * (B + B.T)
    N, m, p = G.shape
    G2 = G.reshape(-1, p)
    d = np.einsum("ij,ij->i", G2 @ B, G2).reshape(N, m).sum(axis=1)
    return float(np.trace(Minv_W)), d


def optimal_approximate_design(G: np.ndarray, W: np.ndarray, tol: float = 1e-3, max_iterations: int = 20000,
                               power: float = 0.5, weights: np.ndarray | None = None) -> ApproximateDesign:
    """Minimise ``V(w)`` over the simplex by the multiplicative algorithm (module docstring) until
    the equivalence-theorem gap ``max_i d_i / V - 1`` is at most ``tol``.

    Start: uniform weights (or ``weights``). Every iterate gives the valid bound
    ``V(w)^2 / max_i d_i``; the best one is returned. Raises ``ValueError`` for a candidate set whose
    uniform design is singular (then no design of the pool identifies the parameters)."""
    with single_thread_blas():      # many small products: threads only add overhead
        return _multiplicative(np.asarray(G, float), np.asarray(W, float), tol, max_iterations, power, weights)


def _multiplicative(G: np.ndarray, W: np.ndarray, tol: float, max_iterations: int, power: float,
                    weights: np.ndarray | None) -> ApproximateDesign:
    N = G.shape[0]
    w = np.full(N, 1.0 / N) if weights is None else np.asarray(weights, float) / np.sum(weights)
    M = information(G, w)
    if not np.isfinite(criterion(W, M)):
        raise ValueError("the candidates cannot make the information matrix regular")
    best_bound, prev = 0.0, math.inf
    it, converged = 0, False
    V, d = derivatives(G, W, M)
    while True:
        dmax = float(d.max())
        best_bound = max(best_bound, V * V / dmax)
        if V > prev * (1 + 1e-9):
            raise RuntimeError(f"multiplicative algorithm not monotone at iteration {it}: {V} > {prev}")
        prev = V
        if dmax <= V * (1.0 + tol):
            converged = True
            break
        if it >= max_iterations:
            break
        w = w * (np.clip(d, 0.0, None) / V) ** power
        w /= w.sum()
        it += 1
        M = information(G, w)
        V, d = derivatives(G, W, M)
    return ApproximateDesign(w, V, float(d.max()), best_bound, it, converged, tol)


def configurations_to_reach(design: ApproximateDesign, target_value: float) -> int:
    """Fewest configurations ``n`` for which the bound ``V* / n`` is at most ``target_value``
    (no exact design with fewer reaches it)."""
    return max(1, math.ceil(design.lower_bound / target_value - 1e-12))


def rms_samples(C: np.ndarray, W: np.ndarray, n_samples: int, rng: np.random.Generator) -> np.ndarray:
    """Draws of the working-region RMS ``sqrt(delta^T W delta)``, ``delta ~ N(0, C)`` (module
    docstring): ``sqrt(sum_k lambda_k z_k^2)``, ``lambda = eig(L^T W L)``, ``z ~ N(0, 1)``."""
    L = np.linalg.cholesky(0.5 * (C + C.T))
    lam = np.clip(np.linalg.eigvalsh(L.T @ W @ L), 0.0, None)
    z = rng.standard_normal((n_samples, lam.size))
    return np.sqrt((z * z) @ lam)


def probability_below(rms_a: np.ndarray, rms_b: np.ndarray, factor: float) -> float:
    """``P(RMS_a <= factor RMS_b)`` for independent draws (paired by index)."""
    k = min(len(rms_a), len(rms_b))
    return float(np.mean(rms_a[:k] <= factor * rms_b[:k]))


def rms_scale_needed(rms_a: np.ndarray, rms_b: np.ndarray, factor: float, n_seeds: int,
                     p_all: float = 0.5) -> float:
    """Largest ``c`` with ``P(c RMS_a <= factor RMS_b) >= p_all^(1/n_seeds)``: the multiple of design
    ``a``'s RMS (its covariance times ``c^2``) a design needs to beat ``b`` by ``1 - factor`` on all
    ``n_seeds`` independent seeds with probability ``p_all``."""
    k = min(len(rms_a), len(rms_b))
    return float(np.quantile(factor * rms_b[:k] / rms_a[:k], 1.0 - p_all ** (1.0 / n_seeds)))


def reflector_jacobian(robot: RobotModel, Qw: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Stacked Jacobian rows ``(3 n_w, p)`` of the reflector position in the tracker frame at the
    working configurations ``Qw`` (nominal model and tracker pose) wrt the identifiable parameters
    (geometric basis ``(7 nq + 21, p)``)."""
    chain = cd.chain_from_robot(robot)
    P = np.asarray(basis, float)
    if P.shape[0] != 7 * chain.nq + 21:
        raise ValueError("reflector_weight needs a geometric parameter basis (no compliance rows)")
    _, J = cd.nominal_jacobian(chain, Qw, robot.tracker.transform_tracker_to_base)
    return (J @ P).reshape(-1, P.shape[1])


def reflector_weight(robot: RobotModel, Qw: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Weighting of the ``calib-design`` study's held-out figure: the reflector position in the
    tracker frame at the working configurations ``Qw``, ``W = sum_w J_w^T J_w / n_w`` with ``J_w``
    the rows of :func:`reflector_jacobian`."""
    Jp = reflector_jacobian(robot, Qw, basis)
    return Jp.T @ Jp / len(Qw)
