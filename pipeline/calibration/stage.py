"""Stage ``calibration``: optimal measurement configurations and geometric calibration.

Pipeline (issue 3; papers 004 §3, 000, 002, 003):

1. identifiable parameter set of the tracker measurement model (SVD + ordered QR, report);
2. candidates: the joint grid (13 per axis) or random configurations, filtered by limits,
   capsule collisions, floor and predicted tracker visibility; whitened Jacobians;
3. selection of ``n_configurations`` by remove-and-replace (default, paper 004) / DETMAX / BSAA /
   random with any observability index, optionally refined by the gradient-based design
   (CasADi/IPOPT, paper 000);
4. measurement with the (simulated) tracker, or a CSV file;
5. registration + Levenberg-Marquardt, covariance from the noise model, calibrated RobotModel;
6. validation on >= ``n_heldout`` held-out visible poses measured on the real robot (or a CSV).

With ``measurements_csv`` (the user's own tracker data) steps 2-4 are skipped and the simulated
robot is never touched: the design fields describe the user's configurations (their index, method
"user file"), and the held-out validation uses only ``validation_csv``; without it there is no
held-out validation (null summary keys), only the fit residuals and the covariance prediction.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.blas import single_thread_blas
from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import design_table as dtab
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import task_space as ts
from pipeline.calibration import validate as va
from pipeline.calibration.config import MAX_CANDIDATES, Config
from pipeline.calibration.estimate import Estimate, calibrated_robot, estimate
from pipeline.errors import ConfigError, InfeasibleError, PipelineError
from pipeline.progress import task

NAME = "calibration"
DEPENDS: tuple[str, ...] = ("model",)
CONFIG_READS: tuple[str, ...] = ("control.iso",)

@dataclass
class CalibrationOutcome:
    """Everything the stage computed (also used by studies and the notebook)."""

    report: em.IdentifiabilityReport
    names: list[str]
    candidates: cd.CandidateSet | None
    selection: ds.SelectionResult | None
    measurements: ms.Measurements
    estimate: Estimate
    validation: dict | None         # None: no held-out validation (measurement file, no validation file)
    robot: Any
    timings_s: dict[str, float]
    gradient: Any = None
    working_Q: np.ndarray | None = None
    #: index of the configurations actually measured (``method`` "user file" for a measurement file)
    measured_design: dict | None = None
    #: in-sample fit residuals (:func:`pipeline.calibration.validate.fit_residuals`)
    fit: dict | None = None
    #: covariance-predicted error over random visible poses (only when there is no held-out set)
    prediction: dict | None = None
    design_table: dict | None = None


def identify_parameter_set(robot, mm: em.MeasurementModel, cfg: Config, rng: np.random.Generator
                           ) -> tuple[em.IdentifiabilityReport, np.ndarray]:
    """Identifiability analysis on random configurations (paper 002 SVD, paper 003 correlations).

    Returns the report (in the error model's own parameters) and the basis ``P`` (n_full, p) of
    the identifiable parameters, ``x = P theta``.
    """
    Q = em.random_configurations(robot, cfg.identifiability_samples, rng)
    chain = cd.chain_from_robot(robot)
    _, J = cd.nominal_jacobian(chain, Q, robot.tracker.transform_tracker_to_base)
    J = J.reshape(-1, mm.n)
    if cfg.error_model == "se3":
        B, names = None, mm.names
    else:
        try:
            B, names = em.mdh_basis(robot, mm.names)
        except ValueError as exc:
            raise ConfigError(None, "calibration.error_model", f"mdh_hayati: {exc}") from None
    Jm = J if B is None else J @ B
    rep = em.identifiability(Jm, names, cfg.identifiability_rel_tol)
    return rep, em.parameter_basis(rep, mm.n, B)


def build_candidates(robot, cfg: Config, basis: np.ndarray, rng: np.random.Generator) -> cd.CandidateSet:
    """Filtered candidate set with whitened Jacobians (nominal model, nominal tracker pose)."""
    chain = cd.chain_from_robot(robot)
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(cfg.margin_incidence_deg), cfg.margin_beam_m)
    grid_index = None
    if cfg.candidates == "grid":
        with task(f"calibration: filtering the {cfg.grid_per_axis}^{robot.nq} grid") as bar:
            Q, grid_index, counts = cd.filter_grid(chain, cfg.grid_per_axis, margins, progress=bar)
    else:
        Q, counts = cd.random_candidates(chain, cfg.n_random_candidates, rng, margins)
    if len(Q) == 0:
        counts_text = ", ".join(f"{k} {v}" for k, v in counts.items() if k != "time_s")
        key = "calibration.grid_per_axis" if cfg.candidates == "grid" else "calibration.candidates"
        raise InfeasibleError(None, key,
                              f"no feasible candidate configuration (joint limits, collisions, floor, tracker "
                              f"visibility with the calibration.margin_* values; {counts_text})")
    return cd.build_candidate_set(chain, Q, basis, robot.tracker.transform_tracker_to_base, counts, grid_index)


def too_few_candidates(cfg: Config, robot, n_feasible: int) -> str:
    """Message for a candidate set smaller than ``n_configurations``, in the user's fields."""
    rules = "joint limits, collisions, floor, tracker visibility with the calibration.margin_* values"
    if cfg.candidates == "random":
        return (f"only {n_feasible} feasible random configurations were found ({rules}; n_random_candidates = "
                f"{cfg.n_random_candidates}), fewer than the {cfg.n_configurations} configurations asked for: "
                "lower n_configurations or the margins, or check the robot's limits, capsules and tracker pose")
    return (f"only {n_feasible} of the {cfg.grid_per_axis}^{robot.nq} grid configurations (grid_per_axis = "
            f"{cfg.grid_per_axis}) are feasible ({rules}), fewer than the {cfg.n_configurations} configurations "
            "asked for: raise grid_per_axis or lower n_configurations")


def working_jacobian(robot, mm: em.MeasurementModel, Qw: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """TCP-position Jacobian rows (3 n_w, p) at working configurations wrt ``theta`` (base frame;
    tracker and reflector parameters do not move the TCP)."""
    f = mm.sym.fk_position_jacobian(robot.frame_tcp)
    rows = []
    for q in Qw:
        full = np.zeros((3, mm.n))
        full[:, mm.sl_kin] = np.asarray(f(q, np.zeros(mm.n_kin))[0])
        rows.append(full @ basis)
    return np.vstack(rows)


def index_spec(cfg: Config, robot, mm: em.MeasurementModel, basis: np.ndarray, rng: np.random.Generator,
               region: ts.WorkingRegion | None = None) -> tuple[ix.IndexSpec, np.ndarray | None]:
    """The observability index; for the TCP criteria random collision-free working poses (``V``: in
    the working region, :mod:`pipeline.calibration.task_space`)."""
    if cfg.index_name == "V":
        Qw = ts.sample_region(robot, region or ts.default_region(robot), cfg.n_region_configurations, rng)
        return ts.task_space_spec(mm, Qw, basis), Qw
    if not cfg.index_name.startswith("tcp_A"):
        return ix.IndexSpec(cfg.index_name), None
    chain = cd.chain_from_robot(robot)
    Qw, _ = cd.random_candidates(chain, cfg.n_working_configurations, rng, visibility=False)
    Jw = working_jacobian(robot, mm, Qw, basis)
    return ix.IndexSpec(cfg.index_name, working_jacobian=Jw, n_working=len(Qw)), Qw


def measured_design(robot, mm: em.MeasurementModel, basis: np.ndarray, Q: np.ndarray, spec: ix.IndexSpec,
                    T_tb, method: str) -> dict:
    """Observability index of the configurations ``Q`` actually measured (nominal model, whitened
    by the tracker noise model, tracker pose ``T_tb``); same conventions as the selection."""
    cs = cd.build_candidate_set(cd.chain_from_robot(robot), Q, basis, T_tb)
    G = cs.G.reshape(-1, basis.shape[1])
    value = ix.evaluate(spec, G.T @ G, len(Q), cs.Y if spec.needs_positions else None)
    return {"method": method, "index_name": spec.name, "n_configurations": int(len(Q)), "index_value": float(value)}


def predicted_on_random_poses(robot, mm: em.MeasurementModel, est: Estimate, cfg: Config,
                              rng: np.random.Generator) -> dict:
    """Covariance-predicted error over ``n_heldout`` random collision-free poses visible to the
    identified tracker (nominal model only: nothing is measured)."""
    chain = cd.chain_from_robot(robot, est.transform_tracker_to_base)
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(1.0), 0.005)
    Q, _ = cd.random_candidates(chain, cfg.n_heldout, rng, margins)
    sigma = ms.noise_model_sigma(robot, mm.predict(Q, est.x, est.registration))
    return va.predicted_error(mm, est, Q, sigma)


def calibrate(robot, real, cfg: Config, rng: np.random.Generator, progress=None,
              region: ts.WorkingRegion | None = None) -> CalibrationOutcome:
    """Run the whole calibration (see the module docstring) and return its outcome.

    ``real`` is only used without ``cfg.measurements_csv`` (may be None with a measurement file);
    ``region``: working region of V and the design table (None: :func:`ts.default_region`)."""
    with single_thread_blas():
        return _calibrate(robot, real, cfg, rng, progress, region or ts.default_region(robot))


def _calibrate(robot, real, cfg: Config, rng: np.random.Generator, progress, region) -> CalibrationOutcome:
    timings: dict[str, float] = {}
    t = time.perf_counter()
    mm = em.MeasurementModel(robot)
    report, basis = identify_parameter_set(robot, mm, cfg, rng)
    timings["identifiability_s"] = time.perf_counter() - t
    p = basis.shape[1]
    user = None
    if cfg.measurements_csv:
        user = ms.read_csv(cfg.measurements_csv, robot, min_rows=p,
                           min_rows_field=f"one per identifiable parameter of {robot.name}")
    val_user = ms.read_csv(cfg.validation_csv, robot, min_rows=1) if cfg.validation_csv else None
    selection = None
    cs = None
    grad = None
    Qw = None
    spec = None
    if user is None:
        if real is None:
            raise PipelineError(None, "calibration", "no measurement file and no simulated robot")
        t = time.perf_counter()
        cs = build_candidates(robot, cfg, basis, rng)
        timings["candidates_s"] = time.perf_counter() - t
        if len(cs) < cfg.n_configurations:
            raise InfeasibleError(None, "calibration.grid_per_axis" if cfg.candidates == "grid"
                                  else "calibration.n_configurations", too_few_candidates(cfg, robot, len(cs)))
        spec, Qw = index_spec(cfg, robot, mm, basis, rng, region)
        positions = cs.Y if spec.needs_positions else None
        pilot = None
        n_design = cfg.n_configurations
        if cfg.selection_method == "gradient":
            pilot = ms.measure_simulated(real, cs.Q[rng.choice(len(cs), size=min(cfg.n_pilot, len(cs)),
                                                                replace=False)], rng)
            n_design = cfg.n_configurations - pilot.n_requested
        t = time.perf_counter()
        method = "remove_and_replace" if cfg.selection_method == "gradient" else cfg.selection_method
        kw: dict[str, Any] = {}
        if method == "remove_and_replace":
            kw["n_initial"] = cfg.n_initial
        selection = ds.select(method, cs.G, spec, n_design, rng, positions=positions, **kw)
        timings["selection_s"] = time.perf_counter() - t
        Q_sel = cs.Q[selection.selected]
        if pilot is not None:
            from pipeline.calibration.estimate import register_points
            from pipeline.calibration.gradient_design import GradientDesignConfig, gradient_design

            t = time.perf_counter()
            T_pilot = register_points(pilot.Y, mm.base_positions(pilot.Q, np.zeros(mm.n))[0]) \
                if len(pilot) >= 3 else None
            grad = gradient_design(robot, mm, basis, Q_sel, spec, GradientDesignConfig(
                max_iterations=cfg.gradient_max_iterations), transform_tracker_to_base=T_pilot)
            timings["gradient_s"] = time.perf_counter() - t
            Q_sel = grad.Q
        t = time.perf_counter()
        meas = ms.measure_simulated(real, Q_sel, rng)
        if pilot is not None:
            meas = ms.Measurements(np.vstack([pilot.Q, meas.Q]), np.vstack([pilot.Y, meas.Y]),
                                   np.concatenate([pilot.sigma_m, meas.sigma_m]), meas.source, None,
                                   pilot.n_requested + meas.n_requested, np.vstack([pilot.invisible, meas.invisible]))
        timings["measure_s"] = time.perf_counter() - t
        if 3 * len(meas) < p:
            raise InfeasibleError(None, "calibration.n_configurations",
                                  f"only {len(meas)} of the {meas.n_requested} measured configurations were visible "
                                  f"to the tracker; the {p} identifiable parameters need at least "
                                  f"{min_configurations(p)}: raise n_configurations")
    else:
        meas = user  # the user's configurations: no candidates, no selection, no simulated robot
    t = time.perf_counter()
    est = estimate(mm, meas.Q, meas.Y, meas.sigma_m, basis, source=meas.source,
                   max_iterations=cfg.max_lm_iterations)
    timings["estimate_s"] = time.perf_counter() - t
    t = time.perf_counter()
    if val_user is not None:
        held = val_user
    elif user is not None:
        held = None  # real tracker data: a simulated held-out set would be fiction
    else:
        if real is None:
            raise PipelineError(None, "calibration.validation_csv", "no validation file and no simulated robot")
        held = heldout_measurements(robot, real, est, cfg, rng)
    validation = va.validate(mm, est, held) if held is not None else None
    timings["validate_s"] = time.perf_counter() - t
    if spec is None:
        spec, Qw = index_spec(cfg, robot, mm, basis, rng, region)
    design = measured_design(robot, mm, basis, meas.Q, spec, est.transform_tracker_to_base,
                             "user file" if user is not None else "measured subset")
    fit = va.fit_residuals(mm, est, meas)
    prediction = predicted_on_random_poses(robot, mm, est, cfg, rng) if validation is None else None
    new_robot = calibrated_robot(robot, mm, est.x)
    table = dtab.for_run(cfg, robot, real if user is None else None, mm, basis, spec, meas.Q, est, cs, region, rng)
    return CalibrationOutcome(report, mm.names, cs, selection, meas, est, validation, new_robot, timings, grad, Qw,
                              design, fit, prediction, table)


def heldout_measurements(robot, real, est: Estimate, cfg: Config, rng: np.random.Generator) -> ms.Measurements:
    """>= n_heldout visible random poses (predicted with the identified tracker pose), measured."""
    chain = cd.chain_from_robot(robot, est.transform_tracker_to_base)
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(1.0), 0.005)
    parts: list[ms.Measurements] = []
    have = 0
    for _ in range(10):
        need = cfg.n_heldout - have
        Q, _ = cd.random_candidates(chain, int(need * 1.1) + 10, rng, margins)
        m = ms.measure_simulated(real, Q, rng)
        parts.append(m)
        have += len(m)
        if have >= cfg.n_heldout:
            break
    Q = np.concatenate([p.Q for p in parts])[: cfg.n_heldout]
    Y = np.concatenate([p.Y for p in parts])[: cfg.n_heldout]
    s = np.concatenate([p.sigma_m for p in parts])[: cfg.n_heldout]
    if len(Q) < cfg.n_heldout:
        raise InfeasibleError(None, "calibration.n_heldout", f"only {len(Q)} visible held-out poses found")
    return ms.Measurements(Q, Y, s, "simulated tracker (held-out)", None, sum(p.n_requested for p in parts))


def min_configurations(n_identifiable: int) -> int:
    """Fewest configurations whose 3 tracker coordinates each can determine ``n_identifiable``
    parameters (no redundancy: a few more are needed when the tracker cannot see some)."""
    return -(-n_identifiable // 3)


def check(config: Config, robot) -> None:
    """Robot-dependent checks and the user files, before the runner creates any directory."""
    cfg = config
    mm = em.MeasurementModel(robot)
    need_samples = -(-mm.n // 3)
    if cfg.identifiability_samples < need_samples:
        raise ConfigError(None, "calibration.identifiability_samples",
                          f"{cfg.identifiability_samples} random configurations give {3 * cfg.identifiability_samples} "
                          f"equations for the {mm.n} model parameters of {robot.name}; need at least {need_samples} "
                          "(default 200)")
    max_inc = math.degrees(robot.tracker.max_incidence_rad)
    if cfg.margin_incidence_deg >= max_inc:
        raise ConfigError(None, "calibration.margin_incidence_deg",
                          f"{cfg.margin_incidence_deg} deg leaves no visible pose: the tracker's maximum incidence "
                          f"angle of {robot.name} is {max_inc:g} deg; the margin must be smaller")
    if not cfg.measurements_csv and cfg.candidates == "grid":
        n_grid = cfg.grid_per_axis ** robot.nq
        if n_grid > MAX_CANDIDATES:
            raise ConfigError(None, "calibration.grid_per_axis",
                              f"{cfg.grid_per_axis}^{robot.nq} = {n_grid:.3g} grid configurations, at most "
                              f"{MAX_CANDIDATES:.3g} (time and memory); lower grid_per_axis or use candidates: random")
    _, basis = identify_parameter_set(robot, mm, cfg, np.random.default_rng(0))
    p = basis.shape[1]
    n_min = min_configurations(p)
    if not cfg.measurements_csv:   # the design fields are used only without a measurement file
        why = (f"3 tracker coordinates per configuration for the {p} identifiable parameters of {robot.name}")
        if cfg.n_configurations < n_min:
            raise ConfigError(None, "calibration.n_configurations",
                              f"need at least {n_min} ({why}; more for redundancy and for poses the "
                              f"tracker cannot see), got {cfg.n_configurations}")
        if cfg.selection_method == "gradient" and cfg.n_configurations - cfg.n_pilot < n_min:
            raise ConfigError(None, "calibration.n_pilot",
                              f"n_configurations - n_pilot = {cfg.n_configurations} - {cfg.n_pilot} designed "
                              f"configurations, need at least {n_min} ({why}): lower n_pilot or raise "
                              "n_configurations")
        if (cfg.n_initial is not None and cfg.selection_method in ("remove_and_replace", "gradient")
                and cfg.n_initial < n_min):
            raise ConfigError(None, "calibration.n_initial",
                              f"the start subset must be regular: need at least {n_min} ({why}) or null "
                              f"(2/3 of n_configurations), got {cfg.n_initial}")
    if cfg.measurements_csv:
        ms.read_csv(cfg.measurements_csv, robot, min_rows=p,
                    min_rows_field=f"one per identifiable parameter of {robot.name}")
    if cfg.validation_csv:
        ms.read_csv(cfg.validation_csv, robot, min_rows=1)


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
    if v is not None:
        predicted, sigma = v["predicted_rms_m"], v["tracker_noise_sigma_m"]
    elif out.prediction is not None:
        predicted, sigma = out.prediction["predicted_rms_m"], out.prediction["tracker_noise_sigma_m"]
    else:
        predicted = sigma = None
    fit = out.fit or {}
    return {
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
        "heldout_rms_position_error_before_m": v["before"]["rms"] if v is not None else None,
        "heldout_rms_position_error_after_m": v["after"]["rms"] if v is not None else None,
        "heldout_mean_position_error_after_m": v["after"]["mean"] if v is not None else None,
        "heldout_max_position_error_after_m": v["after"]["max"] if v is not None else None,
        "heldout_max_position_error_before_m": v["before"]["max"] if v is not None else None,
        "predicted_rms_position_error_m": predicted,
        "actual_over_predicted": v["after"]["rms"] / v["predicted_rms_m"] if v is not None else None,
        "tracker_noise_sigma_m": sigma,
        "rms_after_over_sigma": v["after"]["rms"] / v["tracker_noise_sigma_m"] if v is not None else None,
        "fit_rms_residual_before_m": fit.get("rms_residual_before_m"),
        "fit_rms_residual_after_m": fit.get("rms_residual_after_m"),
        "chi2_per_dof": out.estimate.chi2_per_dof,
        "lm_iterations": out.estimate.iterations,
        "timings_s": {k: round(t, 3) for k, t in out.timings_s.items()},
    }


def visibility_sentence(out: CalibrationOutcome, robot) -> str:
    """How many commanded poses the tracker could not see (report.md)."""
    m = out.measurements
    if from_file(out):
        return (f"Calibration measurements: {len(m)} configurations from the user file `{m.source}` "
                "(poses the tracker could not see are not in the file).")
    k = n_not_visible(out)
    deg = math.degrees(robot.tracker.max_incidence_rad)
    if k == 0:
        return f"All {m.n_requested} selected poses were visible to the tracker."
    return (f"{k} of {m.n_requested} selected poses were not visible to the tracker (beam blocked or "
            f"incidence > {deg:.0f}°) and were dropped; the fit uses the {len(m)} measured ones.")


def report_markdown(out: CalibrationOutcome, cfg: Config, robot) -> str:
    md = ["### Identifiability", "", out.report.markdown(), "", "### Measurements", "",
          visibility_sentence(out, robot), ""]
    d = out.measured_design
    if d is not None and from_file(out):
        md += [f"Configurations chosen by the user (no selection was run): {d['index_name']} = "
               f"{d['index_value']:.6g} for the {d['n_configurations']} measured configurations.", ""]
    md += ["### Fit", "", va.fit_markdown(out.fit, out.prediction), ""]
    if out.validation is None:
        md += ["### Held-out validation", "",
               "**no held-out validation: give calibration.validation_csv** (poses measured on the real "
               "robot, not used in the fit). The figures above are in-sample fit residuals and a "
               "covariance prediction, not a measured accuracy."]
    else:
        md += [f"### Held-out validation (paper 004 Table 2 layout; {out.validation['source']})", "",
               va.table_markdown(out.validation)]
    return "\n".join(md)


def run(ctx) -> Any:
    from pipeline.runner import StageResult

    cfg: Config = ctx.config
    t0 = time.perf_counter()
    # real tracker data: the simulated hidden robot must not be touched (not even ctx.real)
    real = None if cfg.measurements_csv else ctx.real
    region = ts.region_of_run(getattr(ctx, "run", None), cfg, ctx.robot)
    out = calibrate(ctx.robot, real, cfg, ctx.rng, getattr(ctx, "progress", None), region)
    summary = summary_of(out, cfg)
    summary["design_table"] = dtab.summary(out.design_table)
    summary["stage_time_s"] = time.perf_counter() - t0
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
    if out.measurements.invisible is not None and len(out.measurements.invisible):
        arrays["configurations_not_visible"] = out.measurements.invisible
    if out.validation is not None:
        arrays["heldout_errors_before_m"] = out.validation["errors_before_m"]
        arrays["heldout_errors_after_m"] = out.validation["errors_after_m"]
        arrays["heldout_predicted_std_m"] = out.validation["predicted_std_m"]
    if out.selection is not None:
        arrays["index_history"] = np.array(out.selection.history, float).reshape(-1, 2)

    def scalars(d: dict | None) -> dict | None:
        return None if d is None else {k: v for k, v in d.items() if not isinstance(v, np.ndarray)}

    data = {
        "identifiability": out.report.as_dict(),
        "identified": {n: [float(v), float(s)] for n, v, s in
                       zip(out.report.identifiable_names, est.theta, est.std, strict=True)},
        "validation": scalars(out.validation),
        "fit": scalars(out.fit),
        "prediction": scalars(out.prediction),
        "selection": out.selection.as_dict() if out.selection is not None else None,
        "measured_design": out.measured_design,
        "candidate_counts": out.candidates.counts if out.candidates is not None else None,
        "gradient_design": out.gradient.as_dict() if out.gradient is not None else None,
    }
    figures = {}
    if cfg.figures:
        from pipeline.calibration import plots

        figures = plots.stage_figures(out)
    data["design_table"] = out.design_table
    return StageResult(summary=summary, arrays=arrays, data=data, figures=figures, robot=out.robot,
                       report_md=report_markdown(out, cfg, ctx.robot) + dtab.markdown_section(out.design_table))
