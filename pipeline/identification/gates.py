"""Quality gates of the identification stage (:mod:`pipeline.quality`).

* :func:`check_data_excites` (a hard error, before any fit): every joint must move by at least
  ``min_joint_motion_rad`` (peak to peak) in the record, and the base regressor on the data must
  have full column rank (numerical rank, ``s_min > n eps s_max``) with a condition number below
  ``max_cond_base_regressor_data``. A record in which the robot never moves fails here with a
  message instead of an "identification" with cond 1e50.
* :func:`add_result_gates`: the physically consistent fit's IPOPT status is a success, the fitted
  base regressor's condition number within
  ``max_cond_data_over_design`` x the design criterion's (when an excitation was designed),
  the validation RMS per joint at most ``max_validation_rms_over_noise`` x the noise estimate,
  and the model's predicted torques on the validation path at most
  ``max_predicted_torque_over_limit`` x the joint torque limits.
* :func:`model_class_structure` (a warning, not a failure: a record's model class, not its data):
  per joint, the fit residual's autocorrelation at one period of the position filter's cut-off
  (band-limited noise has decorrelated there: for white noise through an ideal low-pass at ``f_c``
  the autocorrelation at lag ``1 / f_c`` is ``sinc(2) = 0``; what is left is slow structure the
  model class does not explain, such as friction of another shape or an effort-to-torque constant
  off), and the held-out RMS over the fit residual (structure that changes over the record).
  A third figure where the record's rate leaves a band above the position cut-off: the held-out RMS
  over a model-free noise estimate, the torques' white-noise level in that band (the model, built
  from states filtered at the cut-off, predicts nothing there) extended to the whole band
  (:func:`band_noise_sigma`). Any of them above its bound (:data:`MAX_RESIDUAL_AUTOCORRELATION`,
  :data:`MAX_HELDOUT_OVER_FIT`, :data:`MAX_HELDOUT_OVER_NOISE`) flags the joint in the summary, the
  report and the run's headline warnings.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from pipeline.core.errors import DataFileError, PipelineError
from pipeline.core.solver_status import is_success
from pipeline.identification.config import Config
from pipeline.quality import QualityGates


def check_data_excites(
    q: np.ndarray, Wb: np.ndarray, joint_names: list[str], min_motion_rad: float, max_cond: float,
    source: str | None,
) -> float:
    """Raise unless the data excite the base parameters; returns ``cond(Wb)``."""
    field = "identification.data_file" if source else "identification.excitation"
    err = DataFileError if source else PipelineError
    motion = np.ptp(np.asarray(q, float), axis=0) if len(q) else np.zeros(len(joint_names))
    still = [f"{n} ({m:.2g} rad)" for n, m in zip(joint_names, motion, strict=True) if not m >= min_motion_rad]
    if still:
        raise err(source, field, f"the robot does not move enough to identify its dynamics: joint(s) "
                  f"{', '.join(still)} move less than identification.min_joint_motion_rad = {min_motion_rad:g} rad "
                  "peak to peak")
    s = np.linalg.svd(Wb, compute_uv=False) if Wb.size else np.zeros(1)
    tol = max(Wb.shape) * np.finfo(float).eps * (s[0] if s.size else 0.0)
    rank = int(np.sum(s > tol))
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else float("inf")
    if rank < Wb.shape[1]:
        raise err(source, field, f"the base regressor on the data has rank {rank} < {Wb.shape[1]} base parameters: "
                  "the motion does not excite every base parameter")
    if not cond <= max_cond:
        raise err(source, field, f"the base regressor on the data has condition number {cond:.3g} > "
                  f"identification.max_cond_base_regressor_data = {max_cond:.3g}: the motion does not excite "
                  "every base parameter")
    return cond


#: a joint's fit residual correlating above this at one cut-off period is structure, not noise
MAX_RESIDUAL_AUTOCORRELATION = 0.5
#: a joint's held-out RMS above this x its fit residual: the model class does not hold over the record
MAX_HELDOUT_OVER_FIT = 1.5


#: a joint's held-out RMS above this x the model-free noise estimate: structure, not noise
MAX_HELDOUT_OVER_NOISE = 3.0


def band_noise_sigma(tau_Nm: np.ndarray, sample_time_s: float, cutoff_hz: float, top_hz: float) -> np.ndarray:
    """Per joint white-noise sigma of the torques (N, nr) from their power spectral density (Welch)
    between 1.2 x the position cut-off and 0.9 x ``top_hz`` (the highest frequency the processing
    keeps: Nyquist, or the decimation filter's edge), its median density times ``top_hz``; NaN where
    the record's rate leaves no such band."""
    tau = np.asarray(tau_Nm, float)
    fs = 1.0 / sample_time_s
    n = tau.shape[0]
    f, P = scipy.signal.welch(tau - tau.mean(axis=0), fs=fs, nperseg=max(8, min(256, n // 4)), axis=0)
    band = (f > 1.2 * cutoff_hz) & (f < 0.9 * top_hz)
    if np.count_nonzero(band) < 2:
        return np.full(tau.shape[1], np.nan)
    return np.sqrt(np.median(P[band], axis=0) * top_hz)


def residual_autocorrelation(residual_Nm: np.ndarray, lag: int) -> np.ndarray:
    """Per joint (column) autocorrelation of the residual (mean removed) at ``lag`` samples."""
    r = np.asarray(residual_Nm, float)
    r = r - r.mean(axis=0)
    den = np.sum(r * r, axis=0)
    num = np.sum(r[lag:] * r[:-lag], axis=0) if 0 < lag < len(r) else np.zeros(r.shape[1])
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def model_class_structure(residual_Nm: np.ndarray, heldout_rms_Nm: np.ndarray, lag: int,
                          joint_numbers: np.ndarray, noise_sigma_Nm: np.ndarray | None = None) -> dict:
    """The model-class check of the module doc on a record: the fit residual (N, nr) on all samples,
    the held-out RMS per joint (nr,), the lag of one cut-off period in samples, the joints' 1-based
    numbers and the model-free noise estimate (:func:`band_noise_sigma`; None or NaN: not checked).
    Returns summary entries (JSON-able) with ``warnings`` naming the flagged joints."""
    res = np.asarray(residual_Nm, float)
    fit_rms = np.sqrt(np.mean(res**2, axis=0))
    acf = residual_autocorrelation(res, lag)
    heldout = np.asarray(heldout_rms_Nm, float)
    ratio = heldout / np.maximum(fit_rms, 1e-300)
    noise = np.full(len(fit_rms), np.nan) if noise_sigma_Nm is None else np.asarray(noise_sigma_Nm, float)
    over_noise = heldout / np.where(noise > 0, noise, np.nan)
    flagged = (acf > MAX_RESIDUAL_AUTOCORRELATION) | (ratio > MAX_HELDOUT_OVER_FIT) | (
        np.nan_to_num(over_noise, nan=0.0) > MAX_HELDOUT_OVER_NOISE)
    numbers = [int(n) for n in np.asarray(joint_numbers)[flagged]]
    out: dict = {"model_class_residual_autocorrelation": [float(a) for a in acf],
                 "model_class_residual_lag_samples": int(lag),
                 "model_class_heldout_over_fit": [float(x) for x in ratio],
                 "model_class_heldout_over_noise": [None if not np.isfinite(x) else float(x) for x in over_noise],
                 "model_class_structure_joints": numbers,
                 "model_class_bounds": {"residual_autocorrelation": MAX_RESIDUAL_AUTOCORRELATION,
                                        "heldout_over_fit": MAX_HELDOUT_OVER_FIT,
                                        "heldout_over_noise": MAX_HELDOUT_OVER_NOISE}}
    if numbers:
        why = [f"joint {n}: residual autocorrelation {a:.2f} at {lag} samples, held-out / fit RMS {x:.2f}"
               + ("" if not np.isfinite(z) else f", held-out / noise {z:.2f}")
               for n, a, x, z in zip(np.asarray(joint_numbers)[flagged], acf[flagged], ratio[flagged],
                                     over_noise[flagged], strict=True)]
        out["warnings"] = [f"the friction/actuation model class leaves structure unexplained on joint(s) "
                           f"{', '.join(map(str, numbers))} (bounds {MAX_RESIDUAL_AUTOCORRELATION:g}, "
                           f"{MAX_HELDOUT_OVER_FIT:g}, {MAX_HELDOUT_OVER_NOISE:g}): " + "; ".join(why)]
    return out


def add_result_gates(
    gates: QualityGates, cfg: Config, cond_data: float, cond_design: float | None, rms_over_noise: np.ndarray,
    predicted_Nm: np.ndarray, effort_limit_Nm: np.ndarray, physical_status: str = "Solve_Succeeded",
    joint_numbers: np.ndarray | None = None,
) -> None:
    """The result gates (see module doc) with the thresholds of ``cfg`` (stage Config). The per-joint
    arrays hold the measured joints only; ``joint_numbers`` (1-based) names them (default 1..n)."""
    ratio = np.asarray(rms_over_noise, float)
    numbers = np.arange(1, ratio.size + 1) if joint_numbers is None else np.asarray(joint_numbers, int)
    gates.require("physical_fit_status", is_success(physical_status),
                  f"IPOPT returned {physical_status} for the physically consistent fit (identification."
                  "physical_max_iter)")
    if cond_design is not None:
        gates.check("cond_data_over_design", cond_data / cond_design, "<=", cfg.max_cond_data_over_design,
                    "fitted base regressor on the data vs the design criterion (identification."
                    "max_cond_data_over_design)")
    worst = int(np.nanargmax(ratio)) if ratio.size and np.any(np.isfinite(ratio)) else 0
    gates.check("validation_rms_over_noise", float(np.max(ratio)) if ratio.size else float("nan"), "<=",
                cfg.max_validation_rms_over_noise,
                f"worst joint {numbers[worst]}; identification.max_validation_rms_over_noise")
    lim = np.asarray(effort_limit_Nm, float)
    over = np.max(np.abs(predicted_Nm), axis=0) / lim if len(predicted_Nm) else np.zeros_like(lim)
    j = int(np.argmax(over))
    gates.check("predicted_torque_over_limit", float(over[j]), "<=", cfg.max_predicted_torque_over_limit,
                f"joint {numbers[j]}: max |predicted torque| on the validation path / torque limit "
                f"{lim[j]:.4g} N·m; identification.max_predicted_torque_over_limit")
