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
   viscous + Coulomb fit is kept beside it, both are scored on the validation torques and the
   better one is handed on. Base-parameter sigmas: HAC sandwich (:func:`.estimate.hac_covariance`).
6. Validation on the run's ISO 9283 path (``control.iso`` from the run's ``control.ik_seeds_deg``,
   measured vs predicted torques; a random Fourier trajectory, with the real reason in the report,
   when that path cannot be used), or the held-out tail of a record.
7. The TX40 record, only for the TX40 or when asked (:func:`tx40_wanted`): base parameters,
   condition number, held-out RMS (:mod:`.tx40`).
8. Quality gates (:func:`.gates.add_result_gates`): condition number vs design, validation RMS vs
   noise, predicted torques vs limits -> :class:`~pipeline.errors.QualityGateError` unless
   ``--accept-poor``.
"""

from __future__ import annotations

import copy
import time
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from pipeline.blas import single_thread_blas
from pipeline.config import resolve_robot_dir
from pipeline.errors import ConfigError, InfeasibleError, PipelineError
from pipeline.identification import design as design_mod
from pipeline.identification import estimate as est_mod
from pipeline.identification import fourier, report
from pipeline.identification import measure as meas_mod
from pipeline.identification import validate as val_mod
from pipeline.identification.base_set import structural_base_parameters
from pipeline.identification.config import DATA_BORDER_SAMPLES, Config, ExcitationConfig
from pipeline.identification.friction import (
    MAX_EXCESS_OVER_LIMIT,
    StribeckFit,
    expand_to_joints,
    fit_stribeck,
    friction_summary,
    stribeck_heldout,
)
from pipeline.identification.gates import add_result_gates, check_data_excites
from pipeline.identification.joints import select_joints
from pipeline.identification.record import load_user_record
from pipeline.identification.regressor import RegressorModel, standard_parameters
from pipeline.identification.tx40 import (
    Tx40Result,
    check_tx40_config,
    heldout_validation,
    run_tx40,
)
from pipeline.quality import QualityGates
from pipeline.robot.assumed_values import predicted_drive_values
from pipeline.robot.defaults import iso_or_derived
from pipeline.robot.handoff import JointFriction
from pipeline.robot.iso9283 import IsoPathConfig
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import DynamicLayout, set_dynamic_parameters
from pipeline.robot.symbolic import SymbolicRobot
from pipeline.solver_status import is_success
from pipeline.stage_api import StageContext, StageResult

NAME = "identification"
DEPENDS: tuple[str, ...] = ("model", "calibration")
#: fields naming files: the inputs hash covers their content, not their path
FILE_INPUTS: tuple[str, ...] = ("data_file",)
#: provenance (pipeline.stage_plan): the field naming a recorded file, else what is simulated
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


def identified_friction(p: np.ndarray, nq: int, stribeck: StribeckFit | None = None) -> JointFriction:
    """The friction handed on: viscous and Coulomb from the standard parameters ``p``, the Stribeck
    term from ``stribeck`` (``friction_model: stribeck``; else none)."""
    layout = DynamicLayout(nq)
    return JointFriction(p[layout.viscous].copy(), p[layout.coulomb].copy(),
                         None if stribeck is None else stribeck.static_excess_Nm.copy(),
                         None if stribeck is None else stribeck.stribeck_velocity_rad_s.copy())


def identified_robot(robot: RobotModel, p: np.ndarray, stribeck: StribeckFit | None = None) -> RobotModel:
    """Copy of ``robot`` with the standard parameters ``p`` (inertias, rotor inertia, viscous and
    Coulomb friction; torque offsets are not part of a RobotModel) and, with a Stribeck fit, its
    static excess and Stribeck velocity (``friction_model: stribeck``; else none)."""
    nq = robot.nq
    model = set_dynamic_parameters(robot.model, p)
    spec = copy.deepcopy(robot.spec)
    off = 10 * (robot.model.njoints - 1)
    spec.actuation.rotor_inertia_kgm2 = p[off : off + nq].copy()
    identified_friction(p, nq, stribeck).apply_to(spec.actuation)
    return robot.with_model(model, spec)


def _fourier_validation(robot: RobotModel, limits: fourier.ExcitationLimits, ex: ExcitationConfig,
                        sample_time_s: float, rng: np.random.Generator) -> val_mod.ValidationTrajectory:
    tr = fourier.random_feasible_trajectories(robot, limits, ex.harmonics, ex.base_frequency_hz, 1, rng)[0]
    t = np.arange(int(round(tr.period_s / sample_time_s))) * sample_time_s
    q, v, a = tr.evaluate(t)
    return val_mod.ValidationTrajectory(t, q, v, a, "fourier", "a random feasible Fourier trajectory")


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
    source = getattr(ctx.run, "source", None)
    cfg.validate(source)
    ex = cfg.excitation
    robot = ctx.robot
    nq = robot.nq
    user_data = bool(cfg.data_file)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if not user_data and ctx.real is None:
        raise PipelineError(None, "identification", "no hidden robot to measure and no data_file given")

    act = robot.actuation
    # a record's torques are motor-side through the gear matrix, unless measured on the link side
    coupled = cfg.actuator_coupling == "gear" or (cfg.actuator_coupling == "auto" and user_data
                                                  and act.torque_side == "motor")
    K = act.gear_matrix if coupled else np.eye(nq)
    rec = load_user_record(cfg, robot) if user_data else None  # before any long computation
    # joints whose torques the fit uses: the named ones, else those whose column carries a signal
    sel = select_joints(cfg.joints, [str(n) for n in robot.model.names[1:]], {} if rec is None else rec.unmeasured)
    used, rows = sel.used, None if sel.all_used else sel.used
    nm = len(used)
    reg = RegressorModel(robot.model, K, act.coulomb_smoothing_rad_s, rows)
    nominal = _nominal_robot(ctx)
    reg_nominal = RegressorModel(nominal.model, K, act.coulomb_smoothing_rad_s, rows)
    # Structural base set, decided on the nominal model (the design criterion's set); the current
    # (calibrated) model keeps the same set with its own combinations (:mod:`.base_set`)
    base_design, base = structural_base_parameters(reg_nominal, reg, ctx.rng, cfg.base_samples, cfg.base_tolerance,
                                                   robot.limits.lower_rad, robot.limits.upper_rad)
    timings["base_parameters_s"] = time.perf_counter() - t0

    # ---------------------------------------------------------------- excitation and data
    exc: design_mod.ExcitationResult | None = None
    limits = traj = None
    t1 = time.perf_counter()
    if rec is not None:  # the user's record: no excitation to design, nothing simulated
        data = meas_mod.process_record(rec, reg, cfg.data_cutoff_hz, cfg.data_decimation, DATA_BORDER_SAMPLES)
        data_source = str(cfg.data_file)
    else:
        limits = fourier.ExcitationLimits.from_robot(
            robot, ex.position_margin, ex.velocity_margin, ex.acceleration_margin, ex.torque_margin,
            ex.floor_clearance_m, ex.self_clearance_m, ex.max_tcp_speed_m_s, ex.max_tcp_acceleration_m_s2)
        sym = SymbolicRobot(robot)
        exc = design_mod.optimize_excitation(
            robot, sym, reg, base_design, limits, ctx.rng, harmonics=ex.harmonics,
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
        data = meas_mod.process_periodic(sim, reg, n_per, cutoff, cfg.decimation)
        data_source = "simulation (ideal tracking of the hidden robot)"
    timings["data_s"] = time.perf_counter() - t1

    # ---------------------------------------------------------------- estimation (all samples)
    t1 = time.perf_counter()
    Wb = base.base_regressor(data.Y)
    y = data.y
    cond_data = check_data_excites(data.q[:, used], Wb, [f"q{j + 1}" for j in used], cfg.min_joint_motion_rad,
                                   cfg.max_cond_base_regressor_data, str(cfg.data_file) if user_data else None)
    cond_data_structural = float(np.linalg.cond(base_design.base_regressor(data.Y)))  # design criterion's set
    wls_vc = est_mod.wls(Wb, y, nm)
    # friction_model stribeck: fit the Stribeck term with the base parameters (IPOPT), nested in the
    # viscous + Coulomb fit, take it off the torques and fit the rest as before; the held-out data
    # choose which of the two models is handed on
    max_excess = MAX_EXCESS_OVER_LIMIT * robot.limits.effort_Nm[used]
    fit = (fit_stribeck(Wb, y, data.v_blocks, wls_vc.beta, wls_vc.joint_sigma_Nm, reg.coulomb_width_rad_s,
                        max_excess_Nm=max_excess) if cfg.friction_model == "stribeck" else None)
    timings["stribeck_fit_s"] = time.perf_counter() - t1
    y_fit = y if fit is None else y - fit.stribeck_torque(data.v_blocks).ravel()
    ols = est_mod.ols(Wb, y_fit, nm)
    wls = wls_vc if fit is None else est_mod.wls(Wb, y_fit, nm)
    drive = predicted_drive_values(act, robot.spec.assumed)   # assumed or link-side drive values: 0
    p_nom = standard_parameters(robot.model, drive["rotor_inertia_kgm2"], drive["viscous_Nms_rad"],
                                drive["coulomb_Nm"])
    phys = est_mod.physical_fit(data.Y, y_fit, nq, p_nom, wls.joint_sigma_Nm, cfg.regularization,
                                cfg.physical_max_iter, n_rows=nm)
    phys_vc = phys if fit is None else est_mod.physical_fit(data.Y, y, nq, p_nom, wls_vc.joint_sigma_Nm,
                                                            cfg.regularization, cfg.physical_max_iter, n_rows=nm)
    timings["estimation_s"] = time.perf_counter() - t1

    # ---------------------------------------------------------------- validation
    t1 = time.perf_counter()
    if rec is not None:
        # held-out tail of the user's record: a separate fit on the first part (tx40 route)
        ho = heldout_validation(data, base, p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                                cfg.physical_max_iter, "identification.data_train_fraction", n_rows=nm)
        pct = round(100 * (1 - cfg.data_train_fraction))
        vt = val_mod.ValidationTrajectory(
            ho.t_s, ho.q, np.empty((0, nq)), np.empty((0, nq)), f"held-out last {pct} % of the user's record",
            f"fit on the first {ho.n_train} of {ho.n_samples} processed samples, scored on the rest")
        tau_v, pred_phys, pred_wls, pred_vc = ho.tau_Nm, ho.pred["physical"], ho.pred["wls"], ho.pred["physical"]
        if fit is not None:   # the Stribeck model: its own fit on the first part, scored on the rest
            pred_s = stribeck_heldout(data, base, p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                                      cfg.physical_max_iter, reg.coulomb_width_rad_s,
                                      "identification.data_train_fraction", max_excess)
            pred_phys, pred_wls = pred_s["physical"], pred_s["wls"]
        rms_phys, rel_phys = val_mod.torque_rms(tau_v, pred_phys)
        rms_wls, rel_wls = val_mod.torque_rms(tau_v, pred_wls)
        # residual sigma per joint of the WLS fit on all samples (processed torques, like the RMS)
        noise_sigma: np.ndarray | None = np.asarray(wls.joint_sigma_Nm, float)
        noise_source = "residuals of the WLS fit (processed torques)"
        validation_md = ""
    else:
        assert limits is not None
        control = val_mod.run_control_config(ctx.run)
        try:
            iso = iso_or_derived(robot, control.iso)     # the cube of the report (configured or derived)
        except InfeasibleError:
            iso = control.iso                            # no cube found: the fallback's note says why
        vt = val_mod.validation_trajectory(
            robot, cfg.validation_sample_time_s,
            lambda: _fourier_validation(robot, limits, ex, cfg.validation_sample_time_s, ctx.rng),
            use_iso=cfg.validation == "iso9283", control=control)
        validation_md = _validation_markdown(cfg, vt, iso, robot)
        noise_sigma = data.noise_sigma_Nm
        noise_source = "spread between excitation periods"
        meas_v = ctx.real.execute_joint_trajectory(vt.t_s, vt.q, vt.v, vt.a, ctx.rng)
        tau_v = meas_v.tau_Nm[:, used]
        Yv = reg.stacked(vt.q, vt.v, vt.a)
        st_v = 0.0 if fit is None else fit.stribeck_torque(vt.v[:, used])
        pred_phys = (Yv @ phys.p).reshape(-1, nm) + st_v
        pred_wls = (base.base_regressor(Yv) @ wls.beta).reshape(-1, nm) + st_v
        pred_vc = (Yv @ phys_vc.p).reshape(-1, nm)
        rms_phys, rel_phys = val_mod.torque_rms(tau_v, pred_phys)
        rms_wls, rel_wls = val_mod.torque_rms(tau_v, pred_wls)
        if noise_sigma is None or not np.all(np.isfinite(noise_sigma)):
            noise_sigma = np.asarray(meas_v.tau_sigma_Nm, float)[used]
            noise_source = "torque sensor of the simulation"
    friction: dict[str, Any] = {}
    if fit is not None:  # both friction models' physically consistent fits on the same held-out torques
        vc_status = phys_vc.status if rec is None else ho.phys.status
        scored = {"viscous_coulomb": val_mod.torque_rms(tau_v, pred_vc)[0]} if is_success(vc_status) else {}
        friction = friction_summary(scored | {"stribeck": rms_phys}, noise_sigma, fit, sel.per_joint,
                                    robot.limits.effort_Nm[used])
        friction["friction_viscous_coulomb_status"] = vc_status   # not scored unless IPOPT succeeded
        if friction["friction_model_best"] == "viscous_coulomb":   # the held-out data select the handed-on model
            fit, phys, pred_phys = None, phys_vc, pred_vc
            rms_phys, rel_phys = val_mod.torque_rms(tau_v, pred_phys)
    friction["friction_model_handed_on"] = "viscous_coulomb" if fit is None else "stribeck"
    if fit is None and wls is not wls_vc:   # the base estimate of the handed-on friction model
        wls, y_fit, ols = wls_vc, y, est_mod.ols(Wb, y, nm)
    white_sigma = wls.sigma
    # correlated residuals: the covariance reported and scored is the HAC sandwich, for a handed-on
    # Stribeck term the joint one of the nested fit (base parameters with fs, log vs), marginal in beta
    J = Wb if fit is None else np.hstack([Wb, fit.jacobian(data.v_blocks)])
    hac = est_mod.hac_covariance(J, y_fit - Wb @ wls.beta, wls.joint_sigma_Nm, wls.covariance)
    wls.covariance = hac.covariance[: base.n_base, : base.n_base]
    new_robot = identified_robot(robot, phys.p, None if fit is None else expand_to_joints(fit, used, nq))
    timings["validation_s"] = time.perf_counter() - t1

    truth = None
    if cfg.score_against_truth and not user_data and ctx.real is not None:
        truth = val_mod.truth_scores(ctx.real, base, wls.beta, wls.sigma)

    # ---------------------------------------------------------------- TX40 record
    tx: Tx40Result | None = None
    if tx40_wanted(cfg, robot):
        t1 = time.perf_counter()
        tx = run_tx40(RobotModel.load("staubli_tx40"), cfg.tx40)   # its own fixed seed (tx40.base_seed)
        timings["tx40_s"] = time.perf_counter() - t1
    timings["total_s"] = time.perf_counter() - t0

    # ---------------------------------------------------------------- outputs
    ratio = rms_phys / noise_sigma if noise_sigma is not None else np.full(nm, np.nan)
    pj = sel.per_joint
    summary: dict[str, Any] = {
        "n_base_parameters": base.n_base,
        "n_base_parameters_structural": base_design.n_base,
        "excitation": report.excitation_label(exc, ex.criterion),
        "excitation_fallback_reason": None if exc is None else (exc.fallback_reason or None),
        "base_parameter_set": base.set_names,
        "cond_optimized": None if exc is None else exc.cond_optimized,
        "cond_random_median": None if exc is None else exc.cond_random_median,
        "cond_improvement": None if exc is None else exc.cond_random_median / exc.cond_optimized,
        "cond_base_regressor_data": cond_data,
        "cond_base_regressor_data_structural": cond_data_structural,
        "excitation_criterion": None if exc is None else ex.criterion,
        # largest TCP speed / acceleration of the excitation (fine grid, nominal kinematics) and the bounds
        "excitation_tcp_speed_max_m_s": None if exc is None else exc.feasibility.tcp_speed_max_m_s,
        "excitation_tcp_acceleration_max_m_s2": None if exc is None else exc.feasibility.tcp_acceleration_max_m_s2,
        "excitation_tcp_speed_bound_m_s": ex.max_tcp_speed_m_s,
        "excitation_tcp_acceleration_bound_m_s2": ex.max_tcp_acceleration_m_s2,
        "validation_trajectory": vt.label,
        "validation_torque_rms_Nm": pj(rms_phys),
        "validation_relative_error": pj(rel_phys),
        "validation_torque_rms_wls_Nm": pj(rms_wls),
        "torque_noise_sigma_Nm": None if noise_sigma is None else pj(noise_sigma),
        "torque_noise_source": noise_source,
        "validation_rms_over_noise": pj(ratio),
        **sel.to_dict(),
        # a record logged with non-uniform time stamps, resampled (signals.resample_uniform)
        "record_max_gap_s": None if rec is None else rec.max_gap_s,
        "record_resampling": None if rec is None or not rec.resampling else rec.resampling,
        "base_covariance": (f"HAC sandwich (Newey & West 1987), Bartlett kernel, bandwidth {hac.bandwidth:.2f} "
                            "samples (Andrews 1991 AR(1) plug-in)"),
        "base_sigma_hac_over_white_median": float(np.median(wls.sigma / np.maximum(white_sigma, 1e-300))),
        "fraction_within_3sigma": None if truth is None else truth["fraction_within_3sigma"],
        "physically_consistent": bool(phys.consistent),
        "fit_rms_Nm_wls": wls.rms_Nm,
        "data_source": data_source,
        "actuator_coupling": "gear matrix" if coupled else "diagonal (joint side)",
        "n_samples_fit": data.n_samples,
        "friction_model": cfg.friction_model,
        **friction,
        "runtime_s": timings["total_s"],
    }
    if tx is not None:
        summary.update(tx.summary())
    if traj is not None:
        t_rep = np.arange(0.0, traj.period_s, 1.0 / cfg.replay_rate_hz)
        q_rep, _, _ = traj.evaluate(t_rep)
    else:  # the user's (processed: filtered, decimated, borders dropped) trajectory
        t_rep, q_rep = report.replay(np.arange(data.n_samples) * data.sample_time_s, data.q, cfg.replay_rate_hz)
    arrays: dict[str, np.ndarray] = {
        "trajectory_excitation_t": t_rep,
        "trajectory_excitation_q": q_rep,
        "base_beta": wls.beta,
        "base_sigma": wls.sigma,
        "base_beta_ols": ols.beta,
        "base_matrix_E": base.matrix,
        "standard_parameters_physical": phys.p,
        "standard_parameters_nominal": p_nom,
        "validation_t_s": vt.t_s,
        "validation_q": vt.q,
        "validation_tau_measured_Nm": tau_v,
        "validation_tau_predicted_Nm": pred_phys,
    }
    if exc is not None and traj is not None:
        arrays["excitation_coefficients"] = traj.coefficients
        arrays["cond_random"] = np.asarray(exc.cond_random)
    if truth is not None:
        arrays["base_beta_true"] = truth["beta_true"]
        arrays["base_z"] = truth["z"]
    if exc is not None and traj is not None:
        excitation_data: dict[str, Any] = {
            "trajectory": traj.to_dict(),
            "starts": exc.start_results,
            "feasibility": exc.feasibility.to_dict(),
            "cond_starts": exc.cond_starts,
            "cond_history": exc.cond_history,
            **exc.details,
        }
    else:
        excitation_data = {"source": "user record", "file": str(cfg.data_file),
                           "cond_base_regressor": cond_data}
    data_out = {
        "base_parameter_names": base.names,
        "standard_parameter_names": base.standard_names,
        "base_qr_tolerance": base.tolerance,
        "base_rank_gap": base.rank_gap,
        "excitation": excitation_data,
        "estimation": {
            "joint_sigma_Nm_wls": wls.joint_sigma_Nm.tolist(),
            "physical_status": phys.status,
            "physical_iterations": phys.iterations,
            "min_pseudo_inertia_eig": phys.min_pseudo_inertia_eig,
        },
        "validation": {"label": vt.label, "note": vt.note, "rms_wls_Nm": rms_wls.tolist(),
                       "relative_wls": rel_wls.tolist()},
        "timings_s": timings,
    }
    if truth is not None:
        data_out["truth_scores"] = {"max_abs_z": truth["max_abs_z"],
                                    "fraction_within_3sigma": truth["fraction_within_3sigma"]}
    if tx is not None:
        data_out["tx40"] = {
            "heldout_rms_per_joint_Nm": tx.heldout_rms_per_joint_Nm,
            "train_rms_Nm": tx.train_rms_Nm,
            "ols_rotor_inertia_axis6_base": tx.details.get("ols_ia6_base_value"),
            **{k: v for k, v in tx.details.items() if k != "ols_ia6_base_value"},
        }
    figures: dict[str, Figure] = {}
    if exc is not None:
        figures["convergence"] = report.convergence_figure(exc)
    figures["parameters"] = report.parameters_figure(base, wls.beta, wls.sigma, base.from_standard(phys.p),
                                            base.from_standard(p_nom), None if truth is None else truth["z"])
    figures["validation_torques"] = report.torques_figure(vt.t_s, tau_v, pred_phys,
                                                 f"validation on {vt.label}: measured vs identified model")
    if tx is not None:
        figures["tx40_heldout"] = report.torques_figure(
            tx.heldout_t_s, tx.heldout_tau_Nm, tx.heldout_pred_Nm["physical"],
            "TX40 held-out 30 %: measured vs physically consistent fit")
    gates = QualityGates(NAME, accept_poor=bool(getattr(ctx.run, "accept_poor", False)))
    add_result_gates(gates, cfg, cond_data, None if exc is None else exc.cond_optimized, ratio, pred_phys,
                     robot.limits.effort_Nm[used], phys.status, used + 1)
    fallback_md = "" if exc is None or not exc.fallback_reason else (
        f"**Excitation: the best random feasible trajectory is used** ({exc.fallback_reason}).\n\n")
    return gates.finish(StageResult(summary=summary, arrays=arrays, data=data_out, figures=figures, robot=new_robot,
                                    report_md=fallback_md + validation_md + report.report_markdown(summary, tx)))


def _validation_markdown(cfg: Config, vt: val_mod.ValidationTrajectory, iso: IsoPathConfig,
                         robot: RobotModel) -> str:
    """One paragraph for report.md: which trajectory validated the model; a visible warning
    when the EN ISO 9283 path was asked for but could not be used."""
    if vt.label == "iso9283":
        return f"Validation on the EN ISO 9283 path of `control.iso` ({vt.note}).\n\n"
    if cfg.validation != "iso9283":
        return ("Validation on a random feasible Fourier trajectory "
                f"(`identification.validation: {cfg.validation}`).\n\n")
    why = vt.note.split("; ")[0] if vt.note else "not reachable"
    fix = ("Set `control.ik_seeds_deg` to a configuration near the path (or the robot's `run_defaults`)"
           if "ik_seeds" in why or "IK" in why else
           "Set `control.iso.centre_m` and `control.iso.edge_m` (or the robot's `run_defaults`) to a cube inside "
           "its workspace")
    return ("**Warning: validation fell back to a random Fourier trajectory.** The EN ISO 9283 path "
            f"(`control.iso.centre_m` = {None if iso.centre_m is None else list(iso.centre_m)} m, "
            f"`control.iso.edge_m` = {iso.edge_m} m) "
            f"cannot be followed by {robot.name}: {why}. {fix}.\n\n")


__all__ = ["NAME", "DEPENDS", "Config", "ExcitationConfig", "check", "run", "identified_robot"]
