"""Noise model of a calibration reading: sensor + arm repeatability + unmodelled remainder.

A reading ``y_k = h(q_k, x) + e_k`` is off the model by three independent parts, each isotropic
per axis:

* the sensor's noise ``sigma_s,k`` (laser tracker: ``noise_const_m + noise_per_m * range``; a 6-D
  camera system: its stated noise);
* the arm's **repeatability**: the arm commanded to ``q_k`` stops a little elsewhere each time.
  Data sheets state ISO 9283 pose repeatability ``RP = l_bar + 3 S_l``, ``l`` the distance of an
  attained position from the barycentre of the attained positions. For an isotropic Gaussian
  scatter of ``sigma`` per axis ``l`` is Maxwell distributed (mean ``2 sqrt(2/pi) sigma``, standard
  deviation ``sqrt(3 - 8/pi) sigma``), so ``RP = 3.616 sigma`` and the 1-sigma per axis is
  ``sigma_r = RP / 3.616`` (:func:`pipeline.robot.repeatability.repeatability_sigma_m`);
* the **remainder** the model does not explain (gear transmission error, thermal drift, link
  bending beyond the joint compliances, a sensor noisier than stated): a variance ``tau^2`` per
  axis estimated from the calibration's own residuals, one per row group (position rows; the
  virtual marker-point rows of 6-D readings).

So ``Sigma_k = (sigma_s,k^2 + sigma_r^2 + tau_g(k)^2) I (+ B_k B_k^T`` of the gravity-model prior,
:mod:`pipeline.calibration.gravity_uncertainty`, in the fit's weights). The remainder is estimated on
the residuals of that fit, which took up part of the inertial error into the compliances: their
covariance carries what it left, ``(B_k - J_k M)(B_k - J_k M)^T`` (``M`` the estimate's gain on the
inertial error, as the held-out prediction of :mod:`pipeline.calibration.validate` has it). With
``B_k B_k^T`` instead the prior would claim residuals the fit has already absorbed and the
remainder come out low: on a soft arm (five times the stated compliance) half to three quarters of
a transmission error of 0.3 mrad.

For 6-D readings the fit may weight the marker-point rows differently from this noise model (a
factor ``kappa`` on their sigma, chosen by cross-validation,
:mod:`pipeline.calibration.model_selection`). The estimate is then a weighted least-squares
estimate with weights ``W = diag(1 / (kappa_k sigma_k)^2)`` of readings whose covariance is still
``S = diag(sigma_k^2)``: its covariance is the sandwich ``A^-1 J^T W S W J A^-1`` with
``A = J^T W J`` (plus the gravity-model gain ``M M^T``), and chi² is taken under ``S``
(:func:`reweighted`), so neither the predicted errors nor the chi² gate take the weight for a
claim about the noise.

``tau^2`` is a variance component estimated by restricted maximum likelihood (REML, Patterson &
Thompson 1971, "Recovery of inter-block information when block sizes are unequal", Biometrika 58;
in geodetic adjustment the same estimate is Förstner's / Koch's variance component estimation,
Koch 1999, "Parameter Estimation and Hypothesis Testing in Linear Models", §3.6). Linearised at the
fit (Jacobian ``J``, residual ``r``), REML minimises over ``tau^2 >= 0``

    l(tau^2) = log|Sigma| + log|J^T Sigma^-1 J| + r^T P r,
    P = Sigma^-1 - Sigma^-1 J (J^T Sigma^-1 J)^-1 J^T Sigma^-1,

which, unlike the maximum-likelihood variance ``|r|^2 / N``, accounts for the ``p`` degrees of
freedom the fit took (``r^T P r`` does not depend on the parameters at which ``r`` is taken,
``P J = 0``). With one component the minimum is found on a bracket in ``log tau``; with two groups
each is updated in turn (two sweeps). ``tau = 0`` is kept when it minimises ``l``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize_scalar

from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import Estimate
from pipeline.calibration.gravity_uncertainty import GravityCovariance
from pipeline.calibration.measure import Measurements
from pipeline.calibration.robust import Rejection, robust_estimate
from pipeline.robot.model import RobotModel
from pipeline.robot.repeatability import (  # noqa: F401 - repeatability_sigma_m re-exported
    REPEATABILITY_KEY,
    repeatability_for_calibration,
    repeatability_sigma_m,
)


@dataclass
class NoiseModel:
    """Per-axis 1-sigma parts of a reading's error besides the sensor's (m)."""

    repeatability_sigma_m: float = 0.0
    #: remainder 1-sigma per row group (0: position rows, 1: virtual marker-point rows)
    remainder_sigma_m: tuple[float, float] = (0.0, 0.0)
    #: factor on the 1-sigma of the marker-point rows in the fit (the orientation weight, chosen by
    #: cross-validation, :func:`pipeline.calibration.model_selection.orientation_weight`)
    orientation_scale: float = 1.0
    #: where the repeatability comes from (:func:`pipeline.robot.repeatability.repeatability_for_calibration`)
    repeatability_source: str = "stated"
    #: robot.yaml's RP (m) when it was not used ("data": the reach class's assumption), else None
    repeatability_not_used_m: float | None = None

    def known(self) -> NoiseModel:
        """The parts known before the fit: no remainder."""
        return replace(self, remainder_sigma_m=(0.0, 0.0))

    def total(self, sensor_sigma_m: np.ndarray, groups: np.ndarray | None = None) -> np.ndarray:
        """``(N,)`` 1-sigma per axis of each reading: sensor, repeatability and remainder combined
        (marker-point rows times ``orientation_scale``)."""
        s = np.asarray(sensor_sigma_m, float)
        g = np.zeros(len(s), int) if groups is None else np.asarray(groups, int)
        tau = np.asarray(self.remainder_sigma_m, float)[g]
        scale = np.where(g == 1, self.orientation_scale, 1.0)
        return scale * np.sqrt(s ** 2 + self.repeatability_sigma_m ** 2 + tau ** 2)

    def as_dict(self) -> dict[str, float | str | None]:
        return {"repeatability_sigma_m": float(self.repeatability_sigma_m),
                "repeatability_source": self.repeatability_source,
                "repeatability_not_used_m": self.repeatability_not_used_m,
                "remainder_sigma_m": float(self.remainder_sigma_m[0]),
                "remainder_orientation_points_sigma_m": float(self.remainder_sigma_m[1]),
                "orientation_weight_scale": float(self.orientation_scale)}


def noise_of_robot(robot: RobotModel, recorded: bool, orientation_scale: float = 1.0) -> NoiseModel:
    """The known noise parts of a calibration of ``robot`` (``recorded``: readings from a file): the
    repeatability by :func:`pipeline.robot.repeatability.repeatability_for_calibration`."""
    rp = robot.spec.repeatability_m
    assumed = REPEATABILITY_KEY in robot.spec.assumed
    sigma, source = repeatability_for_calibration(rp, assumed, recorded)
    return NoiseModel(sigma, orientation_scale=orientation_scale, repeatability_source=source,
                      repeatability_not_used_m=float(rp) if source == "data" and rp is not None else None)


def row_groups(offset_m: np.ndarray | None, n: int) -> np.ndarray:
    """``(N,)`` 0 for a position row (marker origin), 1 for a virtual marker-point row."""
    if offset_m is None:
        return np.zeros(n, int)
    return np.any(np.asarray(offset_m) != 0, axis=1).astype(int)


def _blocks(base_var: np.ndarray, factors: np.ndarray | None) -> np.ndarray:
    cov = base_var[:, None, None] * np.eye(3)
    if factors is not None and factors.shape[2]:
        cov = cov + np.einsum("nir,njr->nij", factors, factors)
    return cov


def reml_objective(residual: np.ndarray, J: np.ndarray, base_var: np.ndarray,
                   factors: np.ndarray | None = None) -> float:
    """``l`` of the module docstring for per-reading variance ``base_var`` (N,) (plus the gravity
    factors' ``B_k B_k^T``); ``residual`` (N, 3), ``J`` (N, 3, p) block-diagonal readings. Without
    factors ``Sigma_k = v_k I``: its Cholesky factor ``sqrt(v_k) I`` and inverse ``(1 / sqrt(v_k)) I`` are
    formed directly (what LAPACK's factorisation and inverse give for a diagonal block, exactly)."""
    if factors is None or not factors.shape[2]:
        sd = np.sqrt(np.asarray(base_var, float))
        L = np.zeros((len(sd), 3, 3))
        L[:, [0, 1, 2], [0, 1, 2]] = sd[:, None]
        w = 1.0 / sd
        wr = (residual * w[:, None]).reshape(-1)
        wJ = (J * w[:, None, None]).reshape(len(wr), -1)
    else:
        L = np.linalg.cholesky(_blocks(base_var, factors))
        W = np.linalg.inv(L)
        wr = np.einsum("nij,nj->ni", W, residual).reshape(-1)
        wJ = np.einsum("nij,njp->nip", W, J).reshape(len(wr), -1)
    logdet_sigma = 2.0 * float(np.sum(np.log(np.diagonal(L, axis1=1, axis2=2))))
    q, r = np.linalg.qr(wJ)
    d = np.abs(np.diagonal(r))
    keep = d > d.max() * 1e-10 if d.size else d.astype(bool)
    logdet_info = 2.0 * float(np.sum(np.log(d[keep])))
    proj = q[:, keep].T @ wr
    return logdet_sigma + logdet_info + float(wr @ wr - proj @ proj)


def reml_remainder(residual: np.ndarray, J: np.ndarray, sigma_m: np.ndarray, groups: np.ndarray | None = None,
                   factors: np.ndarray | None = None, sweeps: int = 2) -> tuple[float, float]:
    """REML remainder 1-sigma per axis (m) of row groups 0 and 1 (module docstring): readings of
    residual ``(N, 3)``, Jacobian ``(N, 3, p)`` wrt the fitted parameters, known 1-sigma ``sigma_m``
    (N,) (sensor and repeatability)."""
    residual, J = np.asarray(residual, float), np.asarray(J, float)
    s2 = np.asarray(sigma_m, float) ** 2
    g = np.zeros(len(s2), int) if groups is None else np.asarray(groups, int)
    tau2 = [0.0, 0.0]
    present = [bool(np.any(g == k)) for k in (0, 1)]
    for _ in range(sweeps if all(present) else 1):
        for k in (0, 1):
            if not present[k]:
                continue

            def obj(log_tau: float, k: int = k) -> float:
                t = list(tau2)
                t[k] = math.exp(2.0 * log_tau)
                return reml_objective(residual, J, s2 + np.asarray(t)[g], factors)

            rows = residual[g == k]
            rms = math.sqrt(float(np.mean(rows ** 2))) if rows.size else 0.0
            floor = math.sqrt(float(np.mean(s2[g == k])))
            hi = math.log(max(4.0 * rms, 2.0 * floor, 1e-12))
            lo = math.log(max(1e-3 * floor, 1e-12))
            sol = minimize_scalar(obj, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3})
            t0 = list(tau2)
            t0[k] = 0.0
            zero = reml_objective(residual, J, s2 + np.asarray(t0)[g], factors)
            tau2[k] = 0.0 if zero <= float(sol.fun) else math.exp(2.0 * float(sol.x))
    return math.sqrt(tau2[0]), math.sqrt(tau2[1])


def _remainder_at(mm: MeasurementModel, est: Estimate, rec: Measurements, known_sigma_m: np.ndarray,
                  groups: np.ndarray, kept: np.ndarray, gravity: GravityCovariance | None) -> tuple[float, float]:
    """REML remainder of the kept readings of ``rec`` at the fit ``est``."""
    def part(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[kept]

    Q, mounted, offsets = rec.Q[kept], part(rec.payload_mounted), part(rec.offset_m)
    pred, J = mm.jacobian(Q, est.x, est.registration, est.basis, mounted, offsets)
    factors = (gravity.factors(Q, est.x, est.registration, mounted, offsets)
               if gravity is not None and gravity.active and mm.compliance else None)
    if factors is not None and est.gravity_gain is not None:
        factors = factors - J @ est.gravity_gain     # what the fit left of the inertial error
    return reml_remainder(rec.Y[kept] - pred, J, known_sigma_m[kept], groups[kept], factors)


def reweighted(mm: MeasurementModel, est: Estimate, Q: np.ndarray, Y: np.ndarray, weight_sigma_m: np.ndarray,
               noise_sigma_m: np.ndarray, mounted: np.ndarray | None = None, offsets: np.ndarray | None = None
               ) -> Estimate:
    """``est`` (fitted with the 1-sigma ``weight_sigma_m`` of readings ``Q, Y``) with the covariance and
    chi²/dof of the weighted estimator under the readings' noise ``noise_sigma_m`` (module docstring)."""
    w = np.asarray(weight_sigma_m, float)
    s = np.asarray(noise_sigma_m, float)
    if np.array_equal(w, s):
        return est
    pred, J = mm.jacobian(Q, est.x, est.registration, est.basis, mounted, offsets)
    Jw = (J / w[:, None, None]).reshape(-1, J.shape[2])
    A_inv = np.linalg.inv(Jw.T @ Jw)
    G = (J * (s / w ** 2)[:, None, None]).reshape(-1, J.shape[2])     # W S^(1/2) J, stacked
    C = A_inv @ (G.T @ G) @ A_inv
    if est.gravity_gain is not None:
        C = C + est.gravity_gain @ est.gravity_gain.T
    dof = max(Jw.shape[0] - Jw.shape[1], 1)
    chi2 = float(np.sum(((np.asarray(Y, float) - pred) / s[:, None]) ** 2) / dof)
    return replace(est, covariance=0.5 * (C + C.T), chi2_per_dof=chi2)


def fit_with_noise_model(mm: MeasurementModel, rec: Measurements, basis: np.ndarray, noise: NoiseModel,
                         gravity: GravityCovariance | None, *, max_iterations: int, loss: str, confidence: float,
                         max_fraction: float, rounds: int = 3, tolerance: float = 0.05,
                         theta0: np.ndarray | None = None) -> tuple[Estimate, Rejection, NoiseModel]:
    """Robust fit (:func:`pipeline.calibration.robust.robust_estimate`) with the readings' noise
    ``sensor + repeatability + remainder``; the remainder by REML on the kept readings of that fit,
    then the fit again with it, until the readings' total variance changes by less than
    ``tolerance`` (relative, mean over the readings) or after ``rounds`` fits. ``theta0``: a warm
    start (a neighbouring fold's fit): the first fit starts from it, each later one from the fit
    before; None: every fit starts from the nominal model."""
    groups = row_groups(rec.offset_m, len(rec))
    known = replace(noise.known(), orientation_scale=1.0).total(rec.sigma_m, groups)
    current = noise
    for _ in range(rounds):
        sigma = current.total(rec.sigma_m, groups)
        est, rejection = robust_estimate(mm, rec.Q, rec.Y, sigma, basis, rec.source, max_iterations,
                                         rec.payload_mounted, loss, confidence, max_fraction, rec.offset_m, gravity,
                                         theta0)
        theta0 = None if theta0 is None else est.theta
        kept = np.ones(len(rec), bool)
        kept[rejection.rejected] = False
        new = replace(noise, remainder_sigma_m=_remainder_at(mm, est, rec, known, groups, kept, gravity))
        change = float(np.mean(np.abs(new.total(rec.sigma_m, groups) ** 2 - sigma ** 2)) / np.mean(sigma ** 2))
        current = new
        if change < tolerance:
            break
    if current.orientation_scale != 1.0:     # the weight is not a claim about the noise: reweighted()
        kept = np.ones(len(rec), bool)
        kept[rejection.rejected] = False
        unit = replace(current, orientation_scale=1.0)

        def part(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[kept]

        est = reweighted(mm, est, rec.Q[kept], rec.Y[kept], current.total(rec.sigma_m, groups)[kept],
                         unit.total(rec.sigma_m, groups)[kept], part(rec.payload_mounted), part(rec.offset_m))
    return est, rejection, current
