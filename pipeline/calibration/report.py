"""Summary (``summary.json``), report (``report.md``), arrays (``results.npz``) and data of the
calibration stage."""

from __future__ import annotations

import math

import numpy as np

from pipeline.calibration import gates as cg
from pipeline.calibration import validate as va
from pipeline.calibration.config import Config
from pipeline.calibration.estimate import MAX_COMPLIANCE_RELATIVE_STD
from pipeline.calibration.outcome import CalibrationOutcome
from pipeline.robot.model import RobotModel


def from_file(out: CalibrationOutcome) -> bool:
    """Whether the calibration measurements came from a file (no selection was measured)."""
    return out.selection is None


def n_not_visible(out: CalibrationOutcome) -> int | None:
    """Commanded configurations the tracker could not see (None for a measurement file: unknown)."""
    if from_file(out):
        return None
    return int(out.measurements.n_requested - len(out.measurements))


def summary_of(out: CalibrationOutcome, cfg: Config) -> dict:
    v = out.validation
    sel = out.selection
    user = from_file(out)
    design = out.measured_design or {}
    pred = v if v is not None else out.prediction
    predicted = pred["predicted_rms_m"] if pred is not None else None
    sigma = pred["noise_total_sigma_m"] if pred is not None else None
    fit = out.fit or {}
    return noise_components(out.notes.noise_model, sigma) | {
        "n_configurations": int(len(out.measurements)),
        "n_configurations_commanded": None if user else int(out.measurements.n_requested),
        "n_configurations_not_visible": n_not_visible(out),
        "measurement_source": out.measurements.source,
        "selection_method": "user file" if user else cfg.selection_method,
        "index_name": cfg.index_name,
        "index_value": (design.get("index_value") if user
                        else float(out.gradient.index_value) if out.gradient is not None
                        else float(sel.index_value)),
        "index_value_measured": design.get("index_value"),
        "selection_time_s": float(sel.run_time_s) if sel is not None else None,
        "selection_evaluations": int(sel.evaluations) if sel is not None else None,
        "n_candidates": int(len(out.candidates)) if out.candidates is not None else None,
        "n_parameters": len(out.names),
        "n_identifiable": int(out.estimate.theta.size),
        "validation_source": v["source"] if v is not None else None,
        "heldout_n_poses": v["n_poses"] if v is not None else None,
        "heldout_n_rejected": v["n_rejected"] if v is not None else None,
        "heldout_rms_position_error_before_m": v["before"]["rms"] if v is not None else None,
        "heldout_rms_position_error_after_m": v["after"]["rms"] if v is not None else None,
        "heldout_mean_position_error_after_m": v["after"]["mean"] if v is not None else None,
        "heldout_max_position_error_after_m": v["after"]["max"] if v is not None else None,
        "heldout_max_position_error_before_m": v["before"]["max"] if v is not None else None,
        **heldout_every_reading(v),
        "predicted_rms_position_error_m": predicted,
        "actual_over_predicted": v["after"]["rms"] / v["predicted_rms_m"] if v is not None else None,
        "actual_over_predicted_test": (cg.ratio_test(v, cfg.max_actual_over_predicted,
                                                     cfg.actual_over_predicted_confidence) if v is not None else None),
        "predicted_gravity_model_rms_m": pred.get("predicted_gravity_model_rms_m") if pred is not None else None,
        "gravity_model_share": pred.get("gravity_model_share") if pred is not None else None,
        "gravity_model_prior": gravity_prior_of(out, cfg),
        "rms_after_over_sigma": v["after"]["rms"] / v["noise_total_sigma_m"] if v is not None else None,
        "fit_rms_residual_before_m": fit.get("rms_residual_before_m"),
        "fit_rms_residual_after_m": fit.get("rms_residual_after_m"),
        "chi2_per_dof": out.estimate.chi2_per_dof,
        "parameters": cfg.parameters,
        "n_outliers_rejected": out.rejection.n_rejected if out.rejection is not None else 0,
        "outliers_rejected": rejected_readings(out),
        "n_payload_readings": (int(np.sum(out.measurements.payload_mounted))
                               if out.measurements.payload_mounted is not None else 0),
        "gravity_pass": out.notes.gravity_pass,
        "cross_validation": out.notes.cross_validation,
        "noise_model": out.notes.noise_model.as_dict() if out.notes.noise_model is not None else None,
        "n_outliers_expected_clean": expected_rejections(out.rejection) if out.rejection is not None else None,
        "joint_stiffness_Nm_rad": (None if out.robot.spec.actuation.joint_stiffness_Nm_rad is None
                                   else [float(v) for v in out.robot.spec.actuation.joint_stiffness_Nm_rad]),
        "design_dropped_parameters": [d.name for d in out.notes.design_dropped],
        "lm_iterations": out.estimate.iterations,
        "timings_s": {k: round(t, 3) for k, t in out.timings_s.items()},
    }


def heldout_every_reading(v: dict | None) -> dict[str, float | None]:
    """Summary keys of the held-out file over every reading (also those the outlier test left out,
    the figures to compare with a published one) and, for 6-D readings, the orientation errors
    (rad): screened (``heldout_*_orientation_error_*_rad``, the poses of the position figures) and
    over every reading (``*_all_poses_*``). None where the file gives none (no validation file, no
    orientation read)."""
    every = None if v is None else v.get("after_all_poses", v["after"])
    out: dict[str, float | None] = {
        "heldout_rms_position_error_all_poses_after_m": every["rms"] if every is not None else None,
        "heldout_max_position_error_all_poses_after_m": every["max"] if every is not None else None}
    rot = {k: (v[k].get("orientation_rad") if v is not None else None) for k in ("before", "after")}
    rot_every = every.get("orientation_rad") if every is not None else None
    out |= {
        "heldout_rms_orientation_error_before_rad": rot["before"]["rms"] if rot["before"] else None,
        "heldout_rms_orientation_error_after_rad": rot["after"]["rms"] if rot["after"] else None,
        "heldout_max_orientation_error_after_rad": rot["after"]["max"] if rot["after"] else None,
        "heldout_predicted_rms_orientation_error_rad": rot["after"].get("predicted_rms") if rot["after"] else None,
        "heldout_orientation_noise_sigma_rad": rot["after"].get("reading_sigma") if rot["after"] else None,
        "heldout_rms_orientation_error_all_poses_after_rad": rot_every["rms"] if rot_every else None,
        "heldout_max_orientation_error_all_poses_after_rad": rot_every["max"] if rot_every else None}
    return out


def noise_components(noise, total_sigma_m: float | None) -> dict[str, float | None]:
    """Summary keys of a position reading's 1-sigma per axis at the held-out (or predicted) poses:
    ``noise_total_sigma_m`` (RMS over the poses) = sqrt(sensor^2 + repeatability^2 + remainder^2)
    and its parts (:mod:`pipeline.calibration.noise_model`); the sensor's part is what the total
    leaves, so the parts add up exactly. ``tracker_noise_sigma_m`` is the sensor's own noise (runs
    saved before the parts had their keys held the total under that name)."""
    rep = float(noise.repeatability_sigma_m) if noise is not None else 0.0
    rem = float(noise.remainder_sigma_m[0]) if noise is not None else 0.0
    sensor = None if total_sigma_m is None else math.sqrt(max(total_sigma_m ** 2 - rep ** 2 - rem ** 2, 0.0))
    return {"noise_total_sigma_m": total_sigma_m, "noise_sensor_sigma_m": sensor,
            "noise_repeatability_sigma_m": rep, "noise_remainder_sigma_m": rem, "tracker_noise_sigma_m": sensor}


#: gravity-model share of the predicted mean-square error above which the report suggests the
#: second calibration pass with an identified gravity model
GRAVITY_SHARE_SUGGEST = 0.5


def gravity_prior_of(out: CalibrationOutcome, cfg: Config) -> dict | None:
    """The gravity-model prior used in the measurement covariance (None: rigid model)."""
    if not any(n.endswith(".c") for n in out.report.identifiable_names):
        return None
    prior = cfg.gravity_prior()
    return {"mass_relative_sigma": prior.mass_relative_sigma, "com_sigma_m": prior.com_sigma_m,
            "gravity_model": cfg.gravity_model or "nominal"}


def gravity_markdown(out: CalibrationOutcome, cfg: Config) -> list[str]:
    """The gravity-model share of the predicted error, and the second pass when it dominates."""
    prior = gravity_prior_of(out, cfg)
    pred = out.validation if out.validation is not None else out.prediction
    if prior is None or pred is None or pred.get("gravity_model_share") is None:
        return []
    share = pred["gravity_model_share"]
    md = [f"Gravity-model uncertainty in the measurement covariance ({prior['gravity_model']} inertias, prior "
          f"1σ {100 * prior['mass_relative_sigma']:.1f} % of each link mass and {1e3 * prior['com_sigma_m']:.1f} mm "
          f"of each centre of mass): {100 * share:.0f} % of the predicted mean-square held-out error "
          f"(RMS {1e3 * pred['predicted_gravity_model_rms_m']:.4f} mm)."]
    if share > GRAVITY_SHARE_SUGGEST and cfg.gravity_model is None:
        md[0] += (" It dominates: run a second calibration pass with "
                  "`calibration.gravity_model: <runs>/<name>/identification/robot` once the identification "
                  "stage has run (identified inertias give the gravity torques of the elastostatic model).")
    return md + [""]


def rejected_readings(out: CalibrationOutcome) -> list[dict]:
    """Readings the outlier test rejected: pose index (0-based row of the record), CSV line (user
    file), whitened residual ``|r / sigma|`` under the final fit."""
    rej = out.rejection
    if rej is None:
        return []
    rec = out.notes.fit_record if out.notes.fit_record is not None else out.measurements   # 6-D: 3 rows a pose
    lines = rec.lines
    pose = rec.pose_index if rec.pose_index is not None else np.arange(len(rec))
    return [{"pose_index": int(pose[i]), "csv_line": None if lines is None else int(lines[i]),
             "whitened_residual": float(rej.whitened_norm[i])} for i in rej.rejected]


def outlier_markdown(out: CalibrationOutcome) -> str:
    """The outlier test and the rejected readings (report.md)."""
    rej = out.rejection
    if rej is None:
        return ""
    head = (f"Outlier test (robust loss `{rej.loss}`, then chi-square with 3 dof on the whitened residual "
            f"at {100 * rej.confidence:.2f} % confidence per reading: reject |r/σ| > {rej.threshold:.2f}): "
            f"**{rej.n_rejected} reading(s) rejected** of {len(rej.whitened_norm)}; a clean record of this size "
            f"would lose {expected_rejections(rej):.2g} on average (the test's false-alarm share).")
    if rej.capped:
        head += (" More readings failed the test than calibration.max_outlier_fraction allows: the model does "
                 "not explain the data (see chi²/dof).")
    rows = rejected_readings(out)
    if not rows:
        return head
    table = ["", "| pose index | CSV line | |r/σ| |", "|---|---|---|"]
    table += [f"| {r['pose_index']} | {r['csv_line'] if r['csv_line'] is not None else '—'} | "
              f"{r['whitened_residual']:.1f} |" for r in rows]
    return head + "\n" + "\n".join(table)


def expected_rejections(rej) -> float:
    """Readings a clean record loses to the outlier test on average: ``N (1 - confidence)``."""
    return float(len(rej.whitened_norm) * (1.0 - rej.confidence))


def noise_markdown(out: CalibrationOutcome) -> list[str]:
    """The readings' noise model: sensor, arm repeatability, REML remainder (report.md)."""
    noise = out.notes.noise_model
    if noise is None:
        return []
    s = np.asarray(out.measurements.sigma_m, float)
    line = (f"Noise model of a reading (1σ per axis, pipeline.calibration.noise_model): sensor "
            f"{1e3 * float(np.sqrt(np.mean(s ** 2))):.4f} mm (RMS over the readings), arm repeatability "
            f"{1e3 * noise.repeatability_sigma_m:.4f} mm ({repeatability_source_text(noise)}), unmodelled "
            f"remainder {1e3 * noise.remainder_sigma_m[0]:.4f} mm (REML on the fit residuals)")
    if noise.remainder_sigma_m[1]:
        line += f", remainder of the marker-point rows {1e3 * noise.remainder_sigma_m[1]:.4f} mm"
    if noise.orientation_scale != 1.0:
        line += (f"; the marker-point rows' sigma times {noise.orientation_scale:g} in the fit (orientation weight "
                 "chosen by cross-validation)")
    return [line + ".", ""]


def repeatability_source_text(noise) -> str:
    """Which repeatability the noise model used (:func:`pipeline.robot.repeatability.repeatability_for_calibration`)."""
    source = getattr(noise, "repeatability_source", "stated")
    if source == "data":
        rp = noise.repeatability_not_used_m
        return ("from the data: robot.yaml's " + (f"±{1e3 * rp:g} mm " if rp is not None else "")
                + "is robot init's reach-class assumption, not used; the remainder estimated from the record "
                "takes up the arm's scatter")
    if source == "assumed":
        return "robot init's reach-class assumption / 3.616 (simulated readings scatter by it)"
    if source == "none":
        return "not stated in robot.yaml: the remainder takes it up"
    return "robot.yaml repeatability_m / 3.616, as stated"


def visibility_sentence(out: CalibrationOutcome, robot: RobotModel) -> str:
    """How many commanded poses the tracker could not see (report.md)."""
    m = out.measurements
    if from_file(out) and m.windows_found is not None:
        return (f"Calibration measurements: {len(m)} configurations from the bag `{m.source}`: "
                f"{m.windows_found} stationary windows found, {len(m)} used (the readings of each averaged).")
    if from_file(out):
        return (f"Calibration measurements: {len(m)} configurations from the user file `{m.source}` "
                "(poses the tracker could not see are not in the file).")
    k = n_not_visible(out)
    deg = math.degrees(robot.tracker.max_incidence_rad)
    if k == 0:
        return f"All {m.n_requested} selected poses were visible to the tracker."
    return (f"{k} of {m.n_requested} selected poses were not visible to the tracker (beam blocked or "
            f"incidence > {deg:.0f}°) and were dropped; the fit uses the {len(m)} measured ones.")


def report_markdown(out: CalibrationOutcome, cfg: Config, robot: RobotModel) -> str:
    md = ["### Identifiability", "", out.report.markdown(), ""]
    dropped = out.notes.design_dropped
    if dropped:
        md += [f"Dropped before the design ({len(dropped)}; held at their nominal values, the design optimises "
               "the rest):", "", *(f"- {d.name}: {d.why}" for d in dropped), ""]
    md += ["### Measurements", "", visibility_sentence(out, robot), ""]
    d = out.measured_design
    if d is not None and from_file(out):
        md += [f"Configurations chosen by the user (no selection was run): {d['index_name']} = "
               f"{d['index_value']:.6g} for the {d['n_configurations']} measured configurations.", ""]
    md += ["### Fit", "", va.fit_markdown(out.fit, out.prediction), "", *noise_markdown(out), outlier_markdown(out),
           ""]
    cv = out.notes.cross_validation
    if cv is not None and cv["rms_position_error_m"] is not None:
        md += [f"{cv['folds']}-fold cross-validation on the measurement file: RMS position error of the left-out "
               f"poses {1e3 * cv['rms_position_error_m']:.4f} mm over {cv['n_poses']} poses "
               f"({cv['n_folds_not_regular']} fold(s) too small to fit); the outlier test runs inside the "
               f"training folds only, {cv['n_rejected']} left-out reading(s) failed it under their fold's model"
               + (f"; predicted RMS {1e3 * cv['predicted_rms_position_error_m']:.4f} mm, actual/predicted "
                  f"{cv['actual_over_predicted']:.3f}" if cv.get("actual_over_predicted") is not None else "")
               + ".", ""]
    g = out.notes.gravity_pass
    if g is not None:
        md += [f"Second calibration pass: gravity torques of the elastostatic model from `{g['gravity_model']}` "
               f"(identified inertias) instead of this run's model; chi²/dof {g['chi2_per_dof_nominal_gravity']:.3f} "
               f"-> {g['chi2_per_dof_upstream_gravity']:.3f}.", "",
               "| compliance | nominal gravity [rad/(N·m)] | identified gravity | change |", "|---|---|---|---|"]
        md += [f"| {r['parameter']} | {r['compliance_nominal_gravity']:.4g} | {r['compliance_upstream_gravity']:.4g} | "
               + (f"{100 * r['relative_change']:+.1f} % |" if r["relative_change"] is not None else "— |")
               for r in g["compliances"]]
        md.append("")
    k = out.robot.spec.actuation.joint_stiffness_Nm_rad
    md += gravity_markdown(out, cfg)
    if any(n.endswith(".c") for n in out.report.identifiable_names) and k is not None:
        md += ["Joint stiffness carried by the calibrated model (1 / identified compliance; nominal where "
               f"not identified or not determined to {100 * MAX_COMPLIANCE_RELATIVE_STD:.0f} % (1 sigma)) "
               "[N·m/rad]: " + ", ".join(f"{v:.4g}" for v in k), ""]
    if out.validation is None:
        md += ["### Held-out validation", "",
               "**no held-out validation: give calibration.validation_csv** (poses measured on the real "
               "robot, not used in the fit). The figures above are in-sample fit residuals and a "
               "covariance prediction, not a measured accuracy."]
    else:
        md += [f"### Held-out validation (paper 004 Table 2 layout; {out.validation['source']})", "",
               va.table_markdown(out.validation)]
    return "\n".join(md)


#: at most about this many candidates are saved for the viewer (every k-th)
VIEWER_CANDIDATES = 2000


def stage_arrays(out: CalibrationOutcome) -> dict[str, np.ndarray]:
    """``results.npz``: the measured record, the fit, the identified parameters, the held-out
    errors and the viewer's layers (candidates thinned to about :data:`VIEWER_CANDIDATES`)."""
    est = out.estimate
    arrays = {
        "configurations_selected": out.measurements.Q,
        "tracker_readings_m": out.measurements.Y,
        "tracker_sigma_m": out.measurements.sigma_m,
        "fit_residuals_m": out.fit["residuals_after_m"],
        "parameters_identified": est.theta,
        "parameters_std": est.std,
        "parameter_covariance": est.covariance,
        "transform_tracker_to_base": est.transform_tracker_to_base.homogeneous,
    }
    if out.rejection is not None and out.rejection.n_rejected:
        arrays["outliers_rejected_rows"] = np.asarray(out.rejection.rejected, int)
    if out.measurements.invisible is not None and len(out.measurements.invisible):
        arrays["configurations_not_visible"] = out.measurements.invisible
    if out.validation is not None:
        arrays["heldout_errors_before_m"] = out.validation["errors_before_m"]
        arrays["heldout_errors_after_m"] = out.validation["errors_after_m"]
        arrays["heldout_predicted_std_m"] = out.validation["predicted_std_m"]
    if out.notes.static_torques is not None:              # elastostatic model: for later gravity models
        arrays.update(out.notes.static_torques.to_arrays())
    if out.notes.heldout_configurations is not None:      # for the viewer's layers
        arrays["configurations_heldout"] = out.notes.heldout_configurations
    if out.candidates is not None and len(out.candidates):
        arrays["configurations_candidates"] = out.candidates.Q[:: max(1, len(out.candidates) // VIEWER_CANDIDATES)]
    if out.selection is not None:
        arrays["index_history"] = np.array(out.selection.history, float).reshape(-1, 2)
    return arrays


def _scalars(d: dict | None) -> dict | None:
    return None if d is None else {k: v for k, v in d.items() if not isinstance(v, np.ndarray)}


def identified_parameters(data: dict) -> list[tuple[str, float, float]]:
    """``(name, value, std)`` of every identified parameter of a saved ``data.json`` (:func:`stage_data`),
    in the order of the fit; empty when it holds none."""
    identified = data.get("identified")
    if not isinstance(identified, dict):
        return []
    return [(str(name), float(pair[0]), float(pair[1])) for name, pair in identified.items()]


def stage_data(out: CalibrationOutcome) -> dict:
    """``data.json``: the identifiability report, the identified values with their std, the
    scalar parts of validation, fit and prediction, the design's records."""
    est = out.estimate
    return {
        "identifiability": out.report.as_dict(),
        "identified": {n: [float(v), float(s)] for n, v, s in
                       zip(out.report.identifiable_names, est.theta, est.std, strict=True)},
        "validation": _scalars(out.validation),
        "fit": _scalars(out.fit),
        "prediction": _scalars(out.prediction),
        "selection": out.selection.as_dict() if out.selection is not None else None,
        "measured_design": out.measured_design,
        "candidate_counts": out.candidates.counts if out.candidates is not None else None,
        "gradient_design": out.gradient.as_dict() if out.gradient is not None else None,
        "design_table": out.design_table,
    }
