"""Validation on held-out poses (paper 004 §3.4, Table 2 layout).

Errors are ``e_k = y_k - h(q_k, x, T_tb)`` between the tracker reading and the model's
prediction, expressed in the robot base frame (``R_tb e_k``). "Before" uses the nominal kinematics
with the tracker pose registered on the calibration data (closed form, paper 003 §2.2); "after"
the identified parameters and tracker pose. The predicted error follows from the parameter
covariance (paper 000 eq. 16 linear error propagation) plus the tracker noise:
``E|e_k|^2 = trace(J_k C J_k^T) + 3 sigma_k^2``; the predicted RMS is the root of its mean. With
the elastostatic model and a gravity-model prior (:mod:`pipeline.calibration.gravity_uncertainty`)
the held-out error is ``e_h = (B_h - J_h M) z - J_h K n + n_h`` (the fit absorbs part of the
inertial error ``z``, ``M`` = ``Estimate.gravity_gain``), so
``E|e_h|^2 = trace(J_h (C - M M^T) J_h^T) + |B_h - J_h M|_F^2 + 3 sigma_h^2``; the second term
is the gravity-model part, whose share of the predicted mean square is reported (``B_h`` at the
fitted compliances, a poorly measured one combined with the nominal rule,
:func:`gravity_linearisation_point`).

Orientation (6-D readings fitted as marker points, :func:`pipeline.calibration.measure.
expand_orientation`): the errors ``e_0, e_x, e_y`` of the marker origin and of the virtual points
``L`` along the marker x and y axes give the marker-frame orientation error ``w`` to first order,
``R^T (e_x - e_0) = L w x e_x`` and ``R^T (e_y - e_0) = L w x e_y`` (``R`` the marker orientation in
the tracker frame), so ``w = (g_y[z], -g_x[z], g_x[y])`` with ``g_k = R^T (e_k - e_0) / L``: a linear
map ``S`` of the point errors, whose covariance follows as above with ``J_h, B_h`` replaced by
``S J_h, S B_h``; ``E|w|^2`` adds ``3 sigma_rot^2`` of a noisy reading. ``sigma_rot`` is the stated
orientation noise and a remainder estimated by REML on the fit's own orientation residuals
(:func:`orientation_noise_rad`), as the position rows' remainder is on theirs: a camera's
orientation noise, the arm's and the model's unexplained part are in the readings, not in a
data-sheet value.

Without a held-out set (a measurement file, no validation file) only the prediction is reported,
over random visible poses (:func:`predicted_on_random_poses`).

The held-out errors' stacked covariance (:func:`heldout_error_moments`) is what the
actual/predicted gate tests against (:mod:`pipeline.calibration.gates`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from pipeline.calibration import candidates as cd
from pipeline.calibration import noise_model as nm
from pipeline.calibration.config import Config
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import MAX_COMPLIANCE_RELATIVE_STD, Estimate
from pipeline.calibration.gravity_uncertainty import GravityCovariance
from pipeline.calibration.measure import MARKER_LEVER_M, Measurements, noise_model_sigma
from pipeline.robot.model import RobotModel
from pipeline.robot.residual_map import ResidualMap
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad

#: stacked held-out error components (3 per scored pose) up to which the actual/predicted test's
#: quantile is exact (:func:`pipeline.core.quadratic_forms.weighted_chi2_quantile`: Imhof's integral
#: over the eigenvalues of the stacked covariance, ~0.3 s at 600);
#: beyond, the Satterthwaite–Welch approximation (:mod:`pipeline.calibration.gates`), whose upper bound on the ratio
#: is within 0.2 % of the exact one for 200 poses sharing 2 or 30 parameter directions
EXACT_QUANTILE_MAX_COMPONENTS = 600


def _stats(e: np.ndarray) -> dict[str, float]:
    n = np.linalg.norm(e, axis=1)
    return {"mean": float(n.mean()), "rms": float(np.sqrt(np.mean(n ** 2))), "max": float(n.max())}


def _axis_stats(e: np.ndarray) -> dict[str, dict[str, float]]:
    out = {}
    for k, ax in enumerate("xyz"):
        v = e[:, k]
        out[ax] = {"max_abs": float(np.abs(v).max()), "half_peak_to_peak": float(0.5 * (v.max() - v.min())),
                   "rms": float(np.sqrt(np.mean(v ** 2)))}
    return out


def gravity_linearisation_point(mm: MeasurementModel, est: Estimate) -> np.ndarray:
    """Parameters at which the gravity-model factors of a prediction are evaluated: the estimate,
    with each estimated compliance replaced by its combination with the nominal rule
    (:func:`pipeline.robot.stiffness.nominal_joint_stiffness_Nm_rad`, relative spread
    :data:`pipeline.calibration.estimate.MAX_COMPLIANCE_RELATIVE_STD` between arms of one type),
    weighted by the inverse variances, ``c = (c_hat s_n^2 + c_n s_hat^2) / (s_n^2 + s_hat^2)``,
    non-negative. The inertial error moves the arm through the true compliance; a well determined
    estimate (also a rigid joint's ~0) is kept, a poor one (a wrist compliance seen by 6-D
    readings, known to +-80 %) does not inflate the prediction. Compliances outside the
    identified set stay as they are. ``s_hat^2`` is the readings' share of the estimate's variance,
    ``C - M M^T``: the inertial part ``M M^T`` is the compliance taking up the error of the nominal
    masses (deflection ``c g``: a mass scale and a compliance scale act alike), which the factors
    ``B_h - J_h M`` account for at the compliance ``M`` was taken at. Counted as doubt about
    ``c_hat`` it would pull a well-measured compliance of a soft arm to the nominal rule and ``B_h``
    away from ``J_h M`` (a UR5 five times softer than stated, 1000 readings: a held-out error
    predicted at 2.3 times its actual value)."""
    x = np.asarray(est.x, float).copy()
    if not mm.compliance:
        return x
    B = np.asarray(est.basis, float)[mm.sl_compliance]
    in_set = np.any(B != 0, axis=1)
    var_hat = np.maximum(np.einsum("ij,jk,ik->i", B, est.readings_covariance, B), 0.0)
    c_nom = 1.0 / nominal_joint_stiffness_Nm_rad(mm.robot)
    var_nom = (MAX_COMPLIANCE_RELATIVE_STD * c_nom) ** 2
    c = x[mm.sl_compliance]
    combined = (c * var_nom + c_nom * var_hat) / (var_nom + var_hat)
    c[in_set] = np.maximum(combined[in_set], 0.0)
    x[mm.sl_compliance] = c
    return x


def predicted_covariance(mm: MeasurementModel, est: Estimate, Q: np.ndarray, sigma_m: np.ndarray,
                         gravity: GravityCovariance | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 3, 3)`` covariance of the error ``y_h - h(q_h, x_hat)`` of a reading at each configuration
    (module docstring) and ``(N,)`` its gravity-model part ``|B_h - J_h M|_F^2``."""
    _, J = mm.jacobian(Q, est.x, est.registration, est.basis)
    B = None
    if _gravity_active(est, gravity):
        B = gravity.factors(Q, gravity_linearisation_point(mm, est), est.registration)
    cov, var_gravity = _model_covariance(J, est, B)
    return cov + np.asarray(sigma_m, float)[:, None, None] ** 2 * np.eye(3), var_gravity


def _gravity_active(est: Estimate, gravity: GravityCovariance | None) -> bool:
    return gravity is not None and gravity.active and est.gravity_gain is not None


def _model_covariance(J: np.ndarray, est: Estimate, B: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """``(N, k, k)`` covariance of ``J dtheta`` plus, given the gravity factors ``B`` (``(N, k, r)``),
    the gravity-model part ``|B - J M|_F^2`` (``M = est.gravity_gain``; the estimate's covariance then
    excludes ``M M^T``), and ``(N,)`` that part's trace."""
    if B is None:
        return np.einsum("nip,pq,njq->nij", J, est.covariance, J), np.zeros(len(J))
    M = est.gravity_gain
    R = B - J @ M
    cov = np.einsum("nir,njr->nij", R, R) + np.einsum("nip,pq,njq->nij", J, est.readings_covariance, J)
    return cov, np.einsum("nir,nir->n", R, R)


def _orientation_rows(R: np.ndarray, points: list[np.ndarray], lever_m: float) -> np.ndarray:
    """``S`` of the module docstring applied to the origin / x / y point blocks ``(N, 3, k)``:
    ``(N, 3, k)`` rows of the marker-frame orientation error."""
    gx = np.einsum("nji,njk->nik", R, points[1] - points[0]) / lever_m
    gy = np.einsum("nji,njk->nik", R, points[2] - points[0]) / lever_m
    return np.stack([gy[:, 2], -gx[:, 2], gx[:, 1]], axis=1)


def _marker_offsets(n: int, lever_m: float) -> list[np.ndarray]:
    return [np.zeros((n, 3)), np.tile([lever_m, 0.0, 0.0], (n, 1)), np.tile([0.0, lever_m, 0.0], (n, 1))]


def _marker_rotation(mm: MeasurementModel, est: Estimate, Q: np.ndarray) -> np.ndarray:
    """``(N, 3, 3)`` marker orientation of the identified model in the identified tracker frame."""
    _, R_base = mm.base_positions(Q, est.x)
    return np.einsum("ji,njk->nik", est.transform_tracker_to_base.rotation, R_base)


def orientation_jacobian(mm: MeasurementModel, est: Estimate, Q: np.ndarray,
                         lever_m: float = MARKER_LEVER_M) -> np.ndarray:
    """``(N, 3, p)`` Jacobian of the marker-frame orientation (rad) wrt the identified parameters
    ``theta`` at configurations ``Q`` (``S J`` of the module docstring; marker-point model)."""
    J = [mm.jacobian(Q, est.x, est.registration, est.basis, offsets=o)[1] for o in _marker_offsets(len(Q), lever_m)]
    return _orientation_rows(_marker_rotation(mm, est, Q), J, lever_m)


def predicted_orientation_covariance(mm: MeasurementModel, est: Estimate, Q: np.ndarray,
                                     gravity: GravityCovariance | None = None,
                                     lever_m: float = MARKER_LEVER_M) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 3, 3)`` covariance of the marker-frame orientation error (rad) of the identified model
    at each configuration, without reading noise (module docstring; needs a marker-point model,
    ``mm.marker_points``), and ``(N,)`` its gravity-model part."""
    Jw = orientation_jacobian(mm, est, Q, lever_m)
    Bw = None
    if _gravity_active(est, gravity):
        x_g = gravity_linearisation_point(mm, est)
        B = [gravity.factors(Q, x_g, est.registration, offsets=o) for o in _marker_offsets(len(Q), lever_m)]
        Bw = _orientation_rows(_marker_rotation(mm, est, Q), B, lever_m)
    return _model_covariance(Jw, est, Bw)


def orientation_noise_rad(mm: MeasurementModel, est: Estimate, rec: Measurements, rejected_rows: np.ndarray,
                          stated_sigma_rad: float, lever_m: float = MARKER_LEVER_M) -> tuple[float, float]:
    """``(sigma_rot, remainder)``: 1-sigma per axis (rad) of a 6-D reading's orientation, the stated
    ``stated_sigma_rad`` and a remainder ``tau`` combined, ``sigma_rot^2 = stated^2 + tau^2``.

    ``tau`` is the REML estimate (:func:`pipeline.calibration.noise_model.reml_remainder`) on the
    fit's orientation residuals ``w_i = S (e_0, e_x, e_y)_i`` (the map ``S`` of the module
    docstring applied to the fitted marker-point residuals of pose ``i``) with their Jacobian
    ``S J_i``, over the poses none of whose rows the fit rejected (the stated value alone when those
    give no more rows than the ``p`` parameters). REML removes the ``p`` fitted
    directions from these ``3 n`` rows as if they alone had fitted the parameters, where the fit
    also had the positions: ``tau`` is then on the large side, the prediction conservative.
    ``rec``: the fitted rows as :func:`pipeline.calibration.measure.expand_orientation` writes them
    (the ``n`` origins, then the ``n`` x points, then the ``n`` y points)."""
    n = len(rec) // 3
    if rec.pose_index is None or not np.array_equal(rec.pose_index, np.tile(np.arange(n), 3)):
        raise ValueError("orientation_noise_rad: rec is not a 6-D record expanded by measure.expand_orientation")
    keep = np.ones(n, bool)
    keep[rec.pose_index[np.asarray(rejected_rows, int)]] = False
    if 3 * int(keep.sum()) <= est.basis.shape[1]:
        return stated_sigma_rad, 0.0    # no orientation rows beyond the fitted directions: nothing to estimate
    e = (rec.Y - mm.predict(rec.Q, est.x, est.registration, None, rec.offset_m)).reshape(3, n, 3)[:, keep]
    Q = rec.Q[:n][keep]
    w = _orientation_rows(_marker_rotation(mm, est, Q), [e_k[:, :, None] for e_k in e], lever_m)[:, :, 0]
    Jw = orientation_jacobian(mm, est, Q, lever_m)
    tau, _ = nm.reml_remainder(w, Jw, np.full(len(Q), stated_sigma_rad))
    return math.sqrt(stated_sigma_rad ** 2 + tau ** 2), tau


def _stacked_factors(mm: MeasurementModel, est: Estimate, Q: np.ndarray, gravity: GravityCovariance | None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """``(F, G)`` with ``F G F^T`` the (3N, 3N) model part of the stacked held-out position errors'
    covariance: ``F = J`` (stacked Jacobian), ``G = C_theta``; with the gravity prior
    ``F = [J, B - J M]``, ``G = diag(C_theta - M M^T, I)``: the terms of :func:`_model_covariance`,
    between poses too."""
    _, J = mm.jacobian(Q, est.x, est.registration, est.basis)
    n_rows = 3 * len(Q)
    F = np.asarray(J, float).reshape(n_rows, -1)
    G = np.asarray(est.covariance, float)
    M = est.gravity_gain
    if gravity is None or M is None or not _gravity_active(est, gravity):
        return F, G
    R = (gravity.factors(Q, gravity_linearisation_point(mm, est), est.registration) - J @ M).reshape(n_rows, -1)
    p, r = G.shape[0], R.shape[1]
    G_full = np.zeros((p + r, p + r))
    G_full[:p, :p] = est.readings_covariance
    G_full[p:, p:] = np.eye(r)
    return np.hstack([F, R]), G_full


def heldout_error_moments(mm: MeasurementModel, est: Estimate, Q: np.ndarray, sigma_m: np.ndarray,
                          gravity: GravityCovariance | None = None, residual_map: ResidualMap | None = None) -> dict:
    """Spectrum of the covariance ``C`` of the stacked position errors of readings at ``Q`` (3N):
    ``C = F G F^T + diag(d)`` (:func:`_stacked_factors`; ``d`` per axis ``sigma_k^2``, with the
    ``residual_map`` its reading variance ``s_map(q_k)^2 + s_n^2`` instead (:func:`predicted_error`),
    taken independent between poses: the map's predict gives no posterior covariance). Its diagonal
    blocks are :func:`predicted_covariance` without the map (``trace C = N E|e|^2`` of
    :func:`predicted_error`); the off-diagonal blocks hold the parameter
    error every pose shares. ``stacked_components`` = 3N, ``stacked_trace_m2 = trace C``,
    ``stacked_square_trace_m4 = trace C^2`` (from the factors, ``trace (G K)^2 + 2 sum d_i
    (F G F^T)_ii + sum d^2``, ``K = F^T F``) and, up to :data:`EXACT_QUANTILE_MAX_COMPONENTS`
    components, ``stacked_eigenvalues_m2`` (else None)."""
    F, G = _stacked_factors(mm, est, Q, gravity)
    var_axis = np.asarray(sigma_m, float) ** 2
    if residual_map is not None:
        var_axis = residual_map.predict_reading(Q)[1] ** 2
    d = np.repeat(var_axis, 3)
    diag_model = np.einsum("ij,jk,ik->i", F, G, F)
    GK = G @ (F.T @ F)
    trace = float(np.sum(diag_model) + np.sum(d))
    square_trace = float(np.sum(GK * GK.T) + 2.0 * np.sum(d * diag_model) + np.sum(d ** 2))
    eig = None
    if len(d) <= EXACT_QUANTILE_MAX_COMPONENTS:
        eig = np.clip(np.linalg.eigvalsh(F @ G @ F.T + np.diag(d)), 0.0, None)
    return {"stacked_components": int(len(d)), "stacked_trace_m2": trace, "stacked_square_trace_m4": square_trace,
            "stacked_eigenvalues_m2": eig}


def predicted_error(mm: MeasurementModel, est: Estimate, Q: np.ndarray, sigma_m: np.ndarray,
                    gravity: GravityCovariance | None = None, residual_map: ResidualMap | None = None) -> dict:
    """Covariance-predicted tracker-measured position error at configurations ``Q`` (no measurement
    needed): ``E|e_k|^2 = trace(J_k C J_k^T) + 3 sigma_k^2`` (paper 000 eq. 16), with ``gravity``
    the gravity-model term of the module docstring. With the calibration's ``residual_map``
    applied the reading's part is the map's (:meth:`pipeline.robot.residual_map.ResidualMap.predict_reading`):
    ``3 (s_map(q_k)^2 + s_n^2)``, its posterior variance and the noise it did not explain, in place
    of ``3 sigma_k^2``, whose remainder held the smooth part the map explains."""
    cov, var_gravity = predicted_covariance(mm, est, Q, sigma_m, gravity)
    var_noise = 3.0 * np.asarray(sigma_m, float) ** 2
    var_map, var_reading = np.zeros(len(Q)), var_noise
    if residual_map is not None:
        var_map = 3.0 * residual_map.predict(Q)[1] ** 2
        var_reading = np.full(len(Q), 3.0 * residual_map.noise_std_m ** 2)
    var_total = np.trace(cov, axis1=1, axis2=2) - var_noise + var_reading + var_map
    var_model = var_total - var_gravity - var_map - var_reading
    return {"n_poses": int(len(Q)), "predicted_rms_m": float(np.sqrt(np.mean(var_total))),
            "predicted_residual_map_rms_m": float(np.sqrt(np.mean(var_map))),
            "predicted_model_rms_m": float(np.sqrt(max(np.mean(var_model), 0.0))),
            "predicted_gravity_model_rms_m": float(np.sqrt(np.mean(var_gravity))),
            "gravity_model_share": float(np.mean(var_gravity) / np.mean(var_total)),
            "noise_total_sigma_m": float(np.sqrt(np.mean(np.asarray(sigma_m, float) ** 2))),
            "predicted_std_m": np.sqrt(var_total)}


def predicted_on_random_poses(robot: RobotModel, mm: MeasurementModel, est: Estimate, cfg: Config,
                              rng: np.random.Generator, gravity: GravityCovariance | None = None,
                              noise: nm.NoiseModel | None = None, residual_map: ResidualMap | None = None) -> dict:
    """Covariance-predicted error over ``n_heldout`` random collision-free poses visible to the
    identified tracker (nominal model only: nothing is measured)."""
    chain = cd.chain_from_robot(robot, est.transform_tracker_to_base)
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(1.0), 0.005)
    Q, _ = cd.random_candidates(chain, cfg.n_heldout, rng, margins)
    sigma = (noise or nm.NoiseModel()).total(noise_model_sigma(robot, mm.predict(Q, est.x, est.registration)))
    return predicted_error(mm, est, Q, sigma, gravity, residual_map)



def fit_residuals(mm: MeasurementModel, est: Estimate, meas: Measurements,
                  rejected: np.ndarray | None = None) -> dict:
    """Residuals of the calibration measurements themselves (in-sample, not a validation):
    ``|y_k - h(q_k, x, T_tb)|`` after the fit and with the nominal model + registration before,
    over the readings kept by the outlier test (``rejected``: row indices left out)."""
    x0 = np.zeros(mm.n)
    keep = np.ones(len(meas), bool)
    if rejected is not None:
        keep[np.asarray(rejected, int)] = False
    Q, Y = meas.Q[keep], meas.Y[keep]
    mounted = None if meas.payload_mounted is None else meas.payload_mounted[keep]
    offsets = None if meas.offset_m is None else meas.offset_m[keep]
    r_before = np.linalg.norm(Y - mm.predict(Q, x0, est.registration, mounted, offsets), axis=1)
    r_after = np.linalg.norm(Y - mm.predict(Q, est.x, est.registration, mounted, offsets), axis=1)
    return {"n_points": int(keep.sum()), "source": meas.source,
            "rms_residual_before_m": float(np.sqrt(np.mean(r_before ** 2))),
            "rms_residual_after_m": float(np.sqrt(np.mean(r_after ** 2))),
            "max_residual_after_m": float(r_after.max()),
            "chi2_per_dof": float(est.chi2_per_dof),
            "residuals_after_m": r_after}


def fit_markdown(fit: dict, prediction: dict | None) -> str:
    """Fit residuals (and the covariance prediction when there is no held-out set) in mm."""
    lines = [f"Fit residuals on the {fit['n_points']} calibration measurements (in-sample, not a validation):",
             "", "| ‖y − h‖ on the calibration points | RMS [mm] | max [mm] |", "|---|---|---|",
             f"| before (nominal model, registered tracker) | {1e3 * fit['rms_residual_before_m']:.4f} | |",
             f"| after the fit | {1e3 * fit['rms_residual_after_m']:.4f} | {1e3 * fit['max_residual_after_m']:.4f} |",
             "", f"chi²/dof = {fit['chi2_per_dof']:.3f} (1 if the tracker noise model, and for the elastostatic "
             "model the gravity-model prior, are right)."]
    if prediction is not None:
        lines += ["", f"Covariance-predicted RMS position error over {prediction['n_poses']} random visible poses "
                  f"(parameter covariance + tracker noise): {1e3 * prediction['predicted_rms_m']:.4f} mm "
                  f"(model part {1e3 * prediction['predicted_model_rms_m']:.4f} mm, gravity-model part "
                  f"{1e3 * prediction['predicted_gravity_model_rms_m']:.4f} mm)."]
    return "\n".join(lines)


def gross_error_rows(mm: MeasurementModel, est: Estimate, meas: Measurements, confidence: float,
                     gravity: GravityCovariance | None = None) -> np.ndarray:
    """Held-out readings that fail the calibration's outlier test (:mod:`pipeline.calibration.robust`:
    chi-square, 3 dof, at ``confidence``, scaled by the robust residual scale) under the identified
    model: a gross tracker error says nothing about the calibration's accuracy. Each reading is
    whitened by its predicted error covariance (:func:`predicted_covariance`: tracker noise,
    parameter uncertainty and, with ``gravity``, the gravity-model part)."""
    cov, _ = predicted_covariance(mm, est, meas.Q, meas.sigma_m, gravity)
    e = meas.Y - mm.predict(meas.Q, est.x, est.registration)
    w = np.sqrt(np.einsum("ni,nij,nj->n", e, np.linalg.inv(cov), e))
    scale = max(1.0, float(np.sqrt(np.median(w ** 2) / chi2.ppf(0.5, 3))))
    return np.flatnonzero(w > np.sqrt(chi2.ppf(confidence, 3)) * scale)


def recorded_gross_rows(mm: MeasurementModel, est: Estimate, meas: Measurements, confidence: float,
                        fit_norm: np.ndarray, max_rows: int, gravity: GravityCovariance | None = None) -> np.ndarray:
    """Readings of a recorded held-out file that fail the calibration's outlier test at the
    calibration's own residual scale: each reading whitened by its predicted error covariance
    (:func:`predicted_covariance`), ``w_k > u sqrt(chi2_3(confidence))`` with
    ``u = max(1, sqrt(median(s_j) / chi2_3.median))`` over the fit's whitened training residuals
    ``s_j = fit_norm_j^2`` (:class:`pipeline.calibration.robust.Rejection`), not over the held-out
    file: a median over a few held-out readings breaks down when half of them are gross (two of
    four) and hides them. At most ``max_rows`` (the caller's share of ``max_outlier_fraction`` of
    the whole record), and never every reading of the file: if more fail, or all of them (a
    held-out file of one pose), none is left out (the model, not the readings, is off, or the file
    holds nothing to tell them apart by), and the held-out figures count every reading."""
    cov, _ = predicted_covariance(mm, est, meas.Q, meas.sigma_m, gravity)
    e = meas.Y - mm.predict(meas.Q, est.x, est.registration)
    w = np.sqrt(np.einsum("ni,nij,nj->n", e, np.linalg.inv(cov), e))
    s = np.asarray(fit_norm, float) ** 2
    scale = max(1.0, float(np.sqrt(np.median(s) / chi2.ppf(0.5, 3)))) if s.size else 1.0
    bad = np.flatnonzero(w > np.sqrt(chi2.ppf(confidence, 3)) * scale)
    return bad if len(bad) <= max(int(max_rows), 0) and len(bad) < len(w) else np.zeros(0, int)


def orientation_stats(mm: MeasurementModel, x: np.ndarray, R_tb: np.ndarray, Q: np.ndarray, rotvec: np.ndarray
                      ) -> dict[str, float]:
    """Mean, RMS and max (rad) of the angle between the read marker frames (rotation vectors
    ``rotvec`` in the tracker frame) and those of the model ``x`` at ``Q``, ``R_tb`` the rotation of
    the tracker-to-base registration."""
    _, R_refl = mm.base_positions(Q, x)
    R_pred = np.einsum("ji,njk->nik", R_tb, R_refl)  # tracker-frame orientation
    err = Rotation.from_matrix(np.einsum("nji,njk->nik", R_pred, Rotation.from_rotvec(rotvec).as_matrix())).as_rotvec()
    ang = np.linalg.norm(err, axis=1)
    return {"mean": float(ang.mean()), "rms": float(np.sqrt(np.mean(ang ** 2))), "max": float(ang.max())}


def validate(mm: MeasurementModel, est: Estimate, meas: Measurements, outlier_confidence: float | None = None,
             gravity: GravityCovariance | None = None, orientation_sigma_rad: float = 0.0,
             residual_map: ResidualMap | None = None, gross_rows: np.ndarray | None = None) -> dict:
    """Held-out statistics before/after calibration and the covariance prediction (with the
    gravity-model term when ``gravity`` is given); with ``outlier_confidence`` the held-out readings
    failing the outlier test are left out and counted (``n_rejected``, ``rejected_rows``). 6-D
    held-out readings give orientation errors; with a marker-point model (orientation fitted) also
    their prediction, ``after.orientation_rad.predicted_rms`` (``orientation_sigma_rad`` the 1-sigma
    per axis of a held-out reading) and ``predicted_model_rms`` (the model part alone). With the
    calibration's ``residual_map`` the "after" errors are those of the model plus the map, and the
    prediction includes the map's posterior variance (:func:`predicted_error`). ``gross_rows``: the
    readings left out, decided by the caller (:func:`recorded_gross_rows`), instead of the test
    above; the errors over every reading stand beside (``after_all_poses``). The ``stacked_*`` entries:
    the spectrum of the scored poses' stacked error covariance (:func:`heldout_error_moments`), what
    the actual/predicted test needs (:func:`ratio_test`)."""
    rejected = np.zeros(0, int)
    n_measured = len(meas)
    every = meas
    if gross_rows is not None:
        rejected = np.asarray(gross_rows, int)
    elif outlier_confidence is not None:
        rejected = gross_error_rows(mm, est, meas, outlier_confidence, gravity)
    if len(rejected):
        keep = np.ones(len(meas), bool)
        keep[rejected] = False
        meas = Measurements(meas.Q[keep], meas.Y[keep], meas.sigma_m[keep], meas.source,
                            None if meas.rotvec is None else meas.rotvec[keep], meas.n_requested)
    Q, Y = meas.Q, meas.Y
    x0 = np.zeros(mm.n)
    R_before = est.registration.rotation
    R_after = est.transform_tracker_to_base.rotation
    e_before = (Y - mm.predict(Q, x0, est.registration)) @ R_before.T
    e_after = (Y - mm.predict(Q, est.x, est.registration)) @ R_after.T
    if residual_map is not None:       # the calibrated model handed on: rigid/elastic model + map
        e_after = e_after - residual_map.predict(Q)[0]
    pred = predicted_error(mm, est, Q, meas.sigma_m, gravity, residual_map)
    moments = heldout_error_moments(mm, est, Q, meas.sigma_m, gravity, residual_map)
    out = {
        "n_poses": int(n_measured),
        "source": meas.source,
        "before": _stats(e_before) | {"axes": _axis_stats(e_before)},
        "after": _stats(e_after) | {"axes": _axis_stats(e_after)},
        "predicted_rms_m": pred["predicted_rms_m"],
        "predicted_model_rms_m": pred["predicted_model_rms_m"],
        "predicted_gravity_model_rms_m": pred["predicted_gravity_model_rms_m"],
        "gravity_model_share": pred["gravity_model_share"],
        "noise_total_sigma_m": pred["noise_total_sigma_m"],
        "errors_before_m": np.linalg.norm(e_before, axis=1),
        "errors_after_m": np.linalg.norm(e_after, axis=1),
        "predicted_std_m": pred["predicted_std_m"],
        "n_rejected": int(len(rejected)),
        "rejected_rows": [int(i) for i in rejected],
    } | moments
    if gross_rows is not None or len(rejected):   # every held-out reading counted, beside the screened figures
        e_all = (every.Y - mm.predict(every.Q, est.x, est.registration)) @ R_after.T
        if residual_map is not None:
            e_all = e_all - residual_map.predict(every.Q)[0]
        out["after_all_poses"] = _stats(e_all)
        if every.rotvec is not None:
            out["after_all_poses"]["orientation_rad"] = orientation_stats(mm, est.x, R_after, every.Q, every.rotvec)
    if meas.rotvec is not None:
        for key, R_tb, x in (("before", est.registration.rotation, x0), ("after", R_after, est.x)):
            out[key]["orientation_rad"] = orientation_stats(mm, x, R_tb, Q, meas.rotvec)
        if mm.marker_points:
            cov_w, _ = predicted_orientation_covariance(mm, est, Q, gravity)
            var_w = np.trace(cov_w, axis1=1, axis2=2)
            out["after"]["orientation_rad"] |= {
                "predicted_rms": float(np.sqrt(np.mean(var_w) + 3 * orientation_sigma_rad ** 2)),
                "reading_sigma": float(orientation_sigma_rad),
                "predicted_model_rms": float(np.sqrt(np.mean(var_w)))}
    return out


def table_markdown(v: dict) -> str:
    """Paper 004 Table 2 layout: maximum and half peak-to-peak per axis, before/after, in mm."""
    b, a = v["before"], v["after"]
    lines = ["| error | max uncal. [mm] | max cal. [mm] | ± uncal. [mm] | ± cal. [mm] |", "|---|---|---|---|---|"]
    for ax in "xyz":
        ba, aa = b["axes"][ax], a["axes"][ax]
        lines.append(f"| e{ax} | {1e3 * ba['max_abs']:.3f} | {1e3 * aa['max_abs']:.3f} | "
                     f"±{1e3 * ba['half_peak_to_peak']:.3f} | ±{1e3 * aa['half_peak_to_peak']:.3f} |")
    lines += ["", "| ‖e‖ over held-out poses | mean [mm] | RMS [mm] | max [mm] |", "|---|---|---|---|"]
    for key, s in (("before", b), ("after", a)):
        lines.append(f"| {key} | {1e3 * s['mean']:.4f} | {1e3 * s['rms']:.4f} | {1e3 * s['max']:.4f} |")
    lines.append(f"| predicted (covariance + noise) | | {1e3 * v['predicted_rms_m']:.4f} | |")
    if v.get("n_rejected"):
        lines.append(f"\n{v['n_rejected']} held-out reading(s) failed the outlier test (gross tracker errors) and are "
                     "left out of these statistics.")
        if "after_all_poses" in v:
            every = v["after_all_poses"]
            rot = (f"; orientation RMS {np.rad2deg(every['orientation_rad']['rms']):.4f} deg, max "
                   f"{np.rad2deg(every['orientation_rad']['max']):.4f} deg" if "orientation_rad" in every else "")
            lines.append(f"Over every held-out reading: RMS {1e3 * every['rms']:.4f} mm, max "
                         f"{1e3 * every['max']:.4f} mm after calibration{rot}.")
    if "orientation_rad" in a:
        lines += ["", "| orientation error | mean [deg] | RMS [deg] | max [deg] |", "|---|---|---|---|"]
        for key, s in (("before", b), ("after", a)):
            o = s["orientation_rad"]
            lines.append(f"| {key} | {np.rad2deg(o['mean']):.4f} | {np.rad2deg(o['rms']):.4f} | "
                         f"{np.rad2deg(o['max']):.4f} |")
        if "predicted_rms" in a["orientation_rad"]:
            o = a["orientation_rad"]
            lines.append(f"| predicted (covariance + noise) | | {np.rad2deg(o['predicted_rms']):.4f} | |")
            lines.append(f"| predicted, model part (exact readings) | | {np.rad2deg(o['predicted_model_rms']):.4f} | |")
            if "reading_sigma" in o:
                lines.append("\nOrientation noise of a reading in the prediction: "
                             f"{np.rad2deg(o['reading_sigma']):.4f} deg per axis (the stated "
                             "calibration.orientation_sigma_rad and a remainder estimated by REML on the fit's "
                             "orientation residuals).")
    else:
        lines.append("\nOrientation errors: not measured (the laser tracker reads positions only).")
    return "\n".join(lines)
