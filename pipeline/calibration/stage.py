"""Stage ``calibration``: optimal measurement configurations and geometric calibration.

Pipeline (papers 004 §3, 000, 002, 003):

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

:func:`calibrate` runs these as named steps: :func:`read_records`, :func:`set_up_model` (step 1,
:func:`pipeline.calibration.design.identify_parameter_set`), :func:`design_configurations` (2-3,
:mod:`pipeline.calibration.design`), :func:`measure_design` (4, :mod:`pipeline.calibration.measure`),
:func:`fit_model` (5, :mod:`pipeline.calibration.noise_model`), :func:`validate_heldout` (6,
:mod:`pipeline.calibration.validate`) and :func:`outcome`; :func:`run` adds the outputs
(:mod:`pipeline.calibration.report`) and the quality gates.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from pipeline.calibration import design as ds
from pipeline.calibration import design_rounding as dr
from pipeline.calibration import design_table as dtab
from pipeline.calibration import gates as cg
from pipeline.calibration import indices as ix
from pipeline.calibration import marker_frame as mf
from pipeline.calibration import measure as ms
from pipeline.calibration import model_selection as msel
from pipeline.calibration import noise_model as nm
from pipeline.calibration import plots
from pipeline.calibration import task_space as ts
from pipeline.calibration import validate as va
from pipeline.calibration.config import Config, check_design_size, check_robot_fields
from pipeline.calibration.crossval import cross_validate
from pipeline.calibration.design import (  # noqa: F401 - build_candidates etc. re-exported (tests, studies)
    build_candidates,
    identify_parameter_set,
    index_spec,
    measured_design,
    too_few_candidates,
    working_jacobian,
)
from pipeline.calibration.design_identifiable import restrict_to_pool
from pipeline.calibration.elastostatic import (
    design_basis,
    design_torques,
    gravity_model_of,
    gravity_pass,
    load_gravity_model,
    measure_with_payload,
    measurement_model,
    static_torque_record,
)
from pipeline.calibration.estimate import calibrated_robot, register_points
from pipeline.calibration.gradient_design import GradientDesignConfig, GradientDesignResult, gradient_design
from pipeline.calibration.gravity_uncertainty import GravityCovariance
from pipeline.calibration.measure import heldout_measurements
from pipeline.calibration.outcome import CalibrationNotes, CalibrationOutcome, Design, Fit, ModelSetUp, UserRecords
from pipeline.calibration.report import (  # noqa: F401 - re-exported (tests, notebook)
    VIEWER_CANDIDATES,
    from_file,
    n_not_visible,
    report_markdown,
    stage_arrays,
    stage_data,
    summary_of,
    visibility_sentence,
)
from pipeline.calibration.validate import predicted_on_random_poses
from pipeline.core.blas import single_thread_blas
from pipeline.core.errors import InfeasibleError, PipelineError
from pipeline.quality import QualityGates
from pipeline.robot.model import RobotModel
from pipeline.stage_api import StageContext, StageResult

NAME = "calibration"
DEPENDS: tuple[str, ...] = ("model",)
CONFIG_READS: tuple[str, ...] = ("control.iso",)
#: provenance (pipeline.run.stage_plan): the field naming a recorded file, else what is simulated
RECORDED_INPUT = "measurements_csv"
SIMULATES = "tracker readings of the hidden robot"
warm_up = None                       # its compiled code is built where it is used
#: cross-validation folds for a measurement file without a validation file (calibration.cross_validation_folds 0)
DEFAULT_FOLDS = 5


def check(config: Config, robot: RobotModel) -> None:
    """Robot-dependent checks and the user files, before the runner creates any directory."""
    cfg = config
    user = ms.read_measurements(cfg.measurements_csv, robot, cfg) if cfg.measurements_csv else None
    mm = measurement_model(robot, cfg, marker_points=user is not None and user.rotvec is not None
                           and cfg.use_orientation)
    load_gravity_model(cfg, robot)
    check_robot_fields(cfg, robot, mm.n)
    _, basis = identify_parameter_set(robot, mm, cfg, np.random.default_rng(0))
    p = basis.shape[1]
    check_design_size(cfg, robot, p, ms.min_configurations(p))
    if user is not None:
        ms.check_rows(cfg.use_orientation, user, p, robot)
    if cfg.validation_csv:
        ms.read_validation(cfg.validation_csv, robot, cfg)


def run(ctx: StageContext[Config]) -> StageResult:
    cfg: Config = ctx.config
    t0 = time.perf_counter()
    # recorded or simulated is the plan's decision (pipeline.run.stage_plan, ctx.provenance): a recorded
    # stage gets no hidden robot (ctx.real None), and with a measurement file calibrate never uses one
    region = ts.region_of_run(getattr(ctx, "run", None), cfg, ctx.robot)
    out = calibrate(ctx.robot, ctx.real, cfg, ctx.rng, getattr(ctx, "progress", None), region)
    result = outputs(out, cfg, ctx.robot, t0)
    gates = QualityGates(NAME, accept_poor=ctx.run.accept_poor)
    cg.check_gates(gates, result.summary, cfg)
    gates.finish(result)   # records the gates in the summary; raises unless passed or accepted
    return result


def outputs(out: CalibrationOutcome, cfg: Config, robot: RobotModel, t0: float) -> StageResult:
    """Summary, arrays, data, figures and report text (:mod:`pipeline.calibration.report`), with
    the model selection's entries; ``t0``: the stage's start (``time.perf_counter``)."""
    summary = summary_of(out, cfg)
    summary["design_table"] = dtab.summary(out.design_table)
    summary["stage_time_s"] = time.perf_counter() - t0
    arrays = stage_arrays(out)
    data = stage_data(out)
    extra_summary, extra_arrays, selection_md = msel.stage_entries(out.notes, cfg.parameters)
    summary |= extra_summary
    arrays |= extra_arrays
    figures = plots.stage_figures(out) if cfg.figures else {}
    return StageResult(summary=summary, arrays=arrays, data=data, figures=figures, robot=out.robot,
                       report_md=selection_md + report_markdown(out, cfg, robot)
                       + dtab.markdown_section(out.design_table))


def calibrate(robot: RobotModel, real, cfg: Config, rng: np.random.Generator, progress=None,
              region: ts.WorkingRegion | None = None) -> CalibrationOutcome:
    """Run the whole calibration (see the module docstring) and return its outcome.

    ``real`` is only used without ``cfg.measurements_csv`` (may be None with a measurement file);
    ``region``: working region of V and the design table (None: :func:`ts.default_region`)."""
    with single_thread_blas():
        return _calibrate(robot, real, cfg, rng, progress, region or ts.default_region(robot))


def _calibrate(robot: RobotModel, real, cfg: Config, rng: np.random.Generator, progress,
               region: ts.WorkingRegion) -> CalibrationOutcome:
    """The steps in order; ``timings`` collects their times (s), ``notes`` the report's extra parts."""
    timings: dict[str, float] = {}
    t = time.perf_counter()
    records, notes = read_records(robot, cfg)
    model = set_up_model(robot, cfg, records, rng, notes)
    timings["identifiability_s"] = time.perf_counter() - t
    design: Design | None = None
    if records.measurements is None:
        design = design_configurations(robot, real, model, rng, region, timings)
        notes.design_dropped = list(model.dropped)
        meas = measure_design(real, model, design, rng, timings)
    else:   # the user's configurations: no candidates, no selection, no simulated robot
        ms.check_rows(model.cfg.use_orientation, records.measurements, model.basis.shape[1], robot)
        meas = records.measurements
    t = time.perf_counter()
    fit = fit_model(robot, model, records, meas, rng, notes)
    timings["estimate_s"] = time.perf_counter() - t
    t = time.perf_counter()
    validation = validate_heldout(robot, real, model, records, fit, rng, notes)
    timings["validate_s"] = time.perf_counter() - t
    return outcome(robot, real, model, records, design, meas, fit, validation, rng, region, timings, notes)


def read_records(robot: RobotModel, cfg: Config) -> tuple[UserRecords, CalibrationNotes]:
    """The user's measurement and validation files (``position_sigma_m`` overriding their sigma);
    for 6-D readings the marker's rotation on the flange in closed form first
    (:func:`pipeline.calibration.marker_frame.align_records`), kept in the returned notes."""
    user = ms.read_measurements(cfg.measurements_csv, robot, cfg) if cfg.measurements_csv else None
    val_user = ms.read_validation(cfg.validation_csv, robot, cfg) if cfg.validation_csv else None
    if cfg.position_sigma_m is not None:
        for m in (user, val_user):
            if m is not None:
                m.sigma_m = np.full(len(m), float(cfg.position_sigma_m))
    six_d = user is not None and user.rotvec is not None and cfg.use_orientation
    notes = CalibrationNotes()
    if six_d and user is not None:   # a marker turned on the flange: its rotation in closed form first
        notes.marker_rotation_on_flange, user, val_user = mf.align_records(robot, user, val_user)
    return UserRecords(user, val_user, six_d), notes


def set_up_model(robot: RobotModel, cfg: Config, records: UserRecords, rng: np.random.Generator,
                 notes: CalibrationNotes) -> ModelSetUp:
    """The parameter subset (model selection on a measurement file, ``notes.model_selection``),
    the measurement model with the upstream gravity model, the identifiable parameter set."""
    cfg, notes.model_selection = msel.choose_parameters(robot, cfg, records.measurements, records.six_d, rng,
                                                           identify_parameter_set)
    mm = measurement_model(robot, cfg, marker_points=records.six_d)
    upstream_gravity = load_gravity_model(cfg, robot)
    if upstream_gravity is not None:
        mm.set_gravity_model(gravity_model_of(robot, upstream_gravity))
    report, basis = identify_parameter_set(robot, mm, cfg, rng)
    return ModelSetUp(cfg, mm, report, basis, design_basis(mm, basis), upstream_gravity)


def design_configurations(robot: RobotModel, real, model: ModelSetUp, rng: np.random.Generator,
                          region: ts.WorkingRegion, timings: dict[str, float]) -> Design:
    """Candidates, the observability index, the selection (after a pilot measurement for the
    gradient design) and the gradient refinement."""
    if real is None:
        raise PipelineError(None, "calibration", "no measurement file and no simulated robot")
    cfg = model.cfg
    t = time.perf_counter()
    cs = build_candidates(robot, cfg, model.design_basis, rng, design_torques(model.mm))
    cs, model.dropped = restrict_to_pool(model, cs)       # what the feasible configurations can identify
    timings["candidates_s"] = time.perf_counter() - t
    if len(cs) < cfg.n_configurations:
        raise InfeasibleError(None, "calibration.grid_per_axis" if cfg.candidates == "grid"
                              else "calibration.n_configurations", too_few_candidates(cfg, robot, len(cs)))
    spec, Qw = index_spec(cfg, robot, model.mm, model.design_basis, rng, region)
    pilot = None
    n_design = cfg.n_configurations
    if cfg.selection_method == "gradient":
        pilot = ms.measure_simulated(real, cs.Q[rng.choice(len(cs), size=min(cfg.n_pilot, len(cs)),
                                                            replace=False)], rng)
        n_design = cfg.n_configurations - pilot.n_requested
    t = time.perf_counter()
    selection = select_configurations(cs.G, cs.Y if spec.needs_positions else None, spec, n_design, cfg, rng)
    timings["selection_s"] = time.perf_counter() - t
    Q_sel = cs.Q[selection.selected]
    grad = None
    if pilot is not None:
        t = time.perf_counter()
        grad = refine_by_gradient(robot, model, Q_sel, spec, pilot)
        timings["gradient_s"] = time.perf_counter() - t
        Q_sel = grad.Q
    return Design(cs, spec, Qw, selection, pilot, Q_sel, grad)


def select_configurations(G: np.ndarray, positions: np.ndarray | None, spec: ix.IndexSpec, n_design: int, cfg: Config,
                          rng: np.random.Generator) -> ds.SelectionResult:
    """``n_design`` of the candidates' blocks ``G`` by ``calibration.selection_method``
    (remove-and-replace from the rounded approximate design, or :func:`pipeline.calibration.design.select`)."""
    method = "remove_and_replace" if cfg.selection_method == "gradient" else cfg.selection_method
    if method == "remove_and_replace" and cfg.design_start == "approximate":
        return dr.approximate_remove_and_replace(G, spec, n_design, rng, positions=positions,
                                                 restarts=cfg.design_restarts, n_initial=cfg.n_initial)
    kw: dict[str, Any] = {"n_initial": cfg.n_initial} if method == "remove_and_replace" else {}
    return ds.select(method, G, spec, n_design, rng, positions=positions, **kw)


def refine_by_gradient(robot: RobotModel, model: ModelSetUp, Q_sel: np.ndarray, spec: ix.IndexSpec,
                       pilot: ms.Measurements) -> GradientDesignResult:
    """The gradient-based design (paper 000) from the selected configurations, with the tracker
    pose registered on the pilot measurement (at least 3 readings, else the nominal pose)."""
    mm = model.mm
    T_pilot = register_points(pilot.Y, mm.base_positions(pilot.Q, np.zeros(mm.n))[0]) if len(pilot) >= 3 else None
    return gradient_design(robot, mm, model.design_basis, Q_sel, spec, GradientDesignConfig(
        max_iterations=model.cfg.gradient_max_iterations), transform_tracker_to_base=T_pilot)


def measure_design(real, model: ModelSetUp, design: Design, rng: np.random.Generator,
                   timings: dict[str, float]) -> ms.Measurements:
    """The designed configurations measured by the simulated tracker (after the pilot's, with
    the payload where configured); enough of them must be visible for the parameters."""
    t = time.perf_counter()
    meas = ms.measure_simulated(real, design.Q, rng)
    if design.pilot is not None:
        meas = ms.concatenate([design.pilot, meas], meas.source)
    meas = measure_with_payload(model.mm, real, meas, model.cfg, rng, model.design_basis, design.spec)
    timings["measure_s"] = time.perf_counter() - t
    p = model.basis.shape[1]
    if 3 * len(meas) < p:
        raise InfeasibleError(None, "calibration.n_configurations",
                              f"only {len(meas)} of the {meas.n_requested} measured configurations were visible "
                              f"to the tracker; the {p} identifiable parameters need at least "
                              f"{ms.min_configurations(p)}: raise n_configurations")
    return meas


def _robust_settings(cfg: Config) -> dict[str, Any]:
    return {"loss": cfg.robust_loss, "confidence": cfg.outlier_confidence, "max_fraction": cfg.max_outlier_fraction}


def fit_model(robot: RobotModel, model: ModelSetUp, records: UserRecords, meas: ms.Measurements,
              rng: np.random.Generator, notes: CalibrationNotes) -> Fit:
    """Robust fit with the noise model (:func:`pipeline.calibration.noise_model.fit_with_noise_model`),
    the residual map, the cross-validation, the gravity pass and the static torques (in ``notes``)."""
    cfg, mm, basis = model.cfg, model.mm, model.basis
    rec = ms.expand_orientation(meas, cfg.orientation_sigma_rad) if records.six_d else meas   # the fitted rows
    gravity = GravityCovariance(mm, cfg.gravity_prior())
    sel = notes.model_selection
    kappa = sel.orientation_scale if sel is not None else 1.0
    known = nm.noise_of_robot(robot, records.measurements is not None, kappa)
    est, rejection, noise = nm.fit_with_noise_model(mm, rec, basis, known, gravity,
                                                    max_iterations=cfg.max_lm_iterations, **_robust_settings(cfg))
    notes.fit_record = rec if records.six_d else None
    notes.noise_model = noise
    notes.residual_map = msel.final_residual_map(sel, mm, est, records.measurements, rec, rejection.rejected, rng,
                                                 noise)
    if records.measurements is not None:
        notes.residual_map_floor_m = msel.map_noise_floor_m(noise, records.measurements.sigma_m)
    fit = Fit(rec, gravity, est, rejection, noise)
    cv = cross_validation(model, records, fit, sel, rng if notes.residual_map is not None else None)
    notes.cross_validation = cv
    if model.upstream_gravity is not None:
        notes.gravity_pass = gravity_pass(mm, rec, basis, est, rejection.rejected, cfg, str(cfg.gravity_model))
    if mm.compliance:
        notes.static_torques = static_torque_record(mm, meas, est, basis, model.report.identifiable_names)
    return fit


def cross_validation(model: ModelSetUp, records: UserRecords, fit: Fit, sel: msel.ModelSelection | None,
                     map_rng: np.random.Generator | None) -> dict | None:
    """K-fold cross-validation of a measurement file (``calibration.cross_validation_folds``, else
    :data:`DEFAULT_FOLDS` without a validation file, else the model selection's folds; None: none)."""
    cfg, user = model.cfg, records.measurements
    if user is not None and sel is not None:
        # the model selection's held-out figures of the chosen model (every fold's own noise model): one
        # computation, so every ratio is of the figures beside it
        return sel.cross_validation()
    folds = cfg.cross_validation_folds or (DEFAULT_FOLDS if user is not None and records.validation is None else 0)
    if user is None or not folds:
        return None
    rec, noise = fit.record, fit.noise
    groups = nm.row_groups(rec.offset_m, len(rec))
    return cross_validate(model.mm, rec, model.basis, noise.total(rec.sigma_m, groups), folds,
                          cfg.max_lm_iterations, gravity=fit.gravity, map_rng=map_rng,
                          noise_sigma_m=replace(noise, orientation_scale=1.0).total(rec.sigma_m, groups),
                          map_noise_floor_m=msel.map_noise_floor_m(noise, user.sigma_m), **_robust_settings(cfg))


def validate_heldout(robot: RobotModel, real, model: ModelSetUp, records: UserRecords, fit: Fit,
                     rng: np.random.Generator, notes: CalibrationNotes) -> dict | None:
    """Held-out validation (:func:`pipeline.calibration.validate.validate`) on the validation file,
    or on simulated held-out poses without a measurement file; None with real data and no
    validation file (a simulated held-out set would be fiction)."""
    cfg = model.cfg
    if records.validation is not None:
        held = records.validation
    elif records.measurements is not None:
        return None
    else:
        if real is None:
            raise PipelineError(None, "calibration.validation_csv", "no validation file and no simulated robot")
        held = heldout_measurements(robot, real, fit.estimate, cfg, rng)
    held.sigma_m = fit.noise.total(held.sigma_m)
    gross = None
    if records.validation is not None and records.measurements is not None:
        allowed = heldout_outlier_allowance(fit, len(records.measurements) + len(held), cfg.max_outlier_fraction)
        rec = fit.record      # the fit's residual scale of positions (marker origins), as the screen judges
        origin = nm.row_groups(rec.offset_m, len(rec)) == 0
        gross = va.recorded_gross_rows(model.mm, fit.estimate, held, cfg.outlier_confidence,
                                       fit.rejection.whitened_norm[origin], allowed, fit.gravity)
    orientation_sigma_rad = cfg.orientation_sigma_rad
    if records.six_d and model.mm.marker_points:     # the readings' orientation noise, as the fit left it
        orientation_sigma_rad, _ = va.orientation_noise_rad(model.mm, fit.estimate, fit.record, fit.rejection.rejected,
                                                            cfg.orientation_sigma_rad)
    validation = va.validate(model.mm, fit.estimate, held, cfg.outlier_confidence, fit.gravity,
                             orientation_sigma_rad, notes.residual_map, gross)
    notes.heldout_configurations = held.Q      # drawn by the viewer
    return validation


def heldout_outlier_allowance(fit: Fit, n_poses: int, max_fraction: float) -> int:
    """Held-out poses of a recorded validation file the gross-error screen may leave out:
    ``max_outlier_fraction`` of the whole record (calibration and validation poses) less the
    calibration positions the fit already rejected (marker-origin rows; a 6-D pose's virtual
    marker-point rows carry its orientation, which this screen does not judge). A held-out file of
    four poses cannot state a fraction of its own; the record's readings share one tracker and one
    share of gross errors. ``n_poses``: the calibration and validation poses together."""
    rec = fit.record
    rows = np.asarray(fit.rejection.rejected, int)
    if rec.offset_m is not None:
        rows = rows[nm.row_groups(rec.offset_m, len(rec))[rows] == 0]
    return int(np.floor(max_fraction * n_poses)) - len(rows)


def outcome(robot: RobotModel, real, model: ModelSetUp, records: UserRecords, design: Design | None,
            meas: ms.Measurements, fit: Fit, validation: dict | None, rng: np.random.Generator,
            region: ts.WorkingRegion, timings: dict[str, float], notes: CalibrationNotes) -> CalibrationOutcome:
    """The measured design's index, the fit residuals, the covariance prediction (without a
    held-out set), the calibrated robot (with the residual map) and the design table."""
    cfg, mm, est = model.cfg, model.mm, fit.estimate
    if design is None:
        spec, Qw = index_spec(cfg, robot, mm, model.design_basis, rng, region)
    else:
        spec, Qw = design.spec, design.working_Q
    user = records.measurements
    measured = measured_design(robot, mm, model.design_basis, meas.Q, spec, est.transform_tracker_to_base,
                               "user file" if user is not None else "measured subset", meas.payload_mounted)
    residuals = va.fit_residuals(mm, est, fit.record, fit.rejection.rejected)
    prediction = (predicted_on_random_poses(robot, mm, est, cfg, rng, fit.gravity, fit.noise, notes.residual_map)
                  if validation is None else None)
    new_robot = calibrated_robot(robot, mm, est.x, model.basis, est.covariance)
    new_robot.residual_map = notes.residual_map   # later stages' forward kinematics (pipeline.robot)
    cs = design.candidates if design is not None else None
    table = dtab.for_run(cfg, robot, real if user is None else None, mm, model.basis, spec, meas.Q, est, cs, region,
                         rng, model.design_basis)
    return CalibrationOutcome(model.report, mm.names, cs, design.selection if design is not None else None, meas,
                              est, validation, new_robot, timings, design.gradient if design is not None else None,
                              Qw, measured, residuals, prediction, fit.rejection, notes, table)
