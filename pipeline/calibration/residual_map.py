"""Fitting the non-geometric residual map (:class:`pipeline.robot.residual_map.ResidualMap`).

The base-frame position residuals ``d_k = R_tb (y_k - h(q_k, x))`` of a calibrated model at its
training poses are regressed on the joint angles by a Gaussian process with a squared-exponential
kernel plus white noise, ``K = s^2 R(l) + s_n^2 I`` with ``R_ij = exp(-|q_i - q_j|^2 / (2 l^2))``;
the three axes share the kernel, and its hyperparameters maximise the summed log marginal
likelihood (Rasmussen & Williams, *Gaussian Processes for Machine Learning*, MIT Press 2006, §5.4.1)

    log p(D) = -1/2 sum_i |u_i^T D|^2 / (s^2 lambda_i + s_n^2) - 3/2 sum_i log(s^2 lambda_i + s_n^2) - const,

written with the eigendecomposition ``R(l) = U diag(lambda) U^T`` (one decomposition per length
scale; ``s`` and ``s_n`` are then found in O(n) per evaluation, L-BFGS-B on their logarithms). The
length scale is searched on a logarithmic grid over its bounds and refined by bounded Brent
minimisation around the best grid point (a global search in the one parameter whose likelihood
is multimodal). On more than :data:`MAX_HYPERPARAMETER_POSES` poses the hyperparameters are
estimated on that many poses drawn from the seed (the subset-of-data estimate, ibid. §8.3.1); the
posterior is then conditioned on every pose (one Cholesky factorisation).

The white-noise level absorbs the readings' noise, so the map interpolates only what repeats over
neighbouring poses; it is bounded below by the noise the calibration knows the readings to have
(``noise_floor_m``: the sensor's and the arm's repeatability, RMS over the poses), so the map never
claims to know the residual at a calibration pose better than it was measured. Its mean is tapered
outside the calibration poses (:mod:`pipeline.robot.residual_map`, support radius
:func:`support_radius_rad`): beyond them the calibrated model falls back to the geometric one and
the stated uncertainty widens to the prior's. Whether the map helps is for cross-validation to say
(:mod:`pipeline.calibration.model_selection`, folds grouped in joint space); a few dozen poses in
six joint angles seldom carry enough of it.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from pipeline.robot.residual_map import ResidualMap

#: hyperparameter bounds: signal std 1 µm .. 10 mm, length 0.05 .. 20 rad, noise std 1 µm .. 10 mm
SIGNAL_STD_BOUNDS_M = (1e-6, 1e-2)
LENGTH_SCALE_BOUNDS_RAD = (0.05, 20.0)
NOISE_STD_BOUNDS_M = (1e-6, 1e-2)
#: length scales of the logarithmic grid the search starts from
LENGTH_SCALE_GRID = 9
#: poses on which the hyperparameters are estimated at most (module docstring)
MAX_HYPERPARAMETER_POSES = 300
#: support radius of the map's taper in largest nearest-neighbour distances among its poses
SUPPORT_RADIUS_NEIGHBOUR_DISTANCES = 2.0


def restart_seed(rng: np.random.Generator) -> int:
    """The seed of a fit (its subset of poses for the hyperparameters): one draw from ``rng``."""
    return int(rng.integers(2 ** 31 - 1))


def support_radius_rad(Q: np.ndarray) -> float:
    """Support radius of a map over the configurations ``Q`` (n, nq):
    :data:`SUPPORT_RADIUS_NEIGHBOUR_DISTANCES` times the largest distance from a pose to its nearest
    neighbour (every pose has another within it; a query farther than a few radii from every pose
    lies outside what the poses cover)."""
    Q = np.asarray(Q, float)
    if len(Q) < 2:
        return float(LENGTH_SCALE_BOUNDS_RAD[0])
    d2 = _squared_distances(Q)
    np.fill_diagonal(d2, np.inf)
    return float(max(SUPPORT_RADIUS_NEIGHBOUR_DISTANCES * np.sqrt(d2.min(1).max()), LENGTH_SCALE_BOUNDS_RAD[0]))


def _squared_distances(Q: np.ndarray) -> np.ndarray:
    sq = np.einsum("ij,ij->i", Q, Q)
    return np.maximum(sq[:, None] + sq[None, :] - 2.0 * Q @ Q.T, 0.0)


class _Evidence:
    """Negative log marginal likelihood of ``D`` over the poses with squared distances ``d2``."""

    def __init__(self, d2: np.ndarray, D: np.ndarray, noise_bounds_m: tuple[float, float]) -> None:
        self.d2, self.D = d2, D
        self.log_bounds: list[tuple[float, float]] = [
            (2.0 * math.log(SIGNAL_STD_BOUNDS_M[0]), 2.0 * math.log(SIGNAL_STD_BOUNDS_M[1])),
            (2.0 * math.log(noise_bounds_m[0]), 2.0 * math.log(noise_bounds_m[1]))]
        rms = max(float(np.sqrt(np.mean(D ** 2))), 1e-300)
        self.start = np.array([min(max(2.0 * math.log(rms), lo), hi) if k == 0 else
                               min(max(2.0 * math.log(rms / 2), lo), hi)
                               for k, (lo, hi) in enumerate(self.log_bounds)])

    def at_length(self, length_rad: float) -> tuple[float, np.ndarray]:
        """Minimum over ``(log s^2, log s_n^2)`` at one length scale, and the minimiser."""
        lam, U = np.linalg.eigh(np.exp(-0.5 * self.d2 / length_rad ** 2))
        lam = np.maximum(lam, 0.0)
        proj = np.sum((U.T @ self.D) ** 2, axis=1)       # |u_i^T D|^2 over the three axes
        k = self.D.shape[1]

        def nll(z: np.ndarray) -> tuple[float, np.ndarray]:
            a, b = math.exp(z[0]), math.exp(z[1])
            v = a * lam + b
            f = 0.5 * float(np.sum(proj / v)) + 0.5 * k * float(np.sum(np.log(v)))
            dv = 0.5 * (k / v - proj / v ** 2)                # d f / d v_i
            return f, np.array([float(np.sum(dv * lam)) * a, float(np.sum(dv)) * b])

        sol = minimize(nll, self.start, jac=True, method="L-BFGS-B", bounds=self.log_bounds)
        return float(sol.fun), sol.x


def _hyperparameters(Q: np.ndarray, D: np.ndarray, noise_bounds_m: tuple[float, float]) -> tuple[float, float, float]:
    """``(l, s, s_n)`` maximising the marginal likelihood (module docstring)."""
    ev = _Evidence(_squared_distances(Q), D, noise_bounds_m)
    lo, hi = (math.log(b) for b in LENGTH_SCALE_BOUNDS_RAD)
    grid = np.linspace(lo, hi, LENGTH_SCALE_GRID)
    values = [ev.at_length(math.exp(g))[0] for g in grid]
    i = int(np.argmin(values))
    bracket = (grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)])
    sol = minimize_scalar(lambda g: ev.at_length(math.exp(g))[0], bounds=bracket, method="bounded",
                          options={"xatol": 1e-2})
    log_l = float(sol.x) if float(sol.fun) < values[i] else float(grid[i])
    _, z = ev.at_length(math.exp(log_l))
    return math.exp(log_l), math.exp(0.5 * z[0]), math.exp(0.5 * z[1])


def fit_residual_map(Q: np.ndarray, residuals_base_m: np.ndarray, rng: np.random.Generator | int,
                     noise_floor_m: float = 0.0) -> ResidualMap:
    """GP posterior of ``residuals_base_m`` (n, 3) over the configurations ``Q`` (n, nq); the
    hyperparameters' subset of poses (more than :data:`MAX_HYPERPARAMETER_POSES`) from the seed
    ``rng`` or one drawn from it (:func:`restart_seed`); the noise level at least ``noise_floor_m``
    (module docstring)."""
    seed = rng if isinstance(rng, int) else restart_seed(rng)
    Q = np.asarray(Q, float)
    D = np.asarray(residuals_base_m, float)
    noise_bounds = (float(np.clip(noise_floor_m, NOISE_STD_BOUNDS_M[0], NOISE_STD_BOUNDS_M[1] / 2)),
                    NOISE_STD_BOUNDS_M[1])
    rows = np.arange(len(Q))
    if len(Q) > MAX_HYPERPARAMETER_POSES:
        rows = np.sort(np.random.default_rng(seed).choice(len(Q), MAX_HYPERPARAMETER_POSES, replace=False))
    length, signal, noise = _hyperparameters(Q[rows], D[rows], noise_bounds)
    K = signal ** 2 * np.exp(-0.5 * _squared_distances(Q) / length ** 2) + noise ** 2 * np.eye(len(Q))
    L = np.linalg.cholesky(K)
    alpha = np.linalg.solve(L.T, np.linalg.solve(L, D))
    return ResidualMap(Q.copy(), alpha, L, length, signal, noise, support_radius_rad(Q))
