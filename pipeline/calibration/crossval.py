"""k-fold cross-validation of a calibration on the user's own readings (no held-out file needed).

The poses (rows of the measurement file; the three fitted rows of a 6-D pose stay together) are
split into ``k`` folds grouped in joint space (:func:`spatial_folds`: poses near each other fall in
one fold, so a fold is predicted where the model must extrapolate from the others). Each fold is
predicted by the robust fit (:func:`pipeline.calibration.robust.robust_estimate`, same identifiable
set, same per-reading noise ``sigma_m``) of the other folds: the outlier test runs inside the
training folds only, so a gross error cannot leave a fold unscored by having been rejected on the
whole record. Every left-out pose is predicted; a left-out reading that fails the held-out outlier
test under its fold's model (:func:`pipeline.calibration.validate.gross_error_rows`: whitened by its
predicted error covariance) is counted (``n_rejected``) and left out of the statistics, as for a
held-out file, unless more than ``max_fraction`` of the left-out readings would be: then none is
left out (the model, not the readings, is at fault) and ``screen_capped`` says so. The figures over
every pose (``*_all_poses``) stand beside the screened ones.

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
from sklearn.cluster import KMeans

from pipeline.calibration import measure as ms
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.gravity_uncertainty import GravityCovariance
from pipeline.calibration.noise_model import reweighted
from pipeline.calibration.residual_map import fit_residual_map
from pipeline.calibration.robust import robust_estimate
from pipeline.calibration.validate import gross_error_rows, predicted_covariance
from pipeline.core.errors import PipelineError

#: clusters per fold of :func:`spatial_folds` (a fold holds this many neighbourhoods of joint space)
CLUSTERS_PER_FOLD = 2
#: seed of the k-means initialisation (:func:`spatial_folds`: the folds are a function of the poses)
FOLD_SEED = 0


def spatial_folds(Q: np.ndarray, folds: int) -> np.ndarray:
    """``(n,)`` fold of each configuration of ``Q`` (n, nq), grouped in joint space.

    The configurations are clustered by k-means (Lloyd's algorithm, scikit-learn's ``KMeans``,
    k-means++ starts seeded by :data:`FOLD_SEED`) into ``CLUSTERS_PER_FOLD * folds`` clusters
    (at most ``n``); the clusters are dealt to the folds largest first, each to the fold with the
    fewest poses so far (the balancing of scikit-learn's ``GroupKFold``). A left-out fold is then a
    set of neighbourhoods no training pose lies in, so a model, or a residual map, that only
    interpolates between the calibration poses is scored where it must extrapolate (Roberts et al.
    2017, "Cross-validation strategies for data with temporal, spatial, hierarchical, or
    phylogenetic structure", Ecography 40: blocked cross-validation of dependent data)."""
    Q = np.asarray(Q, float)
    n = len(Q)
    folds = int(min(folds, n))
    n_clusters = int(min(n, CLUSTERS_PER_FOLD * folds))
    if n_clusters <= folds:
        return np.arange(n) % max(folds, 1)
    labels = KMeans(n_clusters, n_init=4, random_state=FOLD_SEED).fit_predict(Q)
    sizes = np.bincount(labels, minlength=n_clusters)
    load = np.zeros(folds, int)
    fold_of_cluster = np.empty(n_clusters, int)
    for c in sorted(range(n_clusters), key=lambda c: (-sizes[c], c)):
        f = int(np.argmin(load))
        fold_of_cluster[c] = f
        load[f] += sizes[c]
    return fold_of_cluster[labels]


def _rms(e: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(e ** 2))) if e.size else None


def pose_folds(rec: ms.Measurements, folds: int) -> np.ndarray:
    """``(n_poses,)`` fold of each pose of a record (6-D: its three fitted rows share a pose,
    ``pose_index``) by :func:`spatial_folds` of the poses' configurations."""
    if rec.pose_index is None:
        return spatial_folds(rec.Q, folds)
    pose = np.asarray(rec.pose_index, int)
    first = np.unique(pose, return_index=True)[1]
    return spatial_folds(rec.Q[first], folds)


def screen_capped(bad: np.ndarray, max_fraction: float) -> bool:
    """Whether the gross-error screen would leave out more than ``max_fraction`` of the held-out
    readings ``bad`` (bool, one per reading): then it leaves out none (module docstring)."""
    bad = np.asarray(bad, bool)
    return bool(bad.sum() > np.floor(max_fraction * bad.size))


def cross_validate(mm: MeasurementModel, rec: ms.Measurements, basis: np.ndarray, sigma_m: np.ndarray,
                   folds: int, max_iterations: int, *, loss: str = "huber", confidence: float = 0.999,
                   max_fraction: float = 0.1, gravity: GravityCovariance | None = None,
                   map_rng: np.random.Generator | None = None, noise_sigma_m: np.ndarray | None = None,
                   fold_of_pose: np.ndarray | None = None, map_noise_floor_m: float = 0.0) -> dict:
    """Per-fold and overall RMS position error (m) of the left-out poses, before and after, with
    the predicted RMS and the left-out readings rejected (module docstring); ``fold_of_pose``: the
    fold of each pose (default :func:`pose_folds`), ``map_noise_floor_m``: the residual map's noise
    floor (:func:`pipeline.calibration.residual_map.fit_residual_map`)."""
    pose = rec.pose_index if rec.pose_index is not None else np.arange(len(rec))
    sigma_m = np.asarray(sigma_m, float)
    of_pose = pose_folds(rec, folds) if fold_of_pose is None else np.asarray(fold_of_pose, int)
    fold_of = of_pose[pose]
    folds = int(of_pose.max()) + 1 if of_pose.size else int(folds)
    parts: list[tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []   # fold, |e|, before, var, bad
    origin = np.all(rec.offset_m == 0, axis=1) if rec.offset_m is not None else np.ones(len(rec), bool)

    def part(a: np.ndarray | None, m: np.ndarray) -> np.ndarray | None:
        return None if a is None else a[m]

    for f in range(folds):
        train = fold_of != f
        test = (fold_of == f) & origin
        if not test.any():
            continue
        try:
            est, rejection = robust_estimate(mm, rec.Q[train], rec.Y[train], sigma_m[train], basis, f"fold {f + 1}",
                                             max_iterations, part(rec.payload_mounted, train), loss, confidence,
                                             max_fraction, part(rec.offset_m, train), gravity)
        except PipelineError:
            continue   # this fold's training poses do not excite every parameter
        if noise_sigma_m is not None:     # weights other than the noise model's (6-D orientation weight)
            fit = np.flatnonzero(train)
            fit = np.delete(fit, rejection.rejected)
            est = reweighted(mm, est, rec.Q[fit], rec.Y[fit], sigma_m[fit], np.asarray(noise_sigma_m, float)[fit],
                             part(rec.payload_mounted, fit), part(rec.offset_m, fit))
        held = ms.Measurements(rec.Q[test], rec.Y[test], sigma_m[test], f"fold {f + 1}")
        bad = np.zeros(len(held), bool)
        bad[gross_error_rows(mm, est, held, confidence, gravity)] = True
        Q, Y = held.Q, held.Y
        r = Y - mm.predict(Q, est.x, est.registration)
        cov, _ = predicted_covariance(mm, est, Q, held.sigma_m, gravity)
        var = np.trace(cov, axis1=1, axis2=2)
        if map_rng is not None:
            R_tb = est.transform_tracker_to_base.rotation
            fit_rows = train & origin
            Qt = rec.Q[fit_rows]
            gp = fit_residual_map(Qt, (rec.Y[fit_rows] - mm.predict(Qt, est.x, est.registration)) @ R_tb.T, map_rng,
                                  noise_floor_m=map_noise_floor_m)
            mean, reading = gp.predict_reading(Q)    # its reading variance in place of the reading noise
            r, var = r - mean @ R_tb, var + 3.0 * (reading ** 2 - held.sigma_m ** 2)
        before = np.linalg.norm(Y - mm.predict(Q, np.zeros(mm.n), est.registration), axis=1)
        parts.append((f, np.linalg.norm(r, axis=1), before, var, bad))
    return heldout_figures(parts, folds, max_fraction)


def heldout_figures(parts: list[tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]], folds: int,
                    max_fraction: float) -> dict:
    """Summary figures of the left-out poses: per fold ``(fold, |e|, |e| before, E|e|^2, gross)``;
    the screened figures leave out the gross readings unless :func:`screen_capped`, the
    ``*_all_poses`` ones count every pose. Every ratio is of figures in this dict."""
    def cat(i: int) -> np.ndarray:
        return np.concatenate([p[i] for p in parts]) if parts else np.zeros(0)

    e_all, b_all, var_all = cat(1), cat(2), cat(3)
    bad = cat(4).astype(bool)
    capped = screen_capped(bad, max_fraction)
    keep = np.ones(len(bad), bool) if capped else ~bad
    rms, rms_all = _rms(e_all[keep]), _rms(e_all)
    predicted = _rms(np.sqrt(var_all[keep]))
    predicted_all = _rms(np.sqrt(var_all))
    per_fold: list[float | None] = [None] * folds
    for f, e, _, _, b in parts:
        per_fold[f] = _rms(e if capped else e[~b])
    return {"folds": int(folds), "n_poses": int(keep.sum()), "n_rejected": int((~keep).sum()),
            "n_poses_all": int(len(keep)), "screen_capped": capped,
            "rms_position_error_m": rms,
            "rms_position_error_before_m": _rms(b_all[keep]),
            "predicted_rms_position_error_m": predicted,
            "actual_over_predicted": rms / predicted if rms is not None and predicted else None,
            "rms_position_error_all_poses_m": rms_all,
            "predicted_rms_position_error_all_poses_m": predicted_all,
            "actual_over_predicted_all_poses": rms_all / predicted_all if rms_all is not None and predicted_all
            else None,
            "per_fold_rms_m": per_fold,
            "n_folds_not_regular": int(sum(v is None for v in per_fold))}
