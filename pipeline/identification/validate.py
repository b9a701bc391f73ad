"""Validation of an identified model (paper ``004_abbe750b8bbcc3aa.txt`` §4.3, Fig. 5(b)).

* Torque prediction on a trajectory that was not used for the fit: the EN ISO 9283 path
  (DESIGN.md; built with stage 3's ``iso9283_path`` + ``cartesian_reference`` from the run's
  ``control.iso`` section, robot ``run_defaults`` included) or, when that path is out of reach of
  the robot, a different random Fourier trajectory (the label says which).
  The measured torque (sensor noise included) is compared with the model's prediction at the
  commanded states: per joint RMS error and relative error ``RMS / RMS(measured)``.
* In simulation, each base parameter's error against the truth in units of its estimated
  standard deviation, ``z_k = (beta_hat_k - beta_true_k) / sigma_k`` (tests only, or
  :func:`truth_scores` when the stage is explicitly allowed to score against the truth).

The stage's step 6 (:mod:`pipeline.identification.stage`): :func:`validate_on_path` (the hidden
robot on the run's ISO path) or :func:`validate_on_record` (the held-out tail of the user's record,
fitted on its first part), and :func:`choose_friction_model`: the friction model whose physically
consistent fit predicts the validation torques best is handed on.

**An arm in closed loop whose dry friction sticks** (the hidden robot says so: ``torques_in_closed_loop``,
``dry_friction_sticks``; the own simulator's arm tracks ideally and its friction is smooth, so neither
applies to it). Its torque readings are its drives' commands: they carry the servo's reaction to the
encoder noise, which depends on the gains and the inertia along the path, so the excitation's noise
sigma is not the validation path's. The path is run twice and the noise sigma is the spread between the
two runs, ``sigma_j = std(tau_1 - tau_2) / sqrt(2)`` (the same principle as the spread between
excitation periods). Where a joint's commanded speed, or its own speed read from its encoders (central
differences of the readings), is below ``v_s = STICTION_BAND_OVER_WIDTH * w`` (``w`` the model's Coulomb
smoothing width) the joint is held by its dry friction or breaking away (a joint whose drive commands less
than its breakaway torque stays held after its commanded speed has left the band, until the servo's
error has built the rest of the torque): its
torque is what the drive commands within the friction band, not a function of the state that any
smooth friction model predicts, and below ``2 w`` the model's ``tanh(v / w)`` is under 96 % of its level,
a smoothing of the sign rather than a friction law. Those samples are left out of the validation RMS
(as velocity thresholds in Gautier & Khalil's and Swevers et al.'s identification practice), and the
excitation's samples in the band out of the fits (:func:`.measure.without_stiction_band`). A joint
with none left (at rest on the whole path) is scored by the Coulomb law at rest, any friction torque in
``[-F_c, F_c]``: the RMS of its residual's excess over the identified Coulomb level
(:func:`score_stiction_band`). The summary states ``v_s``, the fraction scored per joint and, for the
held samples, the fraction whose residual lies within the identified Coulomb level plus three sigma.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pipeline.control.config import ControlConfig
from pipeline.core.errors import InfeasibleError, PipelineError, SolverError
from pipeline.core.solver_status import is_success
from pipeline.identification import estimate as est_mod
from pipeline.identification import fourier
from pipeline.identification.config import Config, ExcitationConfig
from pipeline.identification.fit import offset_mask
from pipeline.identification.friction import (
    best_friction_model,
    friction_summary,
    load_free_torque,
    load_heldout,
    load_summary,
    stribeck_heldout,
)
from pipeline.identification.friction_terms import FrictionTerms, record_scores
from pipeline.identification.measure import in_stiction_band, stiction_band_speed
from pipeline.identification.outcome import Fits, LoadCandidate, Measured, Regressors, Validation, ValidationTrajectory
from pipeline.identification.regressor import BaseParameters
from pipeline.identification.tx40 import heldout_validation
from pipeline.robot.defaults import ik_seeds_or_derived_rad, iso_or_derived, iso_rotation
from pipeline.robot.iso9283 import IsoPathConfig, iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import cartesian_reference
from pipeline.stage_api import StageContext


def run_control_config(run: object) -> ControlConfig:
    """The run's validated ``control`` section (robot ``run_defaults`` merged in; read through the
    stage's ``CONFIG_READS``), or the built-in ``ControlConfig()`` when the run has none (a plain
    dict: module missing, or a bare RunConfig)."""
    sections = getattr(run, "sections", None) if run is not None else None
    control = sections.get("control") if isinstance(sections, dict) else None
    return control if isinstance(control, ControlConfig) else ControlConfig()


def run_iso_config(run: object) -> IsoPathConfig:
    """The EN ISO 9283 path settings of the run (``control.iso``, :func:`run_control_config`)."""
    return run_control_config(run).iso


def ik_seeds_rad(control: ControlConfig | None, robot: RobotModel) -> np.ndarray:
    """The run's ``control.ik_seeds_deg`` as (k, nq) rad; none given -> seeds derived from the
    robot (:func:`pipeline.robot.defaults.ik_seeds_or_derived_rad`). A seed of the wrong length
    raises :class:`PipelineError` naming the field."""
    nq = robot.nq
    seeds = getattr(control, "ik_seeds_deg", None)
    if seeds is None or len(seeds) == 0:
        return ik_seeds_or_derived_rad(robot, None)
    arr = [np.asarray(s, float).ravel() for s in seeds]
    bad = [i for i, s in enumerate(arr) if s.size != nq]
    if bad:
        raise PipelineError(None, f"control.ik_seeds_deg[{bad[0]}]",
                            f"{arr[bad[0]].size} values, the robot has {nq} joints")
    return np.radians(np.vstack(arr))


def iso_validation_trajectory(robot: RobotModel, sample_time_s: float,
                             control: ControlConfig | None = None) -> ValidationTrajectory:
    """The ISO 9283 path of the run's ``control.iso`` as joint reference of the control stage's path
    frame (``control.path_frame``: the tracker's reflector or the TCP), started by IK
    from the run's ``control.ik_seeds_deg`` with its ``control.ik_tolerance_m`` (``control`` from
    :func:`run_control_config`; None: the built-in control defaults)."""
    cfg = ControlConfig() if control is None else control
    iso = iso_or_derived(robot, cfg.iso)
    rotation = iso_rotation(robot, iso.plane, iso.tool_orientation)
    path = iso9283_path(robot, iso.edge_m, iso.centre_m, iso.plane, rotation, iso.corner_fraction,
                        iso.large_circle_fraction, iso.small_circle_fraction, tuple(iso.segments))
    seeds = ik_seeds_rad(cfg, robot)
    frame = robot.frame_reflector if cfg.path_frame == "reflector" else robot.frame_tcp   # as the control stage
    q_start = start_configuration(robot, path.poses([0.0])[0], seeds, frame)
    ref = cartesian_reference(robot, path, sample_time_s, iso.speed_m_s, iso.acceleration_m_s2,
                              iso.jerk_m_s3, q_start, frame, cfg.ik_tolerance_m)
    return ValidationTrajectory(ref.t_s, ref.q_d, ref.v_d, ref.a_d, "iso9283",
                                f"edge {iso.edge_m} m, centre {list(iso.centre_m)} m, {iso.speed_m_s} m/s")


def fourier_validation(robot: RobotModel, limits: fourier.ExcitationLimits, ex: ExcitationConfig,
                       sample_time_s: float, rng: np.random.Generator) -> ValidationTrajectory:
    """One period of a random feasible Fourier trajectory (the fallback when the ISO path cannot be used)."""
    tr = fourier.random_feasible_trajectories(robot, limits, ex.harmonics, ex.base_frequency_hz, 1, rng)[0]
    t = np.arange(int(round(tr.period_s / sample_time_s))) * sample_time_s
    q, v, a = tr.evaluate(t)
    return ValidationTrajectory(t, q, v, a, "fourier", "a random feasible Fourier trajectory")


def validation_trajectory(
    robot: RobotModel, sample_time_s: float, fallback: Callable[[], ValidationTrajectory], use_iso: bool = True,
    control: ControlConfig | None = None,
) -> ValidationTrajectory:
    """ISO 9283 path of the run's control section (None: built-in defaults) if it can be built for
    ``robot`` (within limits), else ``fallback()`` with ``note`` saying the real reason."""
    note = ""
    if use_iso:
        try:
            vt = iso_validation_trajectory(robot, sample_time_s, control)
            lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
            out_q = np.flatnonzero(np.any((vt.q < lo) | (vt.q > hi), axis=0))
            out_v = np.flatnonzero(np.any(np.abs(vt.v) > robot.limits.velocity_rad_s * 1.0001, axis=0))
            if not out_q.size and not out_v.size:
                return vt
            note = "the ISO 9283 path from the IK seeds of control.ik_seeds_deg leaves " + "; ".join(
                [f"the position limits of joint(s) {', '.join(str(j + 1) for j in out_q)}"] * bool(out_q.size)
                + [f"the velocity limits of joint(s) {', '.join(str(j + 1) for j in out_v)}"] * bool(out_v.size))
        except (PipelineError, ImportError) as exc:
            note = f"ISO 9283 path unavailable: {exc}"
    vt = fallback()
    vt.note = (note + "; " if note else "") + vt.note
    return vt


def outside_stiction_band(t_s: np.ndarray, v_commanded_rad_s: np.ndarray, q_read_rad: np.ndarray,
                          coulomb_width_rad_s: float) -> np.ndarray:
    """(N, n) bool: the samples a stiction-band validation scores, those where neither the commanded speed
    nor the joint's own speed (central differences of its encoder readings ``q_read_rad`` at ``t_s``) is in
    the band ``|v| < v_s`` (:func:`.measure.in_stiction_band`; module docstring)."""
    v_read = np.gradient(np.asarray(q_read_rad, float), np.asarray(t_s, float), axis=0)
    return ~(in_stiction_band(v_commanded_rad_s, coulomb_width_rad_s) | in_stiction_band(v_read, coulomb_width_rad_s))


def torque_rms(measured: np.ndarray, predicted: np.ndarray,
               scored: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per joint RMS error and relative error ``RMS(err) / RMS(measured)``; ``scored`` (N, n) bool:
    the samples each joint's RMS counts (None: all; a joint with none: NaN)."""
    measured, err = np.asarray(measured, float), np.asarray(measured, float) - np.asarray(predicted, float)
    if scored is None:
        rms = np.sqrt(np.mean(err**2, axis=0))
        rel = rms / np.maximum(np.sqrt(np.mean(measured**2, axis=0)), 1e-12)
        return rms, rel
    n = np.sum(scored, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.where(n > 0, np.sqrt(np.sum(np.where(scored, err**2, 0.0), axis=0) / n), np.nan)
        ms = np.where(n > 0, np.sum(np.where(scored, measured**2, 0.0), axis=0) / n, np.nan)
    return rms, rms / np.maximum(np.sqrt(ms), 1e-12)


def score_stiction_band(val: Validation, fits: Fits, regs: Regressors) -> dict[str, Any]:
    """A stiction-band validation's last step ({} and nothing done otherwise), with the handed-on fit:
    a joint with no sample outside the band (at rest on the whole path) is scored by the Coulomb law at
    rest, any friction torque in ``[-F_c, F_c]``: its RMS is that of the residual's excess over the
    identified ``|F_c|``, ``max(|tau - tau_hat| - |F_c|, 0)`` (physical and WLS fits alike). Returns the
    summary entries: ``v_s``, the fraction of samples scored per joint, and per joint the fraction of its
    held samples whose residual lies within ``|F_c|`` plus three noise sigmas (None: no held sample)."""
    scored = val.scored
    if scored is None:
        return {}
    nq, nm = regs.reg.nv, regs.n_used
    coulomb = np.abs(fits.phys.p[len(fits.phys.p) - 2 * nq: len(fits.phys.p) - nq])[regs.used]
    sigma = np.zeros(nm) if val.noise_sigma is None else np.asarray(val.noise_sigma, float)
    residual = val.tau_Nm - val.pred_phys
    held = ~scored
    inside = np.abs(residual) <= coulomb + 3.0 * sigma
    within = [float(np.mean(inside[held[:, j], j])) if held[:, j].any() else float("nan") for j in range(nm)]
    at_rest = ~np.any(scored, axis=0)
    if np.any(at_rest):
        measured_rms = np.maximum(np.sqrt(np.mean(val.tau_Nm**2, axis=0)), 1e-12)
        for rms, rel, pred in ((val.rms_phys, val.rel_phys, val.pred_phys), (val.rms_wls, val.rel_wls, val.pred_wls)):
            excess = np.maximum(np.abs(val.tau_Nm - pred) - coulomb, 0.0)
            rms[at_rest] = np.sqrt(np.mean(excess**2, axis=0))[at_rest]
            rel[at_rest] = rms[at_rest] / measured_rms[at_rest]
    pj = regs.selection.per_joint
    return {"validation_stiction_band_rad_s": val.min_speed_rad_s,
            "validation_fraction_scored": pj(np.mean(scored, axis=0)),
            "validation_held_within_coulomb_band": pj(np.asarray(within))}


def z_scores(beta: np.ndarray, sigma: np.ndarray, beta_true: np.ndarray) -> np.ndarray:
    return (np.asarray(beta) - np.asarray(beta_true)) / np.maximum(np.asarray(sigma), 1e-300)


def fraction_within(z: np.ndarray, k: float = 3.0) -> float:
    return float(np.mean(np.abs(z) <= k))


def truth_scores(real: Any,  # Any: the simulated hidden robot (its true parameters)
                  base: BaseParameters, beta: np.ndarray, sigma: np.ndarray) -> dict:
    """Score the base estimate against the hidden robot (evaluation only: call it after the
    estimate is final; the stage does so only with ``score_against_truth``)."""
    p_true = np.asarray(real.dynamic_parameters, float)
    beta_true = base.from_standard(p_true)
    z = z_scores(beta, sigma, beta_true)
    return {
        "beta_true": beta_true,
        "z": z,
        "fraction_within_3sigma": fraction_within(z, 3.0),
        "max_abs_z": float(np.max(np.abs(z))),
    }


# ------------------------------------------------------------ the stage's steps (6, and the choice of model)
def validate_on_record(robot: RobotModel, cfg: Config, regs: Regressors, measured: Measured, fits: Fits) -> Validation:
    """The held-out tail of the user's record: a separate fit on the first part (tx40 route); the
    noise sigma from the residuals of the WLS fit on all samples."""
    data, nq, nm = measured.validation_data(cfg.data_train_fraction), robot.nq, regs.n_used
    ho = heldout_validation(data, regs.base, fits.p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                            cfg.physical_max_iter, "identification.data_train_fraction", n_rows=nm)
    pct = round(100 * (1 - cfg.data_train_fraction))
    vt = ValidationTrajectory(
        ho.t_s, ho.q, np.empty((0, nq)), np.empty((0, nq)), f"held-out last {pct} % of the user's record",
        f"fit on the first {ho.n_train} of {ho.n_samples} processed samples, scored on the rest")
    tau_v, pred_phys, pred_wls, pred_vc = ho.tau_Nm, ho.pred["physical"], ho.pred["wls"], ho.pred["physical"]
    if fits.stribeck is not None:   # the Stribeck model: its own fit on the first part, scored on the rest
        pred_s = stribeck_heldout(data, regs.base, fits.p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                                  cfg.physical_max_iter, regs.reg.row_coulomb_width_rad_s,
                                  "identification.data_train_fraction", fits.max_excess_Nm)
        pred_phys, pred_wls = pred_s["physical"], pred_s["wls"]
    pred_l = None
    if fits.load_candidate is not None:
        try:
            pred_l = load_heldout(data, regs.base, fits.p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                                  cfg.physical_max_iter, regs.reg.row_coulomb_width_rad_s, offset_mask(regs, nq),
                                  fits.stribeck is not None, "identification.data_train_fraction", fits.max_excess_Nm)
        except SolverError as exc:   # not scored: not handed on
            fits.load_note = f"not scored on the held-out tail: {exc}"
    pred_lv = None
    if fits.load_candidate_vc is not None:
        try:
            pred_lv = load_heldout(data, regs.base, fits.p_nom, nq, cfg.data_train_fraction, cfg.regularization,
                                   cfg.physical_max_iter, regs.reg.row_coulomb_width_rad_s, offset_mask(regs, nq),
                                   False, "identification.data_train_fraction", fits.max_excess_Nm)
        except SolverError:          # not scored: not handed on
            fits.load_candidate_vc = None
    rms_phys, rel_phys = torque_rms(tau_v, pred_phys)
    rms_wls, rel_wls = torque_rms(tau_v, pred_wls)
    # residual sigma per joint of the WLS fit on all samples (processed torques, like the RMS)
    return Validation(vt, tau_v, pred_phys, pred_wls, pred_vc, rms_phys, rel_phys, rms_wls, rel_wls,
                      np.asarray(fits.wls.joint_sigma_Nm, float), "residuals of the WLS fit (processed torques)",
                      heldout=ho, pred_load=None if pred_l is None else pred_l["physical"],
                      pred_load_wls=None if pred_l is None else pred_l["wls"],
                      pred_load_vc=None if pred_lv is None else pred_lv["physical"],
                      pred_load_vc_wls=None if pred_lv is None else pred_lv["wls"])


def validate_on_path(ctx: StageContext, cfg: Config, regs: Regressors, measured: Measured, fits: Fits) -> Validation:
    """The run's ISO 9283 path (or a random Fourier trajectory, the report says why) on the hidden
    robot: measured torques against the fits' predictions; noise sigma from the excitation periods."""
    robot, real, limits, ex, nm = ctx.robot, ctx.real, measured.limits, cfg.excitation, regs.n_used
    assert limits is not None and real is not None     # a simulated experiment: its excitation, the hidden robot
    control = run_control_config(ctx.run)
    try:
        iso = iso_or_derived(robot, control.iso)     # the cube of the report (configured or derived)
    except InfeasibleError:
        iso = control.iso                            # no cube found: the fallback's note says why
    vt = validation_trajectory(
        robot, cfg.validation_sample_time_s,
        lambda: fourier_validation(robot, limits, ex, cfg.validation_sample_time_s, ctx.rng),
        use_iso=cfg.validation == "iso9283", control=control)
    noise_sigma, noise_source = measured.data.noise_sigma_Nm, "spread between excitation periods"
    meas_v = real.execute_joint_trajectory(vt.t_s, vt.q, vt.v, vt.a, ctx.rng)
    tau_v = meas_v.tau_Nm[:, regs.used]
    if real.torques_in_closed_loop:   # the path's own noise: a second run (module docstring)
        tau_2 = real.execute_joint_trajectory(vt.t_s, vt.q, vt.v, vt.a, ctx.rng).tau_Nm[:, regs.used]
        noise_sigma = np.std(tau_v - tau_2, axis=0) / np.sqrt(2.0)
        noise_source = "spread between two runs of the validation path (the drives' torques in closed loop)"
    scored, v_s = None, 0.0
    if real.dry_friction_sticks:
        width = float(np.max(regs.reg.row_coulomb_width_rad_s))   # a simulated experiment: robot.yaml's widest
        v_s = stiction_band_speed(width)
        scored = outside_stiction_band(vt.t_s, vt.v[:, regs.used], meas_v.q_rad[:, regs.used], width)
    Yv = regs.reg.stacked(vt.q, vt.v, vt.a)
    st_v = 0.0 if fits.stribeck is None else fits.stribeck.stribeck_torque(vt.v[:, regs.used])
    pred_phys = (Yv @ fits.phys.p).reshape(-1, nm) + st_v
    pred_wls = (regs.base.base_regressor(Yv) @ fits.wls.beta).reshape(-1, nm) + st_v
    pred_vc = (Yv @ fits.phys_vc.p).reshape(-1, nm)
    pred_l, pred_l_wls = (None, None) if fits.load_candidate is None else load_candidate_predictions(
        regs, fits.load_candidate, Yv, vt.v[:, regs.used], robot.nq)
    rms_phys, rel_phys = torque_rms(tau_v, pred_phys, scored)
    rms_wls, rel_wls = torque_rms(tau_v, pred_wls, scored)
    if noise_sigma is None or not np.all(np.isfinite(noise_sigma)):
        noise_sigma = np.asarray(meas_v.tau_sigma_Nm, float)[regs.used]
        noise_source = "torque sensor of the simulation"
    return Validation(vt, tau_v, pred_phys, pred_wls, pred_vc, rms_phys, rel_phys, rms_wls, rel_wls,
                      noise_sigma, noise_source, iso, pred_load=pred_l, pred_load_wls=pred_l_wls,
                      scored=scored, min_speed_rad_s=v_s)


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
    mask = val.scored
    configured = "viscous_coulomb" if fits.stribeck is None else "stribeck"
    scored: dict[str, np.ndarray] = {configured: val.rms_phys}
    if fits.stribeck is not None:
        vc_status = fits.phys_vc.status if val.heldout is None else val.heldout.phys.status   # a record's tail
        scored = ({"viscous_coulomb": torque_rms(val.tau_Nm, val.pred_vc, mask)[0]} if is_success(vc_status)
                  else {}) | scored
        friction["friction_viscous_coulomb_status"] = vc_status   # not scored unless IPOPT succeeded
    c, with_load = fits.load_candidate, f"{configured}_load"
    if fits.load_note:
        friction["load_friction_status"] = fits.load_note
    elif c is not None and val.pred_load is not None:
        friction |= load_summary(c.fit.load, c.phys.status, regs.selection.per_joint)
        if is_success(c.phys.status):   # not scored unless IPOPT succeeded
            scored[with_load] = torque_rms(val.tau_Nm, val.pred_load, mask)[0]
    c_vc = fits.load_candidate_vc
    if c_vc is not None and val.pred_load_vc is not None and is_success(c_vc.phys.status):
        scored["viscous_coulomb_load"] = torque_rms(val.tau_Nm, val.pred_load_vc, mask)[0]
    best = best_friction_model(scored, val.noise_sigma)     # the held-out data select the handed-on model
    reported = fits.stribeck
    if best == "viscous_coulomb" and fits.stribeck is not None:
        fits.stribeck, fits.phys, val.pred_phys = None, fits.phys_vc, val.pred_vc
        val.rms_phys, val.rel_phys = torque_rms(val.tau_Nm, val.pred_phys, mask)
    elif best == with_load and c is not None:
        hand_on_load_candidate(regs, fits, val, c, val.pred_load, val.pred_load_wls)
        reported = fits.stribeck
    elif best == "viscous_coulomb_load" and c_vc is not None:
        friction |= load_summary(c_vc.fit.load, c_vc.phys.status, regs.selection.per_joint)
        hand_on_load_candidate(regs, fits, val, c_vc, val.pred_load_vc, val.pred_load_vc_wls)
        reported = fits.stribeck
    friction = friction_summary(scored, val.noise_sigma, reported, regs.selection.per_joint,
                                robot.limits.effort_Nm[regs.used]) | friction
    friction["friction_model_handed_on"] = ("viscous_coulomb" if fits.stribeck is None else "stribeck") + (
        "" if fits.load is None else "_load")
    if fits.stribeck is None and fits.load is None and fits.wls is not fits.wls_vc:   # the handed-on base estimate
        fits.wls, fits.y_fit, fits.ols = fits.wls_vc, fits.y, est_mod.ols(fits.Wb, fits.y, regs.n_used)
    return friction | score_stiction_band(val, fits, regs)


def hand_on_load_candidate(regs: Regressors, fits: Fits, val: Validation, c: LoadCandidate,
                           pred_phys: np.ndarray | None, pred_wls: np.ndarray | None) -> None:
    """Switch ``fits`` and ``val`` to the load-dependent candidate ``c`` (its Stribeck term, if any, refitted
    with it) and its held-out predictions ``pred_phys``, ``pred_wls`` (physical and WLS fits)."""
    fits.stribeck, fits.load, fits.phys, fits.wls, fits.y_fit = c.fit.stribeck, c.fit, c.phys, c.wls, c.y_fit
    fits.ols = est_mod.ols(fits.Wb, fits.y_fit, regs.n_used)
    if pred_phys is not None and pred_wls is not None:
        val.pred_phys, val.pred_wls = pred_phys, pred_wls
        mask = val.scored
        val.rms_phys, val.rel_phys = torque_rms(val.tau_Nm, val.pred_phys, mask)
        val.rms_wls, val.rel_wls = torque_rms(val.tau_Nm, val.pred_wls, mask)


def scored_against_truth(ctx: StageContext, cfg: Config, regs: Regressors, fits: Fits) -> dict[str, Any] | None:
    """The final base estimate scored against the hidden robot (:func:`truth_scores`): only for a
    simulated experiment with ``score_against_truth``, else None."""
    if not cfg.score_against_truth or regs.record is not None or ctx.real is None:
        return None
    return truth_scores(ctx.real, regs.base, fits.wls.beta, fits.wls.sigma)


def record_term_scores(cfg: Config, regs: Regressors, measured: Measured, fits: Fits, val: Validation,
                       terms: FrictionTerms | None) -> dict[str, Any]:
    """A user's record: the summary entries of its terms taken off before the fits and the model-class
    check on the handed-on fit's residual (:func:`.friction_terms.record_scores`); {} without terms."""
    if terms is None or regs.record is None:
        return {}
    return record_scores(terms, val, fits.wls.residual_Nm, regs.record.sample_time_s, cfg.data_cutoff_hz,
                         cfg.data_decimation, measured.data, regs.selection.per_joint, regs.used + 1)
