"""Stage ``identification``: optimal Fourier excitation, measurement, estimation, validation,
and the real Stäubli TX40 record (paper ``004_abbe750b8bbcc3aa.txt`` §4).

1. Regressor of the current model (calibrated kinematics when the run has a calibration) and the
   structural base set, decided on the nominal robot and kept for the current one
   (:mod:`.base_set`).
2. Excitation: Fourier trajectory minimising the condition number of the base regressor under
   limits, torques, floor and self-collision (CasADi/IPOPT, random starts; :mod:`.design`),
   against the median of 20 random feasible trajectories; never worse than the best of them
   (fallback, stated in summary and report).
3. Data: the hidden robot follows ``periods`` periods (ideal tracking, sensor noise), or the
   user's CSV record (``data_file``): then no excitation is designed, the condition number is the
   one of the record's base regressor, validation is on the record's held-out tail (fit on the
   first ``data_train_fraction``, :func:`.tx40.heldout_validation`), the noise sigma comes from
   the WLS residuals and the hidden robot (``ctx.real``) is never used. :func:`check` reads and
   checks the record before any stage runs; non-uniform time stamps are resampled, torque columns
   without a signal (or joints not named in ``joints``) are left out (:mod:`.joints`).
4. Period averaging, zero-phase filtering, differentiation, block decimation (:mod:`.measure`);
   the data must excite the model (motion per joint, rank and condition; :mod:`.gates`).
5. OLS, Gautier's WLS (covariance -> base parameter sigmas) and the physically consistent fit
   (log-Cholesky, IPOPT) whose standard parameters become the handed-on ``RobotModel``. With
   ``friction_model: stribeck`` (default) a Stribeck term is fitted first with the base parameters
   (:mod:`.friction`), taken off the torques and handed on in the model's actuation; the
   viscous + Coulomb fit is kept beside it, and the configured model with load-dependent Coulomb
   friction (:func:`.friction.fit_load_friction`, joint-side actuator columns only); all are scored
   on the validation torques and the best one is handed on. Base-parameter sigmas: HAC sandwich
   (:func:`.estimate.hac_covariance`).
6. Validation on the run's ISO 9283 path (``control.iso`` from the run's ``control.ik_seeds_deg``,
   measured vs predicted torques; a random Fourier trajectory, with the real reason in the report,
   when that path cannot be used), or the held-out tail of a record.
7. The TX40 record, only for the TX40 or when asked (:func:`tx40_wanted`): base parameters,
   condition number, held-out RMS (:mod:`.tx40`).
8. Quality gates (:func:`.gates.add_result_gates`): condition number vs design, validation RMS vs
   noise, predicted torques vs limits -> :class:`~pipeline.core.errors.QualityGateError` unless
   ``--accept-poor``.

:func:`run` sequences these steps; what they hand each other is in :mod:`.outcome`, the summary,
figures and report text are built in :mod:`.report`.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from pipeline.core.blas import single_thread_blas
from pipeline.core.config import resolve_robot_dir
from pipeline.core.errors import ConfigError, InfeasibleError, PipelineError, SolverError
from pipeline.core.solver_status import is_success
from pipeline.identification import design as design_mod
from pipeline.identification import estimate as est_mod
from pipeline.identification import fourier, report
from pipeline.identification import measure as meas_mod
from pipeline.identification import validate as val_mod
from pipeline.identification.base_set import structural_base_parameters
from pipeline.identification.config import DATA_BORDER_SAMPLES, Config, ExcitationConfig
from pipeline.identification.friction import (
    MAX_EXCESS_OVER_LIMIT,
    LoadFriction,
    best_friction_model,
    expand_to_joints,
    fit_load_friction,
    fit_stribeck,
    friction_summary,
    load_free_torque,
    load_heldout,
    load_summary,
    stribeck_heldout,
)
from pipeline.identification.gates import add_result_gates, check_data_excites
from pipeline.identification.joints import select_joints
from pipeline.identification.outcome import (
    Fits,
    LoadCandidate,
    Measured,
    Outcome,
    Regressors,
    Validation,
    identified_robot,
)
from pipeline.identification.record import load_user_record
from pipeline.identification.regressor import RegressorModel, standard_parameters
from pipeline.identification.tx40 import Tx40Result, check_tx40_config, heldout_validation, run_tx40
from pipeline.quality import QualityGates
from pipeline.robot.assumed_values import predicted_drive_values
from pipeline.robot.defaults import iso_or_derived
from pipeline.robot.model import RobotModel
from pipeline.robot.symbolic import SymbolicRobot
from pipeline.stage_api import StageContext, StageResult

NAME = "identification"
DEPENDS: tuple[str, ...] = ("model", "calibration")
#: fields naming files: the inputs hash covers their content, not their path
FILE_INPUTS: tuple[str, ...] = ("data_file",)
#: provenance (pipeline.run.stage_plan): the field naming a recorded file, else what is simulated
RECORDED_INPUT = "data_file"
SIMULATES = "joint torques of the hidden robot"
#: settings of other sections this stage reads (the runner adds them to its inputs hash): the
#: validation path is the run's EN ISO 9283 path (robot ``run_defaults`` included)
CONFIG_READS: tuple[str, ...] = ("control.iso", "control.ik_seeds_deg", "control.ik_tolerance_m",
                                  "control.path_frame")
TX40_ROBOT_NAME = "staubli_tx40"


def tx40_wanted(cfg: Config, robot: RobotModel) -> bool:
    """Fit the Stäubli TX40 record? ``run_tx40`` when set, else only when the robot is the TX40
    or ``tx40.data_dir`` points to a record."""
    if cfg.run_tx40 is not None:
        return bool(cfg.run_tx40)
    return getattr(robot, "name", "") == TX40_ROBOT_NAME or bool(cfg.tx40.data_dir)


def _nominal_robot(ctx: StageContext) -> RobotModel:
    """The robot as loaded from its files (structure of the base parameters)."""
    try:
        return RobotModel.load(resolve_robot_dir(ctx.run))
    except PipelineError:
        return ctx.robot


def check(config: Config, robot: RobotModel) -> None:
    """Called by the runner before any stage runs or anything is written: the configuration
    (robot-dependent ranges), the user's record (``data_file``) if any and the TX40 record's
    folder, so a bad value or file is reported before calibration runs."""
    cfg = config
    cfg.validate(None)
    n_params = 10 * (robot.model.njoints - 1) + 4 * robot.nq   # standard parameters (regressor columns)
    nq = robot.nq
    if cfg.base_samples * nq < n_params:
        raise ConfigError(None, "identification.base_samples",
                          f"{cfg.base_samples} random samples give {cfg.base_samples * nq} regressor rows for the "
                          f"{n_params} standard parameters of {robot.name}; need at least {-(-n_params // nq)} "
                          "(default 300)")
    rec = load_user_record(cfg, robot) if cfg.data_file else None
    select_joints(cfg.joints, [str(n) for n in robot.model.names[1:]], {} if rec is None else rec.unmeasured)
    if rec is None:
        ex = cfg.excitation
        n_per = int(round(1.0 / (ex.base_frequency_hz * cfg.sample_time_s)))
        m = n_per // cfg.decimation
        if m <= n_params:  # the fits need more samples than standard parameters
            raise ConfigError(None, "identification.decimation",
                              f"one period of {n_per} samples (1 / excitation.base_frequency_hz / sample_time_s) "
                              f"decimated by {cfg.decimation} leaves {m} samples, not more than the {n_params} "
                              f"standard parameters of {robot.name}; decimation must be at most "
                              f"{max(n_per // (n_params + 1), 1)}")
    if tx40_wanted(cfg, robot):
        check_tx40_config(cfg.tx40)


# --------------------------------------------------------------------------------------- run
def run(ctx: StageContext) -> StageResult:
    with single_thread_blas():
        return _run(ctx)


def _run(ctx: StageContext) -> StageResult:
    cfg: Config = ctx.config
    cfg.validate(getattr(ctx.run, "source", None))
    if not cfg.data_file and ctx.real is None:
        raise PipelineError(None, "identification", "no hidden robot to measure and no data_file given")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    regs = regressors(ctx, cfg)
    timings["base_parameters_s"] = time.perf_counter() - t0
    measured = excite_and_measure(ctx, cfg, regs, timings)
    fits = estimate(ctx.robot, cfg, regs, measured, timings)
    t1 = time.perf_counter()
    val = (validate_on_record(ctx.robot, cfg, regs, measured, fits) if regs.record is not None
           else validate_on_path(ctx, cfg, regs, measured, fits))
    friction = choose_friction_model(ctx.robot, regs, fits, val)
    hac, white_sigma = base_covariance(regs, measured, fits)
    new_robot = identified_robot(ctx.robot, fits.phys.p, None if fits.stribeck is None
                                 else expand_to_joints(fits.stribeck, regs.used, ctx.robot.nq),
                                 None if fits.load is None else load_to_joints(fits.load.load, regs.used, ctx.robot.nq))
    timings["validation_s"] = time.perf_counter() - t1
    truth = None
    if cfg.score_against_truth and regs.record is None and ctx.real is not None:
        truth = val_mod.truth_scores(ctx.real, regs.base, fits.wls.beta, fits.wls.sigma)
    tx = tx40_record(ctx.robot, cfg, timings)
    timings["total_s"] = time.perf_counter() - t0
    result = report.stage_result(cfg, Outcome(regs, measured, fits, val, friction, hac, white_sigma, truth, tx,
                                              timings), new_robot)
    gates = QualityGates(NAME, accept_poor=bool(getattr(ctx.run, "accept_poor", False)))
    add_result_gates(gates, cfg, fits.cond_data, None if measured.excitation is None
                     else measured.excitation.cond_optimized, val.rms_over_noise, val.pred_phys,
                     ctx.robot.limits.effort_Nm[regs.used], fits.phys.status, regs.used + 1)
    return gates.finish(result)


def regressors(ctx: StageContext, cfg: Config) -> Regressors:
    """The regressor of the current model (calibrated kinematics when the run has a calibration),
    the joints the fit uses, and the structural base set decided on the nominal robot (:mod:`.base_set`)."""
    robot = ctx.robot
    act = robot.actuation
    user_data = bool(cfg.data_file)
    # a record's torques are motor-side through the gear matrix, unless measured on the link side
    coupled = cfg.actuator_coupling == "gear" or (cfg.actuator_coupling == "auto" and user_data
                                                  and act.torque_side == "motor")
    K = act.gear_matrix if coupled else np.eye(robot.nq)
    rec = load_user_record(cfg, robot) if user_data else None  # before any long computation
    # joints whose torques the fit uses: the named ones, else those whose column carries a signal
    sel = select_joints(cfg.joints, [str(n) for n in robot.model.names[1:]], {} if rec is None else rec.unmeasured)
    rows = None if sel.all_used else sel.used
    reg = RegressorModel(robot.model, K, act.coulomb_smoothing_rad_s, rows)
    nominal = _nominal_robot(ctx)
    reg_nominal = RegressorModel(nominal.model, K, act.coulomb_smoothing_rad_s, rows)
    # Structural base set, decided on the nominal model (the design criterion's set); the current
    # (calibrated) model keeps the same set with its own combinations (:mod:`.base_set`)
    base_design, base = structural_base_parameters(reg_nominal, reg, ctx.rng, cfg.base_samples, cfg.base_tolerance,
                                                   robot.limits.lower_rad, robot.limits.upper_rad)
    return Regressors(coupled, rec, sel, reg, base_design, base)


def excite_and_measure(ctx: StageContext, cfg: Config, regs: Regressors, timings: dict[str, float]) -> Measured:
    """The user's record processed (no excitation, nothing simulated), or the optimal excitation
    (:mod:`.design`) run on the hidden robot and processed (:mod:`.measure`)."""
    t1 = time.perf_counter()
    if regs.record is not None:  # the user's record: no excitation to design, nothing simulated
        data = meas_mod.process_record(regs.record, regs.reg, cfg.data_cutoff_hz, cfg.data_decimation,
                                       DATA_BORDER_SAMPLES)
        timings["data_s"] = time.perf_counter() - t1
        return Measured(data, str(cfg.data_file))
    robot, ex = ctx.robot, cfg.excitation
    limits = fourier.ExcitationLimits.from_robot(
        robot, ex.position_margin, ex.velocity_margin, ex.acceleration_margin, ex.torque_margin,
        ex.floor_clearance_m, ex.self_clearance_m, ex.max_tcp_speed_m_s, ex.max_tcp_acceleration_m_s2)
    exc = design_mod.optimize_excitation(
        robot, SymbolicRobot(robot), regs.reg, regs.base_design, limits, ctx.rng, harmonics=ex.harmonics,
        base_frequency_hz=ex.base_frequency_hz, n_samples=ex.n_samples, n_starts=ex.n_starts,
        n_random=ex.n_random, max_iter=ex.max_iter, criterion=ex.criterion, n_check=ex.n_check,
        progress=ctx.progress, softness=ex.cond_softness, objective_change_tol=ex.objective_change_tol)
    timings["excitation_s"] = time.perf_counter() - t1
    traj = exc.trajectory
    if not exc.feasibility.feasible:
        raise InfeasibleError(None, "identification.excitation",
                              f"the excitation violates the limits: {exc.feasibility.to_dict()}")
    t1 = time.perf_counter()
    sim = meas_mod.simulate_excitation(ctx.real, traj, cfg.periods, cfg.sample_time_s, ctx.rng)
    n_per = int(round(traj.period_s / cfg.sample_time_s))
    cutoff = cfg.state_cutoff_factor * ex.harmonics * ex.base_frequency_hz
    data = meas_mod.process_periodic(sim, regs.reg, n_per, cutoff, cfg.decimation)
    timings["data_s"] = time.perf_counter() - t1
    return Measured(data, "simulation (ideal tracking of the hidden robot)", exc, limits, traj)


def estimate(robot: RobotModel, cfg: Config, regs: Regressors, measured: Measured, timings: dict[str, float]) -> Fits:
    """OLS, Gautier's WLS and the physically consistent fit on all samples; with ``friction_model:
    stribeck`` the Stribeck term first (nested in the viscous + Coulomb fit), taken off the torques,
    and the viscous + Coulomb fits beside it (the validation torques choose, :func:`choose_friction_model`)."""
    t1 = time.perf_counter()
    data, base, nm = measured.data, regs.base, regs.n_used
    Wb, y = base.base_regressor(data.Y), data.y
    cond_data = check_data_excites(data.q[:, regs.used], Wb, [f"q{j + 1}" for j in regs.used],
                                   cfg.min_joint_motion_rad, cfg.max_cond_base_regressor_data,
                                   str(cfg.data_file) if cfg.data_file else None)
    cond_data_structural = float(np.linalg.cond(regs.base_design.base_regressor(data.Y)))  # design criterion's set
    wls_vc = est_mod.wls(Wb, y, nm)
    max_excess = MAX_EXCESS_OVER_LIMIT * robot.limits.effort_Nm[regs.used]
    fit = (fit_stribeck(Wb, y, data.v_blocks, wls_vc.beta, wls_vc.joint_sigma_Nm, regs.reg.coulomb_width_rad_s,
                        max_excess_Nm=max_excess) if cfg.friction_model == "stribeck" else None)
    timings["stribeck_fit_s"] = time.perf_counter() - t1
    y_fit = y if fit is None else y - fit.stribeck_torque(data.v_blocks).ravel()
    ols = est_mod.ols(Wb, y_fit, nm)
    wls = wls_vc if fit is None else est_mod.wls(Wb, y_fit, nm)
    drive = predicted_drive_values(robot.actuation, robot.spec.assumed)   # assumed or link-side drive values: 0
    p_nom = standard_parameters(robot.model, drive["rotor_inertia_kgm2"], drive["viscous_Nms_rad"],
                                drive["coulomb_Nm"])
    nq = robot.nq
    phys = est_mod.physical_fit(data.Y, y_fit, nq, p_nom, wls.joint_sigma_Nm, cfg.regularization,
                                cfg.physical_max_iter, n_rows=nm)
    phys_vc = phys if fit is None else est_mod.physical_fit(data.Y, y, nq, p_nom, wls_vc.joint_sigma_Nm,
                                                            cfg.regularization, cfg.physical_max_iter, n_rows=nm)
    timings["estimation_s"] = time.perf_counter() - t1
    fits = Fits(Wb, y, cond_data, cond_data_structural, wls_vc, max_excess, fit, y_fit, ols, wls, p_nom, phys,
                phys_vc)
    fit_load_candidate(cfg, regs, data, fits, nq, timings)
    return fits


def fit_load_candidate(cfg: Config, regs: Regressors, data: meas_mod.ProcessedData, fits: Fits, nq: int,
                       timings: dict[str, float]) -> None:
    """The candidate with load-dependent Coulomb friction (:func:`.friction.fit_load_friction`), nested in
    the configured model's fit, and its WLS and physically consistent fits (``fits.load_candidate``);
    on joint-side (diagonal) actuator columns only, else ``fits.load_note`` says why not."""
    K = regs.reg.gear_matrix
    if not np.allclose(K, np.diag(np.diag(K))):
        fits.load_note = "not fitted: coupled axes (a motor's load is not one joint's torque)"
        return
    t1 = time.perf_counter()
    Wb, y, fit, nm = fits.Wb, fits.y, fits.stribeck, regs.n_used
    try:
        lf = fit_load_friction(Wb, y, data.v_blocks, fits.wls_vc.beta if fit is None else fit.beta, fit,
                               fits.wls_vc.joint_sigma_Nm, regs.reg.coulomb_width_rad_s, offset_mask(regs, nq),
                               fits.max_excess_Nm)
        y_l = y - lf.torque(Wb, data.v_blocks).ravel()
        wls_l = est_mod.wls(Wb, y_l, nm)
        phys_l = est_mod.physical_fit(data.Y, y_l, nq, fits.p_nom, wls_l.joint_sigma_Nm, cfg.regularization,
                                      cfg.physical_max_iter, n_rows=nm)
        fits.load_candidate = LoadCandidate(lf, y_l, wls_l, phys_l)
    except SolverError as exc:   # a candidate only: the others stand
        fits.load_note = f"not fitted: {exc}"
    timings["load_friction_fit_s"] = time.perf_counter() - t1


def offset_mask(regs: Regressors, nq: int) -> np.ndarray:
    """Base parameters that are torque offsets (the last ``nq`` standard parameters): left out of the load."""
    return regs.base.independent >= len(regs.base.standard_names) - nq


def load_to_joints(load: LoadFriction, used: np.ndarray, nq: int) -> LoadFriction:
    """The term of the measured joints ``used`` on all ``nq`` joints (0 on the others)."""
    coef = np.zeros(nq)
    coef[used] = load.coefficient
    return LoadFriction(coef, load.coulomb_width_rad_s)


def validate_on_record(robot: RobotModel, cfg: Config, regs: Regressors, measured: Measured, fits: Fits) -> Validation:
    """The held-out tail of the user's record: a separate fit on the first part (tx40 route); the
    noise sigma from the residuals of the WLS fit on all samples."""
    data, nq, nm = measured.data, robot.nq, regs.n_used
    ho = heldout_validation(data, regs.base, fits.p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                            cfg.physical_max_iter, "identification.data_train_fraction", n_rows=nm)
    pct = round(100 * (1 - cfg.data_train_fraction))
    vt = val_mod.ValidationTrajectory(
        ho.t_s, ho.q, np.empty((0, nq)), np.empty((0, nq)), f"held-out last {pct} % of the user's record",
        f"fit on the first {ho.n_train} of {ho.n_samples} processed samples, scored on the rest")
    tau_v, pred_phys, pred_wls, pred_vc = ho.tau_Nm, ho.pred["physical"], ho.pred["wls"], ho.pred["physical"]
    if fits.stribeck is not None:   # the Stribeck model: its own fit on the first part, scored on the rest
        pred_s = stribeck_heldout(data, regs.base, fits.p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                                  cfg.physical_max_iter, regs.reg.coulomb_width_rad_s,
                                  "identification.data_train_fraction", fits.max_excess_Nm)
        pred_phys, pred_wls = pred_s["physical"], pred_s["wls"]
    pred_l = None
    if fits.load_candidate is not None:
        try:
            pred_l = load_heldout(data, regs.base, fits.p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                                  cfg.physical_max_iter, regs.reg.coulomb_width_rad_s, offset_mask(regs, nq),
                                  fits.stribeck is not None, "identification.data_train_fraction", fits.max_excess_Nm)
        except SolverError as exc:   # not scored: not handed on
            fits.load_note = f"not scored on the held-out tail: {exc}"
    rms_phys, rel_phys = val_mod.torque_rms(tau_v, pred_phys)
    rms_wls, rel_wls = val_mod.torque_rms(tau_v, pred_wls)
    # residual sigma per joint of the WLS fit on all samples (processed torques, like the RMS)
    return Validation(vt, tau_v, pred_phys, pred_wls, pred_vc, rms_phys, rel_phys, rms_wls, rel_wls,
                      np.asarray(fits.wls.joint_sigma_Nm, float), "residuals of the WLS fit (processed torques)",
                      heldout=ho, pred_load=None if pred_l is None else pred_l["physical"],
                      pred_load_wls=None if pred_l is None else pred_l["wls"])


def validate_on_path(ctx: StageContext, cfg: Config, regs: Regressors, measured: Measured, fits: Fits) -> Validation:
    """The run's ISO 9283 path (or a random Fourier trajectory, the report says why) on the hidden
    robot: measured torques against the fits' predictions; noise sigma from the excitation periods."""
    robot, limits, ex, nm = ctx.robot, measured.limits, cfg.excitation, regs.n_used
    assert limits is not None
    control = val_mod.run_control_config(ctx.run)
    try:
        iso = iso_or_derived(robot, control.iso)     # the cube of the report (configured or derived)
    except InfeasibleError:
        iso = control.iso                            # no cube found: the fallback's note says why
    vt = val_mod.validation_trajectory(
        robot, cfg.validation_sample_time_s,
        lambda: val_mod.fourier_validation(robot, limits, ex, cfg.validation_sample_time_s, ctx.rng),
        use_iso=cfg.validation == "iso9283", control=control)
    validation_md = report.validation_markdown(cfg, vt, iso, robot)
    noise_sigma, noise_source = measured.data.noise_sigma_Nm, "spread between excitation periods"
    meas_v = ctx.real.execute_joint_trajectory(vt.t_s, vt.q, vt.v, vt.a, ctx.rng)
    tau_v = meas_v.tau_Nm[:, regs.used]
    Yv = regs.reg.stacked(vt.q, vt.v, vt.a)
    st_v = 0.0 if fits.stribeck is None else fits.stribeck.stribeck_torque(vt.v[:, regs.used])
    pred_phys = (Yv @ fits.phys.p).reshape(-1, nm) + st_v
    pred_wls = (regs.base.base_regressor(Yv) @ fits.wls.beta).reshape(-1, nm) + st_v
    pred_vc = (Yv @ fits.phys_vc.p).reshape(-1, nm)
    pred_l, pred_l_wls = (None, None) if fits.load_candidate is None else load_candidate_predictions(
        regs, fits.load_candidate, Yv, vt.v[:, regs.used], robot.nq)
    rms_phys, rel_phys = val_mod.torque_rms(tau_v, pred_phys)
    rms_wls, rel_wls = val_mod.torque_rms(tau_v, pred_wls)
    if noise_sigma is None or not np.all(np.isfinite(noise_sigma)):
        noise_sigma = np.asarray(meas_v.tau_sigma_Nm, float)[regs.used]
        noise_source = "torque sensor of the simulation"
    return Validation(vt, tau_v, pred_phys, pred_wls, pred_vc, rms_phys, rel_phys, rms_wls, rel_wls,
                      noise_sigma, noise_source, validation_md, pred_load=pred_l, pred_load_wls=pred_l_wls)


def load_candidate_predictions(regs: Regressors, c: LoadCandidate, Y: np.ndarray, v: np.ndarray,
                               nq: int) -> tuple[np.ndarray, np.ndarray]:
    """Torques (N, n_used) the load-dependent candidate's physically consistent and WLS fits predict at
    the standard regressor ``Y`` and the measured joints' velocities ``v``; the load torque of each is
    its own torque without the load term and the offsets (:mod:`.friction`)."""
    nm = regs.n_used
    st = 0.0 if c.fit.stribeck is None else c.fit.stribeck.stribeck_torque(v)
    p_free = c.phys.p.copy()
    p_free[len(p_free) - nq:] = 0.0
    pred = (Y @ c.phys.p).reshape(-1, nm) + st + c.fit.load.torque((Y @ p_free).reshape(-1, nm) + st, v)
    W = regs.base.base_regressor(Y)
    load = load_free_torque(W, c.wls.beta, offset_mask(regs, nq), nm, c.fit.stribeck, v)
    return pred, (W @ c.wls.beta).reshape(-1, nm) + st + c.fit.load.torque(load, v)


def choose_friction_model(robot: RobotModel, regs: Regressors, fits: Fits, val: Validation) -> dict[str, Any]:
    """The friction models' physically consistent fits (viscous + Coulomb, Stribeck, the configured one
    with load-dependent Coulomb friction) scored on the same held-out torques; the best one is handed on
    (``fits`` and ``val`` switched to it). Returns the summary's friction part."""
    friction: dict[str, Any] = {}
    configured = "viscous_coulomb" if fits.stribeck is None else "stribeck"
    scored: dict[str, np.ndarray] = {configured: val.rms_phys}
    if fits.stribeck is not None:
        vc_status = fits.phys_vc.status if val.heldout is None else val.heldout.phys.status   # a record's tail
        scored = ({"viscous_coulomb": val_mod.torque_rms(val.tau_Nm, val.pred_vc)[0]} if is_success(vc_status)
                  else {}) | scored
        friction["friction_viscous_coulomb_status"] = vc_status   # not scored unless IPOPT succeeded
    c, with_load = fits.load_candidate, f"{configured}_load"
    if fits.load_note:
        friction["load_friction_status"] = fits.load_note
    elif c is not None and val.pred_load is not None:
        friction |= load_summary(c.fit.load, c.phys.status, regs.selection.per_joint)
        if is_success(c.phys.status):   # not scored unless IPOPT succeeded
            scored[with_load] = val_mod.torque_rms(val.tau_Nm, val.pred_load)[0]
    best = best_friction_model(scored, val.noise_sigma)     # the held-out data select the handed-on model
    reported = fits.stribeck
    if best == "viscous_coulomb" and fits.stribeck is not None:
        fits.stribeck, fits.phys, val.pred_phys = None, fits.phys_vc, val.pred_vc
        val.rms_phys, val.rel_phys = val_mod.torque_rms(val.tau_Nm, val.pred_phys)
    elif best == with_load and c is not None:
        hand_on_load_candidate(regs, fits, val, c)
        reported = fits.stribeck
    friction = friction_summary(scored, val.noise_sigma, reported, regs.selection.per_joint,
                                robot.limits.effort_Nm[regs.used]) | friction
    friction["friction_model_handed_on"] = ("viscous_coulomb" if fits.stribeck is None else "stribeck") + (
        "" if fits.load is None else "_load")
    if fits.stribeck is None and fits.load is None and fits.wls is not fits.wls_vc:   # the handed-on base estimate
        fits.wls, fits.y_fit, fits.ols = fits.wls_vc, fits.y, est_mod.ols(fits.Wb, fits.y, regs.n_used)
    return friction


def hand_on_load_candidate(regs: Regressors, fits: Fits, val: Validation, c: LoadCandidate) -> None:
    """Switch ``fits`` and ``val`` to the load-dependent candidate (its Stribeck term, if any, refitted with it)."""
    fits.stribeck, fits.load, fits.phys, fits.wls, fits.y_fit = c.fit.stribeck, c.fit, c.phys, c.wls, c.y_fit
    fits.ols = est_mod.ols(fits.Wb, fits.y_fit, regs.n_used)
    if val.pred_load is not None and val.pred_load_wls is not None:
        val.pred_phys, val.pred_wls = val.pred_load, val.pred_load_wls
        val.rms_phys, val.rel_phys = val_mod.torque_rms(val.tau_Nm, val.pred_phys)
        val.rms_wls, val.rel_wls = val_mod.torque_rms(val.tau_Nm, val.pred_wls)


def base_covariance(regs: Regressors, measured: Measured, fits: Fits) -> tuple[est_mod.HacCovariance, np.ndarray]:
    """Correlated residuals: the covariance reported and scored is the HAC sandwich, for a handed-on
    Stribeck term the joint one of the nested fit (base parameters with fs, log vs, and fl of a handed-on
    load-dependent term; its column's load torque taken as given), marginal in beta;
    set on ``fits.wls``. Returns it and the white-residual WLS sigmas it replaced."""
    wls = fits.wls
    white_sigma = wls.sigma
    vb = measured.data.v_blocks
    J = np.hstack([fits.Wb, *([] if fits.stribeck is None else [fits.stribeck.jacobian(vb)]),
                   *([] if fits.load is None else [fits.load.load.jacobian(fits.load.load_Nm, vb)])])
    hac = est_mod.hac_covariance(J, fits.y_fit - fits.Wb @ wls.beta, wls.joint_sigma_Nm, wls.covariance)
    wls.covariance = hac.covariance[: regs.base.n_base, : regs.base.n_base]
    return hac, white_sigma


def tx40_record(robot: RobotModel, cfg: Config, timings: dict[str, float]) -> Tx40Result | None:
    """The Stäubli TX40 record's fit, when wanted (:func:`tx40_wanted`)."""
    if not tx40_wanted(cfg, robot):
        return None
    t1 = time.perf_counter()
    tx = run_tx40(RobotModel.load("staubli_tx40"), cfg.tx40)   # its own fixed seed (tx40.base_seed)
    timings["tx40_s"] = time.perf_counter() - t1
    return tx


__all__ = ["NAME", "DEPENDS", "Config", "ExcitationConfig", "check", "run", "identified_robot"]
