"""The calibration's quality gates: the fit's chi²/dof under the noise model, actual/predicted on
held-out or cross-validated poses, and the error after calibration against the nominal model's
(both less the stated reading noise, :func:`error_above_noise_ratio`).

The gate on actual/predicted (:func:`check_gates`) is a one-sided test, not a comparison of the
sample ratio with a fixed bound. The stacked held-out position errors ``e = (e_1, ..., e_N)`` of the
scored poses are, under the prediction, ``N(0, C)`` with ``C`` (3N x 3N,
:func:`pipeline.calibration.validate.heldout_error_moments`) the parameter covariance propagated
through the stacked Jacobian (the parameter error, and with the gravity prior the inertial error,
are common to every pose: ``C_hl = J_h C_theta J_l^T`` off the diagonal) plus each reading's noise.
With ``m`` = ``max_actual_over_predicted`` the hypothesis ``H0: e ~ N(0, s^2 C), s <= m`` is
rejected when ``e^T e`` exceeds ``m^2 q_a``, ``q_a`` the ``a``-quantile (``a`` =
``actual_over_predicted_confidence``) of ``e^T e`` under ``N(0, C)``: a generalized chi-square
``sum_j lambda_j chi2_1`` over the eigenvalues ``lambda_j`` of ``C``. Since actual/predicted is
``sqrt(e^T e / trace C)``, the bound on the ratio is ``m sqrt(q_a / trace C)`` (:func:`ratio_test`).
``q_a`` is exact (Imhof 1961, numerical inversion of the characteristic function,
:mod:`pipeline.core.quadratic_forms`) up to
:data:`pipeline.calibration.validate.EXACT_QUANTILE_MAX_COMPONENTS` components, beyond that the
Satterthwaite–Welch approximation ``e^T e ~ g chi2_nu``, ``g = sum lambda^2 / sum lambda``,
effective degrees of freedom ``nu = (sum lambda)^2 / sum lambda^2``, whose bound is ``m
sqrt(chi2_nu(a) / nu)``. Few poses, or a covariance dominated by a few directions (the parameter
part, common to every pose), give few effective degrees of freedom and a wide bound; many poses of a
noise-dominated prediction give ``nu`` of the order of 3N and a bound that shrinks towards ``m``, as
``m (1 + z_a / sqrt(2 nu))`` roughly, never to ``m`` itself (the sampling spread of an RMS only
vanishes with infinitely many poses). The pessimistic side is the mirror test, a warning only: ``H0:
s >= 1/m`` rejected when ``e^T e < q_(1-a) / m^2``.
"""

from __future__ import annotations

import math

from scipy.stats import chi2

from pipeline.core.quadratic_forms import weighted_chi2_quantile
from pipeline.quality import QualityGates


def ratio_test(moments: dict, max_ratio: float, confidence: float) -> dict:
    """Bounds of the one-sided tests on actual/predicted ``sqrt(e^T e / trace C)`` (module
    docstring) from the stacked covariance's ``moments`` of the scored poses
    (:func:`pipeline.calibration.validate.heldout_error_moments`, also in the validation dict):
    ``threshold = m sqrt(q_a / trace C)`` (rejects ``s <= m``, the gate) and ``lower_threshold =
    (1/m) sqrt(q_(1-a) / trace C)`` (rejects ``s >= 1/m``, a warning), with ``effective_dof =
    (trace C)^2 / trace C^2``; ``method`` "Imhof" (exact) or "Satterthwaite-Welch" (``q = g chi2_nu``)."""
    trace = moments["stacked_trace_m2"]
    nu = trace ** 2 / moments["stacked_square_trace_m4"]
    eig = moments.get("stacked_eigenvalues_m2")
    if eig is not None:
        method = "Imhof"
        q_hi, q_lo = (weighted_chi2_quantile(eig, p) / trace for p in (confidence, 1.0 - confidence))
    else:
        method = "Satterthwaite-Welch"
        q_hi, q_lo = (float(chi2.ppf(p, nu)) / nu for p in (confidence, 1.0 - confidence))
    return {"source": "held-out", "method": method, "confidence": float(confidence),
            "n_scored_poses": int(moments["stacked_components"]) // 3,
            "effective_dof": float(nu), "max_actual_over_predicted": float(max_ratio),
            "threshold": float(max_ratio * math.sqrt(q_hi)), "lower_threshold": float(math.sqrt(q_lo) / max_ratio)}


def stated_noise_rms_m(summary: dict) -> float:
    """RMS length of a position reading's stated noise: ``sqrt(3 (s^2 + r^2))`` with ``s`` the
    sensor's 1-sigma per axis and ``r`` the arm's repeatability as the noise model used it
    (robot.yaml's when stated; 0 when the record's remainder took its place). The REML remainder is
    not part of it: it holds whatever the model leaves, noise or inadequacy alike."""
    sensor = float(summary.get("noise_sensor_sigma_m") or 0.0)
    repeatability = float(summary.get("noise_repeatability_sigma_m") or 0.0)
    return math.sqrt(3.0 * (sensor ** 2 + repeatability ** 2))


def error_above_noise_ratio(after_m: float, before_m: float, noise_m: float) -> float | None:
    """The calibrated model's RMS error over the nominal model's, each less the stated reading
    noise ``noise_m`` (RMS length) in quadrature: ``sqrt(max(a^2 - n^2, 0) / (b^2 - n^2))``, the
    share of the nominal model's systematic error the calibration leaves. A noise the sensor and
    the arm are stated to add is no error of the model: without the subtraction a record whose
    nominal error is a few times its noise could not halve its error however right the model.
    None when the nominal error is within the noise (``b <= n``): nothing to judge."""
    excess_before = before_m ** 2 - noise_m ** 2
    if not excess_before > 0:
        return None
    return math.sqrt(max(after_m ** 2 - noise_m ** 2, 0.0) / excess_before)


def gate_figures(summary: dict) -> tuple[str, float | None, float | None]:
    """The out-of-sample figures the gates judge: ``(source, actual/predicted, after/before)`` from
    the held-out validation, else from the cross-validation, else ``("none", None, None)``.
    After/before is :func:`error_above_noise_ratio` with the stated noise
    (:func:`stated_noise_rms_m`)."""
    noise = stated_noise_rms_m(summary)
    cv = summary.get("cross_validation") or {}
    for source, ratio in (("held-out", summary.get("actual_over_predicted")),
                          ("cross-validated", cv.get("actual_over_predicted"))):
        if ratio is not None:
            after, before = after_and_before_m(summary, source)
            return source, ratio, error_above_noise_ratio(after, before, noise)
    return "none", None, None


def after_and_before_m(summary: dict, source: str) -> tuple[float, float]:
    """RMS position error (m) of the calibrated and of the nominal model on ``source``'s poses
    ("held-out" or "cross-validated"); a missing nominal figure reads 0."""
    if source == "held-out":
        return (float(summary["heldout_rms_position_error_after_m"]),
                float(summary.get("heldout_rms_position_error_before_m") or 0.0))
    cv = summary.get("cross_validation") or {}
    return float(cv["rms_position_error_m"]), float(cv.get("rms_position_error_before_m") or 0.0)


def remainder_hint(summary: dict, noise_m: float) -> str:
    """What to state when the readings scatter well beyond their stated noise ``noise_m``
    (:func:`stated_noise_rms_m`): the REML remainder (1-sigma per axis) against the stated sensor
    and repeatability parts; "" when it is not above twice them. The after/before gate cannot tell
    that scatter from an error of the model."""
    remainder = float(summary.get("noise_remainder_sigma_m") or 0.0)
    stated = noise_m / math.sqrt(3.0)
    if remainder <= 2.0 * stated:
        return ""
    return (f"; the readings scatter {1e3 * remainder:.3g} mm per axis (REML remainder) beyond the stated "
            f"{1e3 * stated:.3g} mm: if that is the sensor's or the arm's noise, state it "
            "(calibration.position_sigma_m or robot.yaml's tracker noise_const_m; repeatability_m) and this gate "
            "judges the error above it")


def ratio_bounds(summary: dict, source: str, max_ratio: float) -> tuple[float, float, str]:
    """``(threshold, lower_threshold, how)`` of the actual/predicted gate: the held-out test's
    bounds (``summary["actual_over_predicted_test"]``, :func:`ratio_test`) and a phrase stating
    them, else (the cross-validated figures, or a summary without the test) the fixed ``m`` and
    ``1/m``. The cross-validated errors come from k fits whose parameter errors are correlated
    through the training readings they share, a covariance no fold's prediction holds, so their
    sum of squares has no stated distribution to test against."""
    test = summary.get("actual_over_predicted_test")
    if source != "held-out" or not test:
        return max_ratio, 1.0 / max_ratio, f"fixed bound {max_ratio:g}"
    how = (f"H0 'true ratio <= {max_ratio:g}' rejected above {test['threshold']:.4g}, where the sum of squared "
           f"errors of the {test['n_scored_poses']} scored pose(s) passes its {100 * test['confidence']:g} % quantile "
           f"under H0 ({test['effective_dof']:.3g} effective dof, {test['method']})")
    return test["threshold"], test["lower_threshold"], how


def check_gates(gates: QualityGates, summary: dict, cfg) -> None:
    """The calibration's quality gates: chi²/dof of the fit under the full noise model (sensor,
    repeatability, remainder: :mod:`pipeline.calibration.noise_model`), actual/predicted on held-out
    or cross-validated poses and the error after calibration against the nominal model's, both less
    the stated reading noise (gross inadequacy, :func:`error_above_noise_ratio`; a nominal model
    already within that noise is a warning, not judged). Held-out actual/predicted fails when the
    one-sided test of the module docstring rejects "the true ratio is at most ``m``"
    (``max_actual_over_predicted``) at
    ``actual_over_predicted_confidence``: the gate's threshold on the ratio is ``m sqrt(q_a / trace C)``;
    below ``(1/m) sqrt(q_(1-a) / trace C)``, a pessimistic prediction, is a warning in the summary.
    The cross-validated ratio is compared with ``m`` and ``1/m`` (:func:`ratio_bounds`). A held-out
    orientation error above its prediction beyond chance is a warning
    (:func:`orientation_prediction_warning`)."""
    gates.check("chi2_per_dof", summary["chi2_per_dof"], "<=", cfg.max_chi2_per_dof,
                "whitened fit residuals after the outlier test under the noise model (sensor, arm repeatability, "
                "remainder estimated by REML); far above 1: the fit did not converge or the remainder estimate failed")
    source, ratio, after_before = gate_figures(summary)
    if ratio is not None:
        threshold, lower, how = ratio_bounds(summary, source, cfg.max_actual_over_predicted)
        what = f"{source} RMS error over its covariance prediction"
        gates.check("actual_over_predicted", ratio, "<=", threshold, f"{what}: the prediction is optimistic; {how}")
        if ratio < lower:   # a pessimistic prediction hands on a sound model with error bars too wide: warned
            summary.setdefault("warnings", []).append(
                f"{what} is {ratio:.3g}, below {lower:.3g}: the prediction is pessimistic (a remainder "
                "estimated from few readings, or a sensor noise stated too high)")
    warning = orientation_prediction_warning(summary, cfg.max_actual_over_predicted,
                                             cfg.actual_over_predicted_confidence)
    if warning:
        summary.setdefault("warnings", []).append(warning)
    noise_m = stated_noise_rms_m(summary)
    if after_before is not None:
        gates.check("error_after_over_before", after_before, "<=", cfg.max_error_after_over_before,
                    f"{source} RMS error of the calibrated model over the nominal model's, each less the stated "
                    f"reading noise ({1e3 * noise_m:.3g} mm RMS): the error model does not explain the readings "
                    f"(calibration.parameters; a wrong tool, tracker or joint order?)"
                    f"{remainder_hint(summary, noise_m)}")
    elif source != "none":
        after, before = after_and_before_m(summary, source)
        summary.setdefault("warnings", []).append(
            f"{source} RMS error of the nominal model, {1e3 * before:.3g} mm, is within the stated reading noise "
            f"({1e3 * noise_m:.3g} mm RMS): the calibration's gain over it is not judged "
            f"(error_after_over_before; calibrated {1e3 * after:.3g} mm)")


def orientation_prediction_warning(summary: dict, m: float, confidence: float) -> str | None:
    """A warning when the held-out orientation error of 6-D readings is above its prediction beyond
    chance: ``rms / predicted > m sqrt(q / (3 n))`` with ``q`` the ``confidence`` quantile of a
    chi-square with ``3 n`` degrees of freedom (``n`` scored poses; the poses' errors taken as
    independent, the parameter error they share neglected). Orientation is not gated: the held-out
    position error is. None: no orientation read, no prediction, or within the bound."""
    rms = summary.get("heldout_rms_orientation_error_after_rad")
    predicted = summary.get("heldout_predicted_rms_orientation_error_rad")
    n = int(summary.get("heldout_n_poses") or 0) - int(summary.get("heldout_n_rejected") or 0)
    if rms is None or not predicted or n <= 0:
        return None
    dof = 3 * n
    bound = m * math.sqrt(float(chi2.ppf(confidence, dof)) / dof)
    ratio = rms / predicted
    if ratio <= bound:
        return None
    return (f"held-out orientation RMS error over its prediction is {ratio:.3g}, above {bound:.3g} ({m:g} with the "
            f"{100 * confidence:g} % chi-square quantile of {n} poses): the orientation noise model is optimistic "
            "(orientation is reported, not gated)")

