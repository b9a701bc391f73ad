"""Quantiles of a quadratic form in normal variables: ``Q = sum_j lambda_j chi2_1`` (independent
terms, ``lambda_j >= 0``), the distribution of ``e^T e`` for ``e ~ N(0, C)`` with ``lambda`` the
eigenvalues of ``C`` (a generalized chi-square). Imhof (1961), "Computing the distribution of
quadratic forms in normal variables", Biometrika 48: the survival function as a one-dimensional
integral of the characteristic function, inverted by Brent's method.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad
from scipy.optimize import brentq
from scipy.stats import chi2

#: eigenvalues below this fraction of the trace are left out of Imhof's integral (they move the
#: quantile by less than this fraction)
NEGLIGIBLE_EIGENVALUE_SHARE = 1e-12
#: absolute tolerance of Imhof's integral (pi times a probability; the tail tested is 1 %)
IMHOF_TOLERANCE = 1e-10


def _imhof_sf(x: float, lam: np.ndarray) -> float:
    """``P(sum_j lam_j chi2_1 > x)`` for independent chi-square variables with one degree of freedom
    (Imhof 1961, "Computing the distribution of quadratic forms in normal variables", Biometrika 48,
    eq. 3.2): ``1/2 + (1/pi) int_0^inf sin(theta(u)) / (u rho(u)) du``, ``theta(u) = 1/2 sum
    arctan(lam_j u) - x u / 2``, ``rho(u) = prod (1 + lam_j^2 u^2)^(1/4)``; ``lam`` normalised to sum 1.
    The integral ends at ``U`` where ``2^(5/4) / rho(U)`` (a bound of the rest, ``U >= 1/max lam``) is
    below :data:`IMHOF_TOLERANCE`. Up to ``a = min(4 pi / x, U)`` (one period of ``x u / 2``) it is
    taken in ``t = ln u`` (``sin(theta) / rho``, smooth over the decades of ``u``; below
    ``u = tol / (1 + x)`` it is ``(1 - x) u / 2``, negligible), beyond ``a`` as
    Fourier integrals (QUADPACK's QAWF) of the slowly varying ``sin(alpha) / (u rho)`` and
    ``cos(alpha) / (u rho)``, ``alpha = 1/2 sum arctan(lam_j u)``."""
    def alpha(u: float) -> float:
        return 0.5 * float(np.sum(np.arctan(lam * u)))

    def rho_inv(u: float) -> float:
        return math.exp(-0.25 * float(np.sum(np.log1p((lam * u) ** 2))))

    end = max(1.0, 1.0 / float(lam.max()))
    while 2.0 ** 1.25 * rho_inv(end) > IMHOF_TOLERANCE:
        end *= 2.0
    a = min(4.0 * math.pi / x, end)
    head = quad(lambda t: math.sin(alpha(math.exp(t)) - 0.5 * x * math.exp(t)) * rho_inv(math.exp(t)),
                math.log(IMHOF_TOLERANCE / (1.0 + x)), math.log(a), limit=400, epsabs=IMHOF_TOLERANCE)[0]
    if a >= end:
        return 0.5 + head / math.pi
    cos_part = quad(lambda u: math.sin(alpha(u)) * rho_inv(u) / u, a, np.inf, weight="cos", wvar=0.5 * x,
                    epsabs=IMHOF_TOLERANCE, limlst=200)[0]
    sin_part = quad(lambda u: math.cos(alpha(u)) * rho_inv(u) / u, a, np.inf, weight="sin", wvar=0.5 * x,
                    epsabs=IMHOF_TOLERANCE, limlst=200)[0]
    return 0.5 + (head + cos_part - sin_part) / math.pi


def weighted_chi2_quantile(eigenvalues: np.ndarray, probability: float) -> float:
    """``probability``-quantile of ``sum_j lambda_j chi2_1`` (independent; ``eigenvalues`` >= 0, not
    all 0) by Imhof's integral (:func:`_imhof_sf`) and Brent's root search, bracketed by the bounds
    ``lambda_max chi2_1 <= Q <= lambda_max chi2_n`` and ``Q >= lambda_min chi2_n`` (each term is
    between them), to the integral's tolerance :data:`IMHOF_TOLERANCE` (equal weights: ``lambda chi2_n``)."""
    lam = np.sort(np.asarray(eigenvalues, float))[::-1]
    total = float(np.sum(lam))
    lam = lam / total
    lam = lam[lam > NEGLIGIBLE_EIGENVALUE_SHARE]
    n = len(lam)
    lo = max(lam[0] * chi2.ppf(probability, 1), lam[-1] * chi2.ppf(probability, n))
    hi = lam[0] * chi2.ppf(probability, n)
    if hi - lo <= 1e-12 * hi:
        return total * float(hi)
    root = brentq(lambda x: _imhof_sf(x, lam) - (1.0 - probability), lo * (1 - 1e-9), hi * (1 + 1e-9),
                  xtol=1e-12, rtol=1e-10)
    return total * float(root)
