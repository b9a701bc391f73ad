"""Robust estimation: a robust-loss fit, an outlier test on whitened residuals, a final LS fit.

Tracker records contain gross errors (a beam that hit the wrong surface: millimetres off; a
stale reading repeated after a blocked beam). One of them moves a least-squares fit far off, so:

0. with the elastostatic model, a geometric screen first: the rigid model (the identified
   geometric parameters alone) fitted with the redescending Cauchy loss, and the readings failing
   the test of step 3 under it left out of step 1. A gross error cannot then pull the compliances
   (and a wrong first-pass gravity model with them) towards itself and hide; a screened reading
   that the elastostatic fit explains comes back in step 3 (:func:`geometric_screen`);
1. plain least squares (:func:`pipeline.calibration.estimate.estimate`, registration + LM);
2. with ``loss`` "huber" or "cauchy": ``scipy.optimize.least_squares`` from that solution with the
   robust loss on the whitened residual components, ``f_scale`` = :data:`ROBUST_SCALE` ``u`` sigma
   with ``u`` the robust scale of step 3 at that solution (Huber 1981, *Robust Statistics*, §7.7:
   an M-estimate's loss is scaled by a robust estimate of the residuals' spread). With the stated
   noise right ``u`` is 1; where the readings' noise exceeds it (a record's first fit, before the
   noise model's remainder is estimated) a loss scaled by the stated sigma alone would treat most
   good readings as outliers, an L1 fit in effect;
3. outlier test: the whitened residual of a reading ``s_k = |r_k / sigma_k|^2`` is chi-square with
   3 degrees of freedom when the reading is good; readings with
   ``s_k > u^2 chi2.ppf(confidence, 3)`` are rejected (at most ``max_fraction`` of them, largest
   first), ``u = max(1, sqrt(median(s_k) / chi2.ppf(0.5, 3)))`` a robust scale of the residuals:
   a model that leaves a small systematic remainder (chi²/dof a little above 1, which the
   quality gate judges) does not make good readings look like gross errors;
4. the least-squares fit (step 1) on the kept readings; steps 3-4 repeat on the new fit (a
   rejected reading that fits again comes back) until the set is stable (at most
   :data:`MAX_ROUNDS`).

With a gravity-model covariance (:mod:`pipeline.calibration.gravity_uncertainty`, elastostatic
model) the fit whitens with the full covariance ``Sigma = D + B B^T`` of the readings and the
outlier test uses each reading's marginal block ``Sigma_k = sigma_k^2 I + B_k B_k^T``
(``s_k = r_k^T Sigma_k^-1 r_k``, still chi-square with 3 dof); the covariance needs the
compliances, so it is evaluated at the plain fit of step 1 and once more at the final
fit (a fixed-point step: the last least-squares fit uses the covariance of its own starting
estimate).

The final estimate, its covariance and chi²/dof are those of plain least squares on the kept
readings, so with no gross error nothing changes against the plain fit. The test is per reading
at the stated confidence: with the default 0.999 a good reading is rejected with probability
0.1 %.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2

from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import Estimate, estimate
from pipeline.calibration.gravity_uncertainty import GravityCovariance, Whitener
from pipeline.core.errors import PipelineError

#: scale of the robust loss in whitened units (readings within 2 sigma count quadratically)
ROBUST_SCALE = 2.0
MAX_ROUNDS = 5
Loss = Literal["linear", "huber", "cauchy"]
LOSSES: tuple[Loss, ...] = get_args(Loss)


@dataclass
class Rejection:
    """Readings rejected by the outlier test (indices into the fitted rows)."""

    rejected: np.ndarray          # (k,) row indices
    whitened_norm: np.ndarray     # (N,) |r_k / sigma_k| of every reading under the final fit
    threshold: float              # rejection threshold of |r_k / sigma_k|
    confidence: float
    loss: str
    capped: bool                  # more readings failed the test than max_fraction allows

    @property
    def n_rejected(self) -> int:
        return int(len(self.rejected))


def _whitened_norm(mm: MeasurementModel, est: Estimate, Q: np.ndarray, Y: np.ndarray, sigma: np.ndarray,
                   mounted: np.ndarray | None, offsets: np.ndarray | None, factors: np.ndarray | None = None
                   ) -> np.ndarray:
    pred = mm.predict(Q, est.x, est.registration, mounted, offsets)
    return Whitener(sigma, factors).reading_norm(Y - pred)


def _robust_refit(mm: MeasurementModel, est: Estimate, Q: np.ndarray, Y: np.ndarray, sigma: np.ndarray,
                  mounted: np.ndarray | None, loss: str, max_iterations: int,
                  offsets: np.ndarray | None, factors: np.ndarray | None = None) -> Estimate:
    """``least_squares`` with the robust loss from the plain fit (same registration and basis), its
    scale :data:`ROBUST_SCALE` times the robust scale of the plain fit's residuals (step 2)."""
    P = est.basis
    wh = Whitener(sigma, factors)
    scale = residual_scale(wh.reading_norm(Y - mm.predict(Q, est.x, est.registration, mounted, offsets)))

    def fun(th: np.ndarray) -> np.ndarray:
        return wh.vector(Y - mm.predict(Q, P @ th, est.registration, mounted, offsets))

    def jac(th: np.ndarray) -> np.ndarray:
        _, J = mm.jacobian(Q, P @ th, est.registration, P, mounted, offsets)
        return -wh.matrix(J)

    sol = least_squares(fun, est.theta, jac=jac, loss=loss, f_scale=ROBUST_SCALE * scale, method="trf",
                        max_nfev=max(4 * max_iterations, 20), x_scale="jac")
    return Estimate(P @ sol.x, sol.x, P, est.covariance, est.transform_tracker_to_base, est.registration,
                    int(sol.nfev), est.chi2_per_dof, est.residual_rms_m, bool(sol.success), est.cost_history)


def residual_scale(norm: np.ndarray) -> float:
    """Robust scale ``u = max(1, sqrt(median(s_k) / chi2.ppf(0.5, 3)))`` of readings whose whitened
    norms are ``norm`` (``s_k = norm_k^2``, chi-square with 3 dof for good readings under the stated
    noise): 1 when the stated noise holds, the factor by which the residuals exceed it otherwise."""
    if not len(norm):
        return 1.0
    return max(1.0, float(np.sqrt(np.median(np.asarray(norm, float) ** 2) / chi2.ppf(0.5, 3))))


def geometric_screen(mm: MeasurementModel, Q: np.ndarray, Y: np.ndarray, sigma: np.ndarray, basis: np.ndarray,
                     source: str, max_iterations: int, mounted: np.ndarray | None, offsets: np.ndarray | None,
                     confidence: float, max_fraction: float) -> np.ndarray:
    """``(N,)`` bool: readings kept by step 0 of the module docstring (all of them without
    compliance columns in ``basis``, or when the rigid fit is not regular)."""
    n = len(Q)
    keep = np.ones(n, bool)
    if not mm.compliance:
        return keep
    elastic = np.any(np.asarray(basis)[mm.sl_compliance] != 0, axis=0)
    if not elastic.any() or elastic.all():
        return keep
    try:
        rigid = estimate(mm, Q, Y, sigma, basis[:, ~elastic], source, max_iterations, mounted, offsets)
    except PipelineError:
        return keep
    rigid = _robust_refit(mm, rigid, Q, Y, sigma, mounted, "cauchy", max_iterations, offsets)
    norm = _whitened_norm(mm, rigid, Q, Y, sigma, mounted, offsets)
    bad = np.flatnonzero(norm > np.sqrt(chi2.ppf(confidence, 3)) * residual_scale(norm))
    keep[bad[np.argsort(-norm[bad])][: int(np.floor(max_fraction * n))]] = False
    return keep


def robust_estimate(mm: MeasurementModel, Q: np.ndarray, Y: np.ndarray, sigma: np.ndarray, basis: np.ndarray,
                    source: str = "measurements", max_iterations: int = 50, mounted: np.ndarray | None = None,
                    loss: str = "huber", confidence: float = 0.999, max_fraction: float = 0.1,
                    offsets: np.ndarray | None = None, gravity: GravityCovariance | None = None,
                    theta0: np.ndarray | None = None) -> tuple[Estimate, Rejection]:
    """Steps 1-4 of the module docstring. ``loss`` "linear": no robust refit (outlier test only);
    ``gravity``: the gravity-model covariance of the readings (None or inactive: ``sigma_k`` only);
    ``theta0``: a warm start (e.g. a neighbouring fold's fit): the first fit starts from it and each
    later one from the fit before; None: every fit starts from the nominal model."""
    Q, Y, sigma = np.asarray(Q, float), np.asarray(Y, float), np.asarray(sigma, float)
    n = len(Q)
    base_threshold = float(np.sqrt(chi2.ppf(confidence, 3)))
    threshold = base_threshold
    max_rejected = int(np.floor(max_fraction * n))
    kept = geometric_screen(mm, Q, Y, sigma, basis, source, max_iterations, mounted, offsets, confidence, max_fraction)

    def rows(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[kept]

    est = estimate(mm, Q[kept], Y[kept], sigma[kept], basis, source, max_iterations, rows(mounted), rows(offsets),
                   theta0=theta0)

    def start(e: Estimate) -> np.ndarray | None:
        return None if theta0 is None else e.theta

    use_gravity = gravity is not None and gravity.active

    def gravity_factors(e: Estimate) -> np.ndarray | None:
        return gravity.factors(Q, e.x, e.registration, mounted, offsets) if use_gravity else None

    fac = gravity_factors(est)
    if fac is not None:
        est = estimate(mm, Q[kept], Y[kept], sigma[kept], basis, source, max_iterations, rows(mounted), rows(offsets),
                       fac[kept], theta0=start(est))
    probe = est if loss == "linear" else _robust_refit(mm, est, Q, Y, sigma, mounted, loss, max_iterations, offsets,
                                                       fac)
    capped = False
    for _ in range(MAX_ROUNDS):
        norm = _whitened_norm(mm, probe, Q, Y, sigma, mounted, offsets, fac)
        threshold = base_threshold * residual_scale(norm)
        bad = np.flatnonzero(norm > threshold)
        capped = len(bad) > max_rejected
        bad = bad[np.argsort(-norm[bad])][:max_rejected]
        new_kept = np.ones(n, bool)
        new_kept[bad] = False
        if np.array_equal(new_kept, kept):
            break
        kept = new_kept
        m = None if mounted is None else mounted[kept]
        o = None if offsets is None else offsets[kept]
        est = estimate(mm, Q[kept], Y[kept], sigma[kept], basis, source, max_iterations, m, o,
                       None if fac is None else fac[kept], theta0=start(est))
        probe = est
    if fac is not None:   # fixed-point step: the covariance at the final compliances
        fac = gravity_factors(est)
        m = None if mounted is None else mounted[kept]
        o = None if offsets is None else offsets[kept]
        est = estimate(mm, Q[kept], Y[kept], sigma[kept], basis, source, max_iterations, m, o, fac[kept],
                       theta0=start(est))
    norm = _whitened_norm(mm, est, Q, Y, sigma, mounted, offsets, fac)
    return est, Rejection(np.flatnonzero(~kept), norm, threshold, confidence, loss, capped)
