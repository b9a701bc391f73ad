"""Fitting the non-geometric residual map (:class:`pipeline.robot.residual_map.ResidualMap`).

The base-frame position residuals ``d_k = R_tb (y_k - h(q_k, x))`` of a calibrated model at its
training poses are regressed on the joint angles by a Gaussian process with a squared-exponential
kernel plus white noise; the three axes share the kernel, and its hyperparameters maximise the
summed log marginal likelihood (Rasmussen & Williams, *Gaussian Processes for Machine Learning*,
MIT Press 2006, §5.4.1; scikit-learn's ``GaussianProcessRegressor`` with L-BFGS-B restarts from a
seeded generator). The white-noise level absorbs the readings' noise, so the map interpolates only
what repeats over neighbouring poses. Whether the map helps is for cross-validation to say
(:mod:`pipeline.calibration.model_selection`); a few dozen poses in six joint angles seldom carry
enough of it.
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

from pipeline.robot.residual_map import ResidualMap

#: hyperparameter bounds: signal std 1 µm .. 10 mm, length 0.05 .. 20 rad, noise std 1 µm .. 10 mm
SIGNAL_STD_BOUNDS_M = (1e-6, 1e-2)
LENGTH_SCALE_BOUNDS_RAD = (0.05, 20.0)
NOISE_STD_BOUNDS_M = (1e-6, 1e-2)
#: L-BFGS-B restarts of the marginal likelihood from random starts
RESTARTS = 1


def restart_seed(rng: np.random.Generator) -> int:
    """The seed of a fit's restarts: one draw from ``rng``."""
    return int(rng.integers(2 ** 31 - 1))


def fit_residual_map(Q: np.ndarray, residuals_base_m: np.ndarray, rng: np.random.Generator | int) -> ResidualMap:
    """GP posterior of ``residuals_base_m`` (n, 3) over the configurations ``Q`` (n, nq); the
    restarts' random starts from the seed ``rng`` or one drawn from it (:func:`restart_seed`)."""
    seed = rng if isinstance(rng, int) else restart_seed(rng)
    Q = np.asarray(Q, float)
    D = np.asarray(residuals_base_m, float)
    s0 = float(np.clip(np.sqrt(np.mean(D ** 2)), *SIGNAL_STD_BOUNDS_M))
    kernel = (ConstantKernel(s0 ** 2, tuple(b ** 2 for b in SIGNAL_STD_BOUNDS_M))
              * RBF(1.0, LENGTH_SCALE_BOUNDS_RAD)
              + WhiteKernel(s0 ** 2, tuple(b ** 2 for b in NOISE_STD_BOUNDS_M)))
    gp = GaussianProcessRegressor(kernel, normalize_y=False, n_restarts_optimizer=RESTARTS,
                                  random_state=np.random.RandomState(seed))
    with warnings.catch_warnings():   # a hyperparameter at its bound is a result, not a fault
        warnings.simplefilter("ignore", ConvergenceWarning)
        gp.fit(Q, D)
    k = gp.kernel_
    signal = float(np.sqrt(k.k1.k1.constant_value))
    length = float(k.k1.k2.length_scale)
    noise = float(np.sqrt(k.k2.noise_level))
    d2 = ((Q[:, None, :] - Q[None, :, :]) ** 2).sum(-1)
    K = signal ** 2 * np.exp(-0.5 * d2 / length ** 2) + noise ** 2 * np.eye(len(Q))
    L = np.linalg.cholesky(K)
    alpha = np.linalg.solve(L.T, np.linalg.solve(L, D))
    return ResidualMap(Q.copy(), alpha, L, length, signal, noise)
