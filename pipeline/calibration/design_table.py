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

What the measured column can show, and what no design can change: the *verified* prediction
``sqrt(trace(W_h M^-1))`` of each design (``W_h = sum_k J_k^T J_k / n_h``, ``J_k`` the reflector's
reading Jacobian at the held-out poses, ``M`` the information of the configurations the tracker
actually measured, all whitened by the same tracker noise model, so the rows compare) is the
expected model part of the actual figure; against it stands the certified lower bound of
:mod:`pipeline.calibration.design_bound` on the same ``W_h`` over the whole candidate pool,
``sqrt(V*/n)`` (the pool whitened at the registered tracker pose, like the rows): no design of ``n``
pool configurations has a smaller expected model RMS on the held-out poses. One calibration's
actual figure is one draw around its design's prediction (and the unmodelled remainder of the hidden
arm and the held-out noise left after subtracting its model add to every row alike), so a seed on
which a baseline measures better than the chosen design is read against the two: how far the chosen
design's prediction is from the bound, and how far the baseline's; ``repeats`` further calibrations
of every design (fresh tracker noise) measure the expected figure itself.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import design_bound as db
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


#: equivalence-theorem gap at which the table's bound stops (the bound is certified at any gap; a
#: looser stop only makes it a little lower: 7.26 against 7.31 µm at 3e-2 and 1e-2 on the RX130L pool)
BOUND_TOL = 3e-2
BOUND_MAX_ITERATIONS = 400


def verified_weight(mm: MeasurementModel, held: ms.Measurements, geometric_basis: np.ndarray, T_tb) -> np.ndarray:
    """``W_h = sum_k J_k^T J_k / n_h`` of the reflector readings at the held-out poses (tracker pose
    ``T_tb``), in the design's basis: the weighting of the verified prediction (module docstring)."""
    J = ts.reflector_jacobian(mm, held.Q, geometric_basis, T_tb)
    return J.T @ J / len(held)


def verified_bound(G_pool: np.ndarray, W_h: np.ndarray, n: int) -> dict | None:
    """The certified lower bound ``sqrt(V*/n)`` on the verified prediction of every design of ``n``
    configurations of the pool whose whitened blocks are ``G_pool`` (N, m, p)
    (:func:`pipeline.calibration.design_bound.optimal_approximate_design`; None when the pool cannot
    make ``M`` regular)."""
    try:
        ad = db.optimal_approximate_design(G_pool, W_h, tol=BOUND_TOL, max_iterations=BOUND_MAX_ITERATIONS)
    except (ValueError, RuntimeError, np.linalg.LinAlgError):
        return None
    return {"bound_verified_rms_m": math.sqrt(max(ad.exact_bound(n), 0.0)), "n_configurations": int(n),
            "n_candidates": int(len(G_pool)), "equivalence_gap": float(ad.gap)}


def repeated_model_rms(real, mm: MeasurementModel, basis: np.ndarray, Q: np.ndarray, held: ms.Measurements,
                       repeats: int, rng: np.random.Generator, max_lm_iterations: int = 50) -> float:
    """The design ``Q`` measured ``repeats`` times (fresh tracker noise each time) and fitted by weighted
    least squares; the actual model RMS over the repeats, ``sqrt(max(mean_r RMS_r^2 - mean 3 sigma_k^2, 0))``
    on the held-out readings ``held``: the design's expected model RMS, of which one calibration is a draw."""
    ms2 = []
    for _ in range(repeats):
        meas = ms.measure_simulated(real, Q, rng)
        est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis, source="repeat", max_iterations=max_lm_iterations)
        ms2.append(va.validate(mm, est, held)["after"]["rms"] ** 2)
    noise2 = 3.0 * float(np.mean(np.asarray(held.sigma_m) ** 2))
    return math.sqrt(max(float(np.mean(ms2)) - noise2, 0.0))


def design_table(robot: RobotModel, real, mm: MeasurementModel, basis: np.ndarray, spec_v: ix.IndexSpec,
                 chosen_label: str, chosen_Q: np.ndarray, chosen_est: Estimate, cs: cd.CandidateSet | None,
                 region: ts.WorkingRegion, rng: np.random.Generator, n_heldout: int = 300,
                 max_lm_iterations: int = 50, geometric_basis: np.ndarray | None = None,
                 bound: bool = True, repeats: int = 0) -> dict:
    """Rows ``{design, n_configurations, n_measured, predicted_tcp_rms_m, actual_model_rms_m,
    predicted_model_rms_m, predicted_verified_rms_m}`` for the chosen design and the baselines (``real``
    None or ``cs`` None: predicted figures of the chosen design only), and with ``bound`` the certified
    bound of the verified prediction over the pool (``table["bound"]``, module docstring). ``repeats``
    > 0: every design measured and fitted that many more times (:func:`repeated_model_rms`), the RMS over
    the repeats in ``repeated_model_rms_m``. ``basis`` is
    the fit's (it may hold joint compliances); the candidate Jacobians and the V criterion use the
    design's basis ``geometric_basis`` (default ``basis``;
    :func:`pipeline.calibration.elastostatic.design_basis`: compliances included, rescaled)."""
    geometric_basis = basis if geometric_basis is None else geometric_basis
    n = len(chosen_Q)
    T_tb = chosen_est.transform_tracker_to_base
    chain = cd.chain_from_robot(robot, T_tb)
    designs: dict[str, np.ndarray] = {chosen_label: np.asarray(chosen_Q, float)}
    if cs is not None and real is not None and len(cs) >= n:
        for label, sel in baseline_designs(cs, n, rng).items():
            designs[label] = cs.Q[sel]
    held = heldout_in_region(robot, real, region, chosen_est, n_heldout, rng) if real is not None else None
    W_h = verified_weight(mm, held, geometric_basis, T_tb) if held is not None else None
    torques = mm.static_torques if mm.compliance else None
    rows = []
    for label, Q in designs.items():
        G = cd.build_candidate_set(chain, Q, geometric_basis, T_tb, static_torques=torques).G
        row = {"design": label, "n_configurations": int(len(Q)), "n_measured": None,
               "predicted_tcp_rms_m": ts.predicted_tcp_rms_m(spec_v, information(G)),
               "actual_model_rms_m": None, "predicted_model_rms_m": None, "heldout_rms_m": None,
               "predicted_verified_rms_m": None}
        if held is not None and W_h is not None:
            if label == chosen_label:
                est, Q_measured = chosen_est, Q
            else:
                meas = ms.measure_simulated(real, Q, rng)
                est, Q_measured = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis, source=label,
                                           max_iterations=max_lm_iterations), meas.Q
            v = va.validate(mm, est, held)
            row["actual_model_rms_m"], row["predicted_model_rms_m"] = model_rms(v)
            row["heldout_rms_m"] = v["after"]["rms"]
            row["n_measured"] = int(len(Q_measured))
            G_measured = cd.build_candidate_set(chain, Q_measured, geometric_basis, T_tb, static_torques=torques).G
            V = db.criterion(W_h, information(G_measured))
            row["predicted_verified_rms_m"] = math.sqrt(V) if math.isfinite(V) else math.inf
        rows.append(row)
    if held is not None and repeats > 0:          # after the single draws: their stream is unchanged
        for row in rows:
            row["repeated_model_rms_m"] = repeated_model_rms(real, mm, basis, designs[str(row["design"])], held,
                                                             repeats, rng, max_lm_iterations)
    bound_row = None
    if bound and cs is not None and W_h is not None and len(rows) > 1:   # the pool whitened like the rows
        G_pool = cd.build_candidate_set(chain, cs.Q, geometric_basis, T_tb, static_torques=torques).G
        bound_row = verified_bound(G_pool, W_h, n)
    return {"region": region.describe(), "n_working_configurations": int(spec_v.n_working),
            "n_heldout_region": None if held is None else int(len(held)),
            "heldout_noise_rms_m": None if held is None else
            float(math.sqrt(3.0 * np.mean(np.asarray(held.sigma_m) ** 2))),
            "rows": rows, "bound": bound_row}


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
              "predicted model RMS [µm] | measured held-out RMS [µm] | verified prediction [µm] |",
              "|---|---|---|---|---|---|---|"]
    for r in table["rows"]:
        lines.append(f"| {r['design']} | {r['n_configurations']} | {um(r['predicted_tcp_rms_m'])} | "
                     f"{um(r['actual_model_rms_m'])} | {um(r['predicted_model_rms_m'])} | {um(r['heldout_rms_m'])} | "
                     f"{um(r.get('predicted_verified_rms_m'))} |")
    repeated = [r for r in table["rows"] if r.get("repeated_model_rms_m") is not None]
    if repeated:
        lines += ["", "Actual model RMS over repeated calibrations of each design (fresh tracker noise, weighted "
                  "least squares; the design's expected figure, of which the column above is one draw): "
                  + "; ".join(f"{r['design']} {um(r['repeated_model_rms_m'])} µm" for r in repeated) + "."]
    b = table.get("bound")
    if b is not None:
        lines += ["", f"Verified prediction = sqrt(trace(W_h M⁻¹)) at the held-out poses from the configurations "
                  f"each design had measured, the same tracker noise model for every row. Certified bound "
                  f"(optimal approximate design, equivalence-theorem gap {b['equivalence_gap']:.3f}): no design of "
                  f"{b['n_configurations']} of the {b['n_candidates']} candidates predicts less than "
                  f"**{um(b['bound_verified_rms_m'])} µm** there; one seed's actual figure is one draw around "
                  "its design's prediction."]
    return "\n".join(lines)


def summary(table: dict | None) -> dict | None:
    """Headline figures for summary.json: per design the predicted TCP RMS and the actual model RMS."""
    if table is None:
        return None
    out: dict = {r["design"]: {"predicted_tcp_rms_m": r["predicted_tcp_rms_m"],
                               "actual_model_rms_m": r["actual_model_rms_m"],
                               "predicted_verified_rms_m": r.get("predicted_verified_rms_m"),
                               "repeated_model_rms_m": r.get("repeated_model_rms_m")} for r in table["rows"]}
    if table.get("bound") is not None:
        out["bound"] = dict(table["bound"])
    return out


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
                        region, rng, cfg.design_table_heldout, cfg.max_lm_iterations, geometric_basis,
                        cfg.design_table_bound, cfg.design_table_repeats)


def markdown_section(table: dict | None) -> str:
    """The report.md section ('' without a table)."""
    if table is None:
        return ""
    return "\n\n### Design table (the chosen design against baselines of the same size)\n\n" + markdown(table)
