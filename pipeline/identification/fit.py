"""The fits on all samples, step 5 of :mod:`pipeline.identification.stage` (paper
``004_abbe750b8bbcc3aa.txt`` §4.2), and the model they hand on.

* :func:`fit_models`: OLS, Gautier's WLS ``beta = (W^T S^-1 W)^-1 W^T S^-1 y`` (``S``: per-joint
  residual variances) and the physically consistent fit (log-Cholesky, IPOPT; :mod:`.estimate`);
  with ``friction_model: stribeck`` the Stribeck term first (:func:`.friction.fit_stribeck`, nested
  in the viscous + Coulomb fit) and taken off the torques, the viscous + Coulomb fits kept beside
  it; the candidate with load-dependent Coulomb friction (:func:`fit_load_candidate`). The
  validation torques choose among them (:func:`pipeline.identification.validate.choose_friction_model`).
* :func:`base_covariance`: the HAC sandwich of the handed-on fit (:func:`.estimate.hac_covariance`).

The robot these fits hand on: :mod:`.handed_on`.
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.core.errors import SolverError
from pipeline.identification import estimate as est_mod
from pipeline.identification import measure as meas_mod
from pipeline.identification.config import Config
from pipeline.identification.friction import (
    MAX_EXCESS_OVER_LIMIT,
    StribeckFit,
    fit_load_friction,
    fit_stribeck,
)
from pipeline.identification.gates import check_data_excites
from pipeline.identification.outcome import Fits, LoadCandidate, Measured, Regressors
from pipeline.identification.regressor import standard_parameters
from pipeline.robot.assumed_values import predicted_drive_values
from pipeline.robot.model import RobotModel


def fit_models(robot: RobotModel, cfg: Config, regs: Regressors, measured: Measured, timings: dict[str, float]) -> Fits:
    """OLS, Gautier's WLS and the physically consistent fit on all samples; with ``friction_model:
    stribeck`` the Stribeck term first (nested in the viscous + Coulomb fit), taken off the torques,
    and the viscous + Coulomb fits beside it (the validation torques choose,
    :func:`pipeline.identification.validate.choose_friction_model`). The data must excite the model
    (:func:`.gates.check_data_excites`)."""
    t1 = time.perf_counter()
    data, base, nm = measured.fit_data, regs.base, regs.n_used
    Wb, y = base.base_regressor(data.Y), data.y
    cond_data = check_data_excites(data.q[:, regs.used], Wb, [f"q{j + 1}" for j in regs.used],
                                   cfg.min_joint_motion_rad, cfg.max_cond_base_regressor_data,
                                   str(cfg.data_file) if cfg.data_file else None)
    cond_data_structural = float(np.linalg.cond(regs.base_design.base_regressor(data.Y)))  # design criterion's set
    wls_vc = est_mod.wls(Wb, y, nm)
    max_excess = MAX_EXCESS_OVER_LIMIT * robot.limits.effort_Nm[regs.used]
    fit = (fit_stribeck(Wb, y, data.v_blocks, wls_vc.beta, wls_vc.joint_sigma_Nm, regs.reg.row_coulomb_width_rad_s,
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
    the configured model's fit, and its WLS and physically consistent fits (``fits.load_candidate``); for a
    record fitted with the Stribeck term also nested in the viscous + Coulomb fit (``fits.load_candidate_vc``:
    a Stribeck fit that extrapolates badly on one joint must not keep the load term from the others); on
    joint-side (diagonal) actuator columns only, else ``fits.load_note`` says why not."""
    K = regs.reg.gear_matrix
    if not np.allclose(K, np.diag(np.diag(K))):
        fits.load_note = "not fitted: coupled axes (a motor's load is not one joint's torque)"
        return
    t1 = time.perf_counter()
    try:
        fits.load_candidate = _load_candidate(cfg, regs, data, fits, nq, fits.stribeck)
    except SolverError as exc:   # a candidate only: the others stand
        fits.load_note = f"not fitted: {exc}"
    if fits.stribeck is not None and regs.record is not None:
        try:
            fits.load_candidate_vc = _load_candidate(cfg, regs, data, fits, nq, None)
        except SolverError:      # a candidate only
            fits.load_candidate_vc = None
    timings["load_friction_fit_s"] = time.perf_counter() - t1


def _load_candidate(cfg: Config, regs: Regressors, data: meas_mod.ProcessedData, fits: Fits, nq: int,
                    stribeck: StribeckFit | None) -> LoadCandidate:
    """The load-dependent candidate nested in the fit with the Stribeck term ``stribeck`` (None: viscous +
    Coulomb) and its WLS and physically consistent fits; raises :class:`SolverError`."""
    Wb, y, nm = fits.Wb, fits.y, regs.n_used
    lf = fit_load_friction(Wb, y, data.v_blocks, fits.wls_vc.beta if stribeck is None else stribeck.beta, stribeck,
                           fits.wls_vc.joint_sigma_Nm, regs.reg.row_coulomb_width_rad_s, offset_mask(regs, nq),
                           fits.max_excess_Nm)
    y_l = y - lf.torque(Wb, data.v_blocks).ravel()
    wls_l = est_mod.wls(Wb, y_l, nm)
    phys_l = est_mod.physical_fit(data.Y, y_l, nq, fits.p_nom, wls_l.joint_sigma_Nm, cfg.regularization,
                                  cfg.physical_max_iter, n_rows=nm)
    return LoadCandidate(lf, y_l, wls_l, phys_l)


def offset_mask(regs: Regressors, nq: int) -> np.ndarray:
    """Base parameters that are torque offsets (the last ``nq`` standard parameters): left out of the load."""
    return regs.base.independent >= len(regs.base.standard_names) - nq


def base_covariance(regs: Regressors, measured: Measured, fits: Fits) -> tuple[est_mod.HacCovariance, np.ndarray]:
    """Correlated residuals: the covariance reported and scored is the HAC sandwich, for a handed-on
    Stribeck term the joint one of the nested fit (base parameters with fs, log vs, and fl of a handed-on
    load-dependent term; its column's load torque taken as given), marginal in beta;
    set on ``fits.wls``. Returns it and the white-residual WLS sigmas it replaced."""
    wls = fits.wls
    white_sigma = wls.sigma
    vb = measured.fit_data.v_blocks
    J = np.hstack([fits.Wb, *([] if fits.stribeck is None else [fits.stribeck.jacobian(vb)]),
                   *([] if fits.load is None else [fits.load.load.jacobian(fits.load.load_Nm, vb)])])
    hac = est_mod.hac_covariance(J, fits.y_fit - fits.Wb @ wls.beta, wls.joint_sigma_Nm, wls.covariance)
    wls.covariance = hac.covariance[: regs.base.n_base, : regs.base.n_base]
    return hac, white_sigma
