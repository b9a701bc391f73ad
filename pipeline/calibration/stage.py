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
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from pipeline.blas import single_thread_blas
from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import design_rounding as dr
from pipeline.calibration import design_table as dtab
from pipeline.calibration import error_model as em
from pipeline.calibration import feasibility as fz
from pipeline.calibration import grid_cache, plots, subsets
from pipeline.calibration import indices as ix
from pipeline.calibration import marker_frame as mf
from pipeline.calibration import measure as ms
from pipeline.calibration import model_selection as msel
from pipeline.calibration import noise_model as nm
from pipeline.calibration import task_space as ts
from pipeline.calibration import validate as va
from pipeline.calibration.config import MAX_CANDIDATES, Config
from pipeline.calibration.crossval import cross_validate
from pipeline.calibration.elastostatic import (
    design_basis,
    design_blocks,
    design_torques,
    gravity_model_of,
    gravity_pass,
    load_gravity_model,
    measure_with_payload,
    measurement_model,
    negligible_compliances,
    static_torque_record,
)
from pipeline.calibration.estimate import Estimate, calibrated_robot, register_points
from pipeline.calibration.gradient_design import GradientDesignConfig, gradient_design
from pipeline.calibration.gravity_uncertainty import GravityCovariance
from pipeline.calibration.outcome import CalibrationOutcome
from pipeline.calibration.report import (  # noqa: F401 - re-exported (tests, notebook)
    from_file,
    n_not_visible,
    report_markdown,
    summary_of,
    visibility_sentence,
)
from pipeline.errors import ConfigError, InfeasibleError, PipelineError
from pipeline.progress import task
from pipeline.quality import QualityGates
from pipeline.robot.iso_search import POSE_AXES
from pipeline.robot.model import RobotModel
from pipeline.robot.residual_map import ResidualMap
from pipeline.stage_api import StageResult

NAME = "calibration"
DEPENDS: tuple[str, ...] = ("model",)
CONFIG_READS: tuple[str, ...] = ("control.iso",)
#: fields naming files or folders: the inputs hash covers their content, not their path
FILE_INPUTS: tuple[str, ...] = ("gravity_model", "measurements_csv", "validation_csv", "working_csv")
#: provenance (pipeline.stage_plan): the field naming a recorded file, else what is simulated
RECORDED_INPUT = "measurements_csv"
SIMULATES = "tracker readings of the hidden robot"
#: at most about this many candidates are saved for the viewer (every k-th)
VIEWER_CANDIDATES = 2000
#: cross-validation folds for a measurement file without a validation file (calibration.cross_validation_folds 0)
DEFAULT_FOLDS = 5

def identify_parameter_set(robot: RobotModel, mm: em.MeasurementModel, cfg: Config, rng: np.random.Generator
                           ) -> tuple[em.IdentifiabilityReport, np.ndarray]:
    """Identifiability analysis on random configurations (paper 002 SVD, paper 003 correlations)
    of the parameters in ``calibration.parameters`` (:mod:`pipeline.calibration.subsets`).

    Returns the report (in the error model's own parameters) and the basis ``P`` (n_full, p) of
    the identifiable parameters, ``x = P theta``.
    """
    Q = em.random_configurations(robot, cfg.identifiability_samples, rng)
    if mm.marker_points:   # 6-D readings: the marker origin and the two virtual axis points
        n = len(Q)
        offsets = np.repeat(ms.MARKER_LEVER_M * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), n, 0)
        _, J = mm.jacobian(np.concatenate([Q] * 3), np.zeros(mm.n), robot.tracker.transform_tracker_to_base,
                           offsets=offsets)
    elif mm.compliance:   # the elastostatic columns need the gravity torques: the CasADi model
        _, J = mm.jacobian(Q, np.zeros(mm.n), robot.tracker.transform_tracker_to_base)
    else:
        _, J = cd.nominal_jacobian(cd.chain_from_robot(robot), Q, robot.tracker.transform_tracker_to_base)
    J = J.reshape(-1, mm.n)
    if mm.compliance:   # no gravity torque on a joint: its compliance has no effect
        J[:, np.arange(mm.n)[mm.sl_compliance][negligible_compliances(mm, J)]] = 0.0
    if cfg.error_model == "se3":
        B, names = np.eye(mm.n), mm.names
    else:
        try:
            B, names = em.mdh_basis(robot, mm.names)
        except ValueError as exc:
            raise ConfigError(None, "calibration.error_model", f"mdh_hayati: {exc}") from None
    cols = subsets.select(cfg.parameters, names)
    rep = em.identifiability((J @ B)[:, cols], [names[i] for i in cols], cfg.identifiability_rel_tol)
    return rep, em.parameter_basis(rep, mm.n, B[:, cols])


def build_candidates(robot: RobotModel, cfg: Config, basis: np.ndarray, rng: np.random.Generator,
                     static_torques: Callable[[np.ndarray], np.ndarray] | None = None) -> cd.CandidateSet:
    """Filtered candidate set with whitened Jacobians (nominal model, nominal tracker pose;
    ``static_torques`` for a basis with compliances, :func:`cd.build_candidate_set`)."""
    chain = cd.chain_from_robot(robot)
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(cfg.margin_incidence_deg), cfg.margin_beam_m)
    grid_index = None
    # a first 1 % of random configurations: none feasible -> stop with the cause, not after minutes
    first = fz.probe(chain, margins, [c.name for c in robot.capsules])
    if first.n_feasible == 0:
        raise fz.infeasible_error(first, robot.spec.path)
    if cfg.candidates == "grid":
        per_axis = cfg.grid_points_per_axis(robot.nq)
        with task(f"calibration: filtering the {per_axis}^{robot.nq} grid") as bar:
            Q, grid_index, counts = grid_cache.filter_grid(chain, per_axis, margins, progress=bar)
    else:
        Q, counts = cd.random_candidates(chain, cfg.n_random_candidates, rng, margins)
    if len(Q) == 0:
        counts_text = ", ".join(f"{k} {v}" for k, v in counts.items() if k != "time_s")
        key = "calibration.grid_per_axis" if cfg.candidates == "grid" else "calibration.candidates"
        raise InfeasibleError(None, key,
                              f"no feasible candidate configuration (joint limits, collisions, floor, tracker "
                              f"visibility with the calibration.margin_* values; {counts_text})")
    return cd.build_candidate_set(chain, Q, basis, robot.tracker.transform_tracker_to_base, counts, grid_index,
                                  static_torques=static_torques)


def too_few_candidates(cfg: Config, robot: RobotModel, n_feasible: int) -> str:
    """Message for a candidate set smaller than ``n_configurations``, in the user's fields."""
    rules = "joint limits, collisions, floor, tracker visibility with the calibration.margin_* values"
    if cfg.candidates == "random":
        return (f"only {n_feasible} feasible random configurations were found ({rules}; n_random_candidates = "
                f"{cfg.n_random_candidates}), fewer than the {cfg.n_configurations} configurations asked for: "
                "lower n_configurations or the margins, or check the robot's limits, capsules and tracker pose")
    per_axis = cfg.grid_points_per_axis(robot.nq)
    return (f"only {n_feasible} of the {per_axis}^{robot.nq} grid configurations (grid_per_axis = "
            f"{per_axis}) are feasible ({rules}), fewer than the {cfg.n_configurations} configurations "
            "asked for: raise grid_per_axis or lower n_configurations")


def working_jacobian(robot: RobotModel, mm: em.MeasurementModel, Qw: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """TCP-position Jacobian rows (3 n_w, p) at working configurations wrt ``theta`` (base frame;
    tracker and reflector parameters do not move the TCP; compliances by the gravity deflection,
    :func:`pipeline.calibration.task_space.tcp_jacobian`)."""
    return ts.tcp_jacobian(mm, Qw, basis, robot.frame_tcp)


def index_spec(cfg: Config, robot: RobotModel, mm: em.MeasurementModel, basis: np.ndarray, rng: np.random.Generator,
               region: ts.WorkingRegion | None = None) -> tuple[ix.IndexSpec, np.ndarray | None]:
    """The observability index; for the TCP criteria random collision-free working poses (``V``: in
    the working region, :mod:`pipeline.calibration.task_space`)."""
    if cfg.index_name == "V":
        Qw = ts.sample_region(robot, region or ts.default_region(robot), cfg.n_region_configurations, rng)
        return ts.task_space_spec(mm, Qw, basis, cfg.design_figure), Qw
    if not cfg.index_name.startswith("tcp_A"):
        return ix.IndexSpec(cfg.index_name), None
    chain = cd.chain_from_robot(robot)
    Qw, _ = cd.random_candidates(chain, cfg.n_working_configurations, rng, visibility=False)
    Jw = working_jacobian(robot, mm, Qw, basis)
    return ix.IndexSpec(cfg.index_name, working_jacobian=Jw, n_working=len(Qw)), Qw


def measured_design(robot: RobotModel, mm: em.MeasurementModel, basis: np.ndarray, Q: np.ndarray, spec: ix.IndexSpec,
                    T_tb, method: str, mounted: np.ndarray | None = None) -> dict:
    """Observability index of the configurations ``Q`` actually measured (nominal model, whitened
    by the tracker noise model, tracker pose ``T_tb``, the payload's torque where ``mounted``);
    same conventions as the selection."""
    G = design_blocks(mm, Q, basis, T_tb, mounted).reshape(-1, basis.shape[1])
    Y = cd.nominal_jacobian(cd.chain_from_robot(robot), Q, T_tb)[0] if spec.needs_positions else None
    value = ix.evaluate(spec, G.T @ G, len(Q), Y)
    return {"method": method, "index_name": spec.name, "n_configurations": int(len(Q)), "index_value": float(value)}


def predicted_on_random_poses(robot: RobotModel, mm: em.MeasurementModel, est: Estimate, cfg: Config,
                              rng: np.random.Generator, gravity: GravityCovariance | None = None,
                              noise: nm.NoiseModel | None = None, residual_map: ResidualMap | None = None) -> dict:
    """Covariance-predicted error over ``n_heldout`` random collision-free poses visible to the
    identified tracker (nominal model only: nothing is measured)."""
    chain = cd.chain_from_robot(robot, est.transform_tracker_to_base)
    margins = cd.FilterMargins(cfg.margin_collision_m, math.radians(1.0), 0.005)
    Q, _ = cd.random_candidates(chain, cfg.n_heldout, rng, margins)
    sigma = (noise or nm.NoiseModel()).total(ms.noise_model_sigma(robot, mm.predict(Q, est.x, est.registration)))
    return va.predicted_error(mm, est, Q, sigma, gravity, residual_map)


def calibrate(robot: RobotModel, real, cfg: Config, rng: np.random.Generator, progress=None,
              region: ts.WorkingRegion | None = None) -> CalibrationOutcome:
    """Run the whole calibration (see the module docstring) and return its outcome.

    ``real`` is only used without ``cfg.measurements_csv`` (may be None with a measurement file);
    ``region``: working region of V and the design table (None: :func:`ts.default_region`)."""
    with single_thread_blas():
        return _calibrate(robot, real, cfg, rng, progress, region or ts.default_region(robot))


def _calibrate(robot: RobotModel, real, cfg: Config, rng: np.random.Generator, progress, region) -> CalibrationOutcome:
    timings: dict[str, float] = {}
    t = time.perf_counter()
    user = ms.read_csv(cfg.measurements_csv, robot, min_rows=1) if cfg.measurements_csv else None
    val_user = ms.read_csv(cfg.validation_csv, robot, min_rows=1) if cfg.validation_csv else None
    if cfg.position_sigma_m is not None:
        for m in (user, val_user):
            if m is not None:
                m.sigma_m = np.full(len(m), float(cfg.position_sigma_m))
    six_d = user is not None and user.rotvec is not None and cfg.use_orientation
    notes: dict = {}
    if six_d and user is not None:   # a marker turned on the flange: its rotation in closed form first
        notes["marker_rotation_on_flange"], user, val_user = mf.align_records(robot, user, val_user)
    cfg, notes["model_selection"] = msel.choose_parameters(robot, cfg, user, six_d, rng, identify_parameter_set)
    mm = measurement_model(robot, cfg, marker_points=six_d)
    upstream_gravity = load_gravity_model(cfg, robot)
    if upstream_gravity is not None:
        mm.set_gravity_model(gravity_model_of(robot, upstream_gravity))
    report, basis = identify_parameter_set(robot, mm, cfg, rng)
    dbasis = design_basis(mm, basis)
    timings["identifiability_s"] = time.perf_counter() - t
    p = basis.shape[1]
    if user is not None:
        ms.check_rows(cfg.use_orientation, user, p, robot)
    selection = None
    cs = None
    grad = None
    Qw = None
    spec = None
    if user is None:
        if real is None:
            raise PipelineError(None, "calibration", "no measurement file and no simulated robot")
        t = time.perf_counter()
        cs = build_candidates(robot, cfg, dbasis, rng, design_torques(mm))
        timings["candidates_s"] = time.perf_counter() - t
        if len(cs) < cfg.n_configurations:
            raise InfeasibleError(None, "calibration.grid_per_axis" if cfg.candidates == "grid"
                                  else "calibration.n_configurations", too_few_candidates(cfg, robot, len(cs)))
        spec, Qw = index_spec(cfg, robot, mm, dbasis, rng, region)
        positions = cs.Y if spec.needs_positions else None
        pilot = None
        n_design = cfg.n_configurations
        if cfg.selection_method == "gradient":
            pilot = ms.measure_simulated(real, cs.Q[rng.choice(len(cs), size=min(cfg.n_pilot, len(cs)),
                                                                replace=False)], rng)
            n_design = cfg.n_configurations - pilot.n_requested
        t = time.perf_counter()
        method = "remove_and_replace" if cfg.selection_method == "gradient" else cfg.selection_method
        if method == "remove_and_replace" and cfg.design_start == "approximate":
            selection = dr.approximate_remove_and_replace(cs.G, spec, n_design, rng, positions=positions,
                                                          restarts=cfg.design_restarts, n_initial=cfg.n_initial)
        else:
            kw: dict[str, Any] = {"n_initial": cfg.n_initial} if method == "remove_and_replace" else {}
            selection = ds.select(method, cs.G, spec, n_design, rng, positions=positions, **kw)
        timings["selection_s"] = time.perf_counter() - t
        Q_sel = cs.Q[selection.selected]
        if pilot is not None:
            t = time.perf_counter()
            T_pilot = register_points(pilot.Y, mm.base_positions(pilot.Q, np.zeros(mm.n))[0]) \
                if len(pilot) >= 3 else None
            grad = gradient_design(robot, mm, dbasis, Q_sel, spec, GradientDesignConfig(
                max_iterations=cfg.gradient_max_iterations), transform_tracker_to_base=T_pilot)
            timings["gradient_s"] = time.perf_counter() - t
            Q_sel = grad.Q
        t = time.perf_counter()
        meas = ms.measure_simulated(real, Q_sel, rng)
        if pilot is not None:
            meas = ms.concatenate([pilot, meas], meas.source)
        meas = measure_with_payload(mm, real, meas, cfg, rng, dbasis, spec)
        timings["measure_s"] = time.perf_counter() - t
        if 3 * len(meas) < p:
            raise InfeasibleError(None, "calibration.n_configurations",
                                  f"only {len(meas)} of the {meas.n_requested} measured configurations were visible "
                                  f"to the tracker; the {p} identifiable parameters need at least "
                                  f"{ms.min_configurations(p)}: raise n_configurations")
    else:
        meas = user  # the user's configurations: no candidates, no selection, no simulated robot
    t = time.perf_counter()
    rec = ms.expand_orientation(meas, cfg.orientation_sigma_rad) if six_d else meas   # the fitted rows
    gravity = GravityCovariance(mm, cfg.gravity_prior())
    robust: dict[str, Any] = {"loss": cfg.robust_loss, "confidence": cfg.outlier_confidence,
                              "max_fraction": cfg.max_outlier_fraction}
    kappa = notes["model_selection"].orientation_scale if notes["model_selection"] is not None else 1.0
    est, rejection, noise = nm.fit_with_noise_model(mm, rec, basis, nm.NoiseModel(nm.repeatability_sigma_m(
        robot.spec.repeatability_m or 0.0), orientation_scale=kappa), gravity, max_iterations=cfg.max_lm_iterations,
        **robust)
    notes |= {"fit_record": rec} if six_d else {}
    notes["noise_model"] = noise
    sel = notes["model_selection"]
    notes["residual_map"] = msel.final_residual_map(sel, mm, est, user, rec, rejection.rejected, rng)
    folds = cfg.cross_validation_folds or (DEFAULT_FOLDS if user is not None and val_user is None else 0)
    if user is not None and (folds or sel is not None):
        groups = nm.row_groups(rec.offset_m, len(rec))
        cv = cross_validate(mm, rec, basis, noise.total(rec.sigma_m, groups), folds or sel.folds,
                            cfg.max_lm_iterations, gravity=gravity,
                            map_rng=rng if notes["residual_map"] is not None else None,
                            noise_sigma_m=replace(noise, orientation_scale=1.0).total(rec.sigma_m, groups), **robust)
        # the model selection's figures of the chosen model; the gates' actual/predicted from this fit's noise model
        notes["cross_validation"] = cv | sel.cross_validation() if sel is not None else cv
    if upstream_gravity is not None:
        notes["gravity_pass"] = gravity_pass(mm, rec, basis, est, rejection.rejected, cfg, str(cfg.gravity_model))
    if mm.compliance:
        notes["static_torques"] = static_torque_record(mm, meas, est, basis, report.identifiable_names)
    timings["estimate_s"] = time.perf_counter() - t
    t = time.perf_counter()
    if val_user is not None:
        held = val_user
        held.sigma_m = noise.total(held.sigma_m)
    elif user is not None:
        held = None  # real tracker data: a simulated held-out set would be fiction
    else:
        if real is None:
            raise PipelineError(None, "calibration.validation_csv", "no validation file and no simulated robot")
        held = heldout_measurements(robot, real, est, cfg, rng)
        held.sigma_m = noise.total(held.sigma_m)
    validation = (va.validate(mm, est, held, cfg.outlier_confidence, gravity, cfg.orientation_sigma_rad,
                              notes["residual_map"]) if held is not None else None)
    if held is not None:
        notes["heldout_configurations"] = held.Q      # drawn by the viewer
    timings["validate_s"] = time.perf_counter() - t
    if spec is None:
        spec, Qw = index_spec(cfg, robot, mm, dbasis, rng, region)
    design = measured_design(robot, mm, dbasis, meas.Q, spec, est.transform_tracker_to_base,
                             "user file" if user is not None else "measured subset", meas.payload_mounted)
    fit = va.fit_residuals(mm, est, rec, rejection.rejected)
    prediction = (predicted_on_random_poses(robot, mm, est, cfg, rng, gravity, noise, notes["residual_map"])
                  if validation is None else None)
    new_robot = calibrated_robot(robot, mm, est.x, basis, est.covariance)
    new_robot.residual_map = notes["residual_map"]   # later stages' forward kinematics (pipeline.robot)
    table = dtab.for_run(cfg, robot, real if user is None else None, mm, basis, spec, meas.Q, est, cs, region, rng,
                         dbasis)
    return CalibrationOutcome(report, mm.names, cs, selection, meas, est, validation, new_robot, timings, grad, Qw,
                              design, fit, prediction, rejection, notes, table)


def heldout_measurements(robot: RobotModel, real, est: Estimate, cfg: Config,
                         rng: np.random.Generator) -> ms.Measurements:
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


def check(config: Config, robot: RobotModel) -> None:
    """Robot-dependent checks and the user files, before the runner creates any directory."""
    cfg = config
    user = ms.read_csv(cfg.measurements_csv, robot, min_rows=1) if cfg.measurements_csv else None
    mm = measurement_model(robot, cfg, marker_points=user is not None and user.rotvec is not None
                           and cfg.use_orientation)
    load_gravity_model(cfg, robot)
    need_samples = -(-mm.n // 3)
    if cfg.identifiability_samples < need_samples:
        raise ConfigError(None, "calibration.identifiability_samples",
                          f"{cfg.identifiability_samples} random configurations give {3 * cfg.identifiability_samples} "
                          f"equations for the {mm.n} model parameters of {robot.name}; need at least {need_samples} "
                          "(default 200)")
    if cfg.working_region == "iso_cube" and robot.nq < POSE_AXES:
        raise ConfigError(None, "calibration.working_region", f"iso_cube: the ISO 9283 path holds a 6-D tool pose, "
                          f"which the {robot.nq} axes of {robot.name} cannot follow; use box (working_box_m) or csv")
    max_inc = math.degrees(robot.tracker.max_incidence_rad)
    if cfg.margin_incidence_deg >= max_inc:
        raise ConfigError(None, "calibration.margin_incidence_deg",
                          f"{cfg.margin_incidence_deg} deg leaves no visible pose: the tracker's maximum incidence "
                          f"angle of {robot.name} is {max_inc:g} deg; the margin must be smaller")
    if not cfg.measurements_csv and cfg.candidates == "grid":
        per_axis = cfg.grid_points_per_axis(robot.nq)
        n_grid = per_axis ** robot.nq
        if n_grid > MAX_CANDIDATES:
            raise ConfigError(None, "calibration.grid_per_axis",
                              f"{per_axis}^{robot.nq} = {n_grid:.3g} grid configurations, at most "
                              f"{MAX_CANDIDATES:.3g} (time and memory); lower grid_per_axis or use candidates: random")
    _, basis = identify_parameter_set(robot, mm, cfg, np.random.default_rng(0))
    p = basis.shape[1]
    n_min = ms.min_configurations(p)
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
        ms.check_rows(cfg.use_orientation, user, p, robot)
    if cfg.validation_csv:
        ms.read_csv(cfg.validation_csv, robot, min_rows=1)


def run(ctx) -> Any:
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
    if out.rejection is not None and out.rejection.n_rejected:
        arrays["outliers_rejected_rows"] = np.asarray(out.rejection.rejected, int)
    if out.measurements.invisible is not None and len(out.measurements.invisible):
        arrays["configurations_not_visible"] = out.measurements.invisible
    if out.validation is not None:
        arrays["heldout_errors_before_m"] = out.validation["errors_before_m"]
        arrays["heldout_errors_after_m"] = out.validation["errors_after_m"]
        arrays["heldout_predicted_std_m"] = out.validation["predicted_std_m"]
    if "static_torques" in out.notes:                     # elastostatic model: for later gravity models
        arrays.update(out.notes["static_torques"].to_arrays())
    if out.notes.get("heldout_configurations") is not None:   # for the viewer's layers
        arrays["configurations_heldout"] = out.notes["heldout_configurations"]
    if out.candidates is not None and len(out.candidates):
        arrays["configurations_candidates"] = out.candidates.Q[:: max(1, len(out.candidates) // VIEWER_CANDIDATES)]
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
    extra_summary, extra_arrays, selection_md = msel.stage_entries(out.notes, cfg.parameters)
    summary |= extra_summary
    arrays |= extra_arrays
    figures = {}
    if cfg.figures:
        figures = plots.stage_figures(out)
    data["design_table"] = out.design_table
    result = StageResult(summary=summary, arrays=arrays, data=data, figures=figures, robot=out.robot,
                         report_md=selection_md + report_markdown(out, cfg, ctx.robot)
                         + dtab.markdown_section(out.design_table))
    gates = QualityGates(NAME, accept_poor=ctx.run.accept_poor)
    va.check_gates(gates, summary, cfg)
    return gates.finish(result)
