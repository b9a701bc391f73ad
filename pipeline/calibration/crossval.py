"""k-fold cross-validation of a calibration on the user's own readings (no held-out file needed).

The poses (rows of the measurement file; the three fitted rows of a 6-D pose stay together) are
split into ``k`` folds in file order modulo ``k``. Each fold is predicted by the robust fit
(:func:`pipeline.calibration.robust.robust_estimate`, same identifiable set, same per-reading noise
``sigma_m``) of the other folds: the outlier test runs inside the training folds only, so a gross
error cannot leave a fold unscored by having been rejected on the whole record. Every left-out
pose is predicted; a left-out reading that fails the held-out outlier test under its fold's
model (:func:`pipeline.calibration.validate.gross_error_rows`: whitened by its predicted error
covariance) is counted (``n_rejected``) and left out of the statistics, as for a held-out file.

Per left-out pose the error ``|e|`` and its prediction ``E|e|^2 = trace(J C J^T) + 3 sigma^2``
(:func:`pipeline.calibration.validate.predicted_covariance`) give the cross-validated
``actual_over_predicted = sqrt(mean |e|^2 / mean E|e|^2)``; the nominal model with the fold's
registered tracker pose gives the error "before". Readings fitted with weights other than their noise
(``noise_sigma_m``: a 6-D record's orientation weight) give each fold's covariance as the weighted
estimator's sandwich (:func:`pipeline.calibration.noise_model.reweighted`). The RMS of the left-out errors is an honest
out-of-sample accuracy; it exceeds the in-sample fit residual by the estimation noise.

With the residual map (``map_rng`` given: the model selection chose it) each fold also fits the map
to its training poses' residuals (:func:`pipeline.calibration.residual_map.fit_residual_map`), the
left-out errors are those of the model plus the map, and the prediction adds the map's posterior
variance ``3 s_map(q)^2`` at the left-out poses (:func:`pipeline.calibration.validate.predicted_error`).
"""

from __future__ import annotations

import numpy as np

from pipeline.calibration import measure as ms
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.gravity_uncertainty import GravityCovariance
from pipeline.calibration.noise_model import reweighted
from pipeline.calibration.residual_map import fit_residual_map
from pipeline.calibration.robust import robust_estimate
from pipeline.calibration.validate import gross_error_rows, predicted_covariance
from pipeline.core.errors import PipelineError


def _rms(e: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(e ** 2))) if e.size else None


def cross_validate(mm: MeasurementModel, rec: ms.Measurements, basis: np.ndarray, sigma_m: np.ndarray,
                   folds: int, max_iterations: int, *, loss: str = "huber", confidence: float = 0.999,
                   max_fraction: float = 0.1, gravity: GravityCovariance | None = None,
                   map_rng: np.random.Generator | None = None, noise_sigma_m: np.ndarray | None = None) -> dict:
    """Per-fold and overall RMS position error (m) of the left-out poses, before and after, with
    the predicted RMS and the left-out readings rejected (module docstring)."""
    pose = rec.pose_index if rec.pose_index is not None else np.arange(len(rec))
    sigma_m = np.asarray(sigma_m, float)
    fold_of = pose % folds
    after: list[np.ndarray] = []
    before: list[np.ndarray] = []
    predicted_var: list[np.ndarray] = []
    per_fold: list[float | None] = []
    n_rejected = 0
    origin = np.all(rec.offset_m == 0, axis=1) if rec.offset_m is not None else np.ones(len(rec), bool)

    def part(a: np.ndarray | None, m: np.ndarray) -> np.ndarray | None:
        return None if a is None else a[m]

    for f in range(folds):
        train = fold_of != f
        test = (fold_of == f) & origin
        if not test.any():
            per_fold.append(None)
            continue
        try:
            est, rejection = robust_estimate(mm, rec.Q[train], rec.Y[train], sigma_m[train], basis, f"fold {f + 1}",
                                             max_iterations, part(rec.payload_mounted, train), loss, confidence,
                                             max_fraction, part(rec.offset_m, train), gravity)
        except PipelineError:
            per_fold.append(None)   # this fold's training poses do not excite every parameter
            continue
        if noise_sigma_m is not None:     # weights other than the noise model's (6-D orientation weight)
            fit = np.flatnonzero(train)
            fit = np.delete(fit, rejection.rejected)
            est = reweighted(mm, est, rec.Q[fit], rec.Y[fit], sigma_m[fit], np.asarray(noise_sigma_m, float)[fit],
                             part(rec.payload_mounted, fit), part(rec.offset_m, fit))
        held = ms.Measurements(rec.Q[test], rec.Y[test], sigma_m[test], f"fold {f + 1}")
        bad = gross_error_rows(mm, est, held, confidence, gravity)
        ok = np.ones(len(held), bool)
        ok[bad] = False
        n_rejected += int(len(bad))
        Q, Y = held.Q[ok], held.Y[ok]
        if not len(Q):
            per_fold.append(None)
            continue
        r = Y - mm.predict(Q, est.x, est.registration)
        cov, _ = predicted_covariance(mm, est, Q, held.sigma_m[ok], gravity)
        var = np.trace(cov, axis1=1, axis2=2)
        if map_rng is not None:
            R_tb = est.transform_tracker_to_base.rotation
            fit_rows = train & origin
            Qt = rec.Q[fit_rows]
            gp = fit_residual_map(Qt, (rec.Y[fit_rows] - mm.predict(Qt, est.x, est.registration)) @ R_tb.T, map_rng)
            mean, std = gp.predict(Q)
            r, var = r - mean @ R_tb, var + 3.0 * std ** 2
        e = np.linalg.norm(r, axis=1)
        after.append(e)
        before.append(np.linalg.norm(Y - mm.predict(Q, np.zeros(mm.n), est.registration), axis=1))
        predicted_var.append(var)
        per_fold.append(_rms(e))
    e_all = np.concatenate(after) if after else np.zeros(0)
    b_all = np.concatenate(before) if before else np.zeros(0)
    var = np.concatenate(predicted_var) if predicted_var else np.zeros(0)
    predicted = float(np.sqrt(np.mean(var))) if var.size else None
    rms = _rms(e_all)
    return {"folds": int(folds), "n_poses": int(e_all.size), "n_rejected": n_rejected,
            "rms_position_error_m": rms,
            "rms_position_error_before_m": _rms(b_all),
            "predicted_rms_position_error_m": predicted,
            "actual_over_predicted": rms / predicted if rms is not None and predicted else None,
            "per_fold_rms_m": per_fold,
            "n_folds_not_regular": int(sum(v is None for v in per_fold))}
