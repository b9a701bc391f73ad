"""Design table: the chosen calibration design against baselines of the same size, in micrometres.

Every design is scored on what it is for, the accuracy of the calibrated TCP where the arm works
(:mod:`pipeline.calibration.task_space`):

- *predicted TCP RMS* over the working configurations, ``sqrt(trace(W M^-1))`` (paper 000 eq. 16
  error propagation averaged over the working region, the ``V`` criterion), from the nominal
  whitened Jacobians of the design's configurations;
- in simulation, the design is measured on the hidden robot, calibrated, and scored on the same
  held-out poses in the working region that the tracker can see: the *actual* model RMS
  ``sqrt(max(mean |e_k|² - mean 3 sigma_k², 0))`` (the tracker noise of the held-out readings
  removed, so the figure is the calibrated model's error, not the tracker's) next to its
  *predicted* value ``sqrt(mean trace(J_k C J_k^T))`` at the same poses (paper 000 eq. 16).

Baselines (same number of configurations): every (N/n)-th feasible grid configuration in grid
order (paper 004's "linear scan"), a random regular subset, and remove-and-replace on O3 (paper
004 §3.3.1). With user data only the predicted figure of the user's configurations is given.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import task_space as ts
from pipeline.calibration import validate as va
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import Estimate, estimate
from pipeline.core.errors import PipelineError
from pipeline.robot.model import RobotModel


def information(G: np.ndarray) -> np.ndarray:
    """``M = sum_k G_k^T G_k`` of whitened blocks (n, m, p)."""
    return np.einsum("kmi,kmj->ij", G, G)


def baseline_designs(cs: cd.CandidateSet, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Candidate indices of the baselines of ``n`` configurations (module docstring)."""
    o3 = ix.IndexSpec("O3")
    return {"every (N/n)-th feasible candidate": ds.linear_scan_design(cs.G, o3, n).selected,
            "random": ds.random_design(cs.G, o3, n, rng).selected,
            "O3 remove-and-replace": ds.remove_and_replace(cs.G, o3, n, rng).selected}


def model_rms(validation: dict) -> tuple[float, float]:
    """(actual, predicted) model RMS of a validation: measured RMS with the tracker noise removed,
    and the covariance-predicted model part."""
    noise2 = 3.0 * validation["noise_total_sigma_m"] ** 2
    actual = math.sqrt(max(validation["after"]["rms"] ** 2 - noise2, 0.0))
    return actual, float(validation["predicted_model_rms_m"])


def heldout_in_region(robot: RobotModel, real, region: ts.WorkingRegion, est: Estimate, n: int,
                      rng: np.random.Generator) -> ms.Measurements | None:
    """Up to ``n`` visible poses of the working region measured on the hidden robot (None: none)."""
    chain = cd.chain_from_robot(robot, est.transform_tracker_to_base)
    margins = cd.FilterMargins(0.01, math.radians(1.0), 0.005)
    try:
        Q = ts.sample_region(robot, region, n, rng, chain=chain, visibility=True, margins=margins)
    except PipelineError:
        return None
    m = ms.measure_simulated(real, Q, rng)
    return m if len(m) >= 3 else None


def design_table(robot: RobotModel, real, mm: MeasurementModel, basis: np.ndarray, spec_v: ix.IndexSpec,
                 chosen_label: str, chosen_Q: np.ndarray, chosen_est: Estimate, cs: cd.CandidateSet | None,
                 region: ts.WorkingRegion, rng: np.random.Generator, n_heldout: int = 300,
                 max_lm_iterations: int = 50, geometric_basis: np.ndarray | None = None) -> dict:
    """Rows ``{design, n_configurations, predicted_tcp_rms_m, actual_model_rms_m, predicted_model_rms_m}``
    for the chosen design and the baselines (``real`` None or ``cs`` None: predicted figures of the
    chosen design only). ``basis`` is the fit's (it may hold joint compliances); the candidate
    Jacobians and the V criterion use the design's basis ``geometric_basis`` (default ``basis``;
    :func:`pipeline.calibration.elastostatic.design_basis`: compliances included, rescaled)."""
    geometric_basis = basis if geometric_basis is None else geometric_basis
    n = len(chosen_Q)
    chain = cd.chain_from_robot(robot, chosen_est.transform_tracker_to_base)
    designs: dict[str, np.ndarray] = {chosen_label: np.asarray(chosen_Q, float)}
    if cs is not None and real is not None and len(cs) >= n:
        for label, sel in baseline_designs(cs, n, rng).items():
            designs[label] = cs.Q[sel]
    held = heldout_in_region(robot, real, region, chosen_est, n_heldout, rng) if real is not None else None
    rows = []
    for label, Q in designs.items():
        G = cd.build_candidate_set(chain, Q, geometric_basis, chosen_est.transform_tracker_to_base,
                                   static_torques=mm.static_torques if mm.compliance else None).G
        row = {"design": label, "n_configurations": int(len(Q)),
               "predicted_tcp_rms_m": ts.predicted_tcp_rms_m(spec_v, information(G)),
               "actual_model_rms_m": None, "predicted_model_rms_m": None, "heldout_rms_m": None}
        if held is not None:
            if label == chosen_label:
                est = chosen_est
            else:
                meas = ms.measure_simulated(real, Q, rng)
                est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis, source=label,
                               max_iterations=max_lm_iterations)
            v = va.validate(mm, est, held)
            row["actual_model_rms_m"], row["predicted_model_rms_m"] = model_rms(v)
            row["heldout_rms_m"] = v["after"]["rms"]
        rows.append(row)
    return {"region": region.describe(), "n_working_configurations": int(spec_v.n_working),
            "n_heldout_region": None if held is None else int(len(held)),
            "heldout_noise_rms_m": None if held is None else
            float(math.sqrt(3.0 * np.mean(np.asarray(held.sigma_m) ** 2))),
            "rows": rows}


def markdown(table: dict) -> str:
    """The design table of report.md (µm)."""
    def um(v: float | None) -> str:
        return "–" if v is None or not math.isfinite(v) else f"{1e6 * v:.1f}"

    lines = [f"Working region: {table['region']} ({table['n_working_configurations']} working configurations). "
             "Predicted TCP RMS = sqrt(trace(W M⁻¹)) with W on the TCP (the V criterion on the TCP)."]
    if table["n_heldout_region"] is None:
        lines.append("No measured comparison (user data, or no pose of the region visible to the tracker): "
                     "predicted figures only.")
    else:
        lines.append(f"Each design measured on the simulated robot, calibrated, and scored on "
                     f"{table['n_heldout_region']} visible held-out poses of the region; actual = measured RMS "
                     f"with the tracker noise ({um(table['heldout_noise_rms_m'])} µm RMS) removed.")
    lines += ["", "| design | configurations | predicted TCP RMS [µm] | actual model RMS [µm] | "
              "predicted model RMS [µm] | measured held-out RMS [µm] |", "|---|---|---|---|---|---|"]
    for r in table["rows"]:
        lines.append(f"| {r['design']} | {r['n_configurations']} | {um(r['predicted_tcp_rms_m'])} | "
                     f"{um(r['actual_model_rms_m'])} | {um(r['predicted_model_rms_m'])} | {um(r['heldout_rms_m'])} |")
    return "\n".join(lines)


def summary(table: dict | None) -> dict | None:
    """Headline figures for summary.json: per design the predicted TCP RMS and the actual model RMS."""
    if table is None:
        return None
    return {r["design"]: {"predicted_tcp_rms_m": r["predicted_tcp_rms_m"],
                          "actual_model_rms_m": r["actual_model_rms_m"]} for r in table["rows"]}


def for_run(cfg, robot: RobotModel, real, mm: MeasurementModel, basis: np.ndarray, spec: ix.IndexSpec,
            measured_Q: np.ndarray, est: Estimate, cs: cd.CandidateSet | None, region: ts.WorkingRegion | None,
            rng: np.random.Generator, geometric_basis: np.ndarray | None = None) -> dict | None:
    """The stage's call: the table of a calibration ``Config`` (None when ``design_table`` is off);
    ``spec`` the run's index (its TCP rows are reused when it is ``V``); ``geometric_basis``: the
    design's basis (see :func:`design_table`)."""
    geometric_basis = basis if geometric_basis is None else geometric_basis
    if not cfg.design_table:
        return None
    region = region or ts.default_region(robot)
    spec_v = ts.tcp_part(spec, cfg.design_figure) if spec.name == "V" else None
    if spec_v is None:
        spec_v = ts.task_space_spec(mm, ts.sample_region(robot, region, cfg.n_region_configurations, rng),
                                    geometric_basis)
    label = "user file" if real is None and cs is None else f"chosen: {cfg.selection_method} on {cfg.index_name}"
    return design_table(robot, real, mm, basis, spec_v, label, measured_Q, est, cs,
                        region, rng, cfg.design_table_heldout, cfg.max_lm_iterations, geometric_basis)


def markdown_section(table: dict | None) -> str:
    """The report.md section ('' without a table)."""
    if table is None:
        return ""
    return "\n\n### Design table (the chosen design against baselines of the same size)\n\n" + markdown(table)
