"""The fits on all samples, step 5 of :mod:`pipeline.identification.stage` (paper
``004_abbe750b8bbcc3aa.txt`` §4.2), and the model they hand on.

* :func:`fit_models`: OLS, Gautier's WLS ``beta = (W^T S^-1 W)^-1 W^T S^-1 y`` (``S``: per-joint
  residual variances) and the physically consistent fit (log-Cholesky, IPOPT; :mod:`.estimate`);
  with ``friction_model: stribeck`` the Stribeck term first (:func:`.friction.fit_stribeck`, nested
  in the viscous + Coulomb fit) and taken off the torques, the viscous + Coulomb fits kept beside
  it; the candidate with load-dependent Coulomb friction (:func:`fit_load_candidate`). The
  validation torques choose among them (:func:`pipeline.identification.validate.choose_friction_model`).
* :func:`base_covariance`: the HAC sandwich of the handed-on fit (:func:`.estimate.hac_covariance`).
* :func:`handed_on_robot`: the robot with the handed-on standard parameters and friction terms, and
  robot.yaml's rotor inertia where the record shows none (:func:`unseen_rotor_inertia_joints`).
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
    LoadFriction,
    StribeckFit,
    expand_to_joints,
    fit_load_friction,
    fit_stribeck,
)
from pipeline.identification.gates import check_data_excites
from pipeline.identification.joints import JointSelection
from pipeline.identification.outcome import Fits, LoadCandidate, Measured, Regressors, identified_robot
from pipeline.identification.regressor import standard_parameters
from pipeline.robot.assumed_values import predicted_drive_values, value_digest
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


def load_to_joints(load: LoadFriction, used: np.ndarray, nq: int) -> LoadFriction:
    """The term of the measured joints ``used`` on all ``nq`` joints (0 on the others)."""
    coef = np.zeros(nq)
    coef[used] = load.coefficient
    return LoadFriction(coef, load.coulomb_width_rad_s)


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


def handed_on_robot(robot: RobotModel, regs: Regressors, fits: Fits) -> RobotModel:
    """``robot`` with the handed-on fit's standard parameters and friction terms (Stribeck,
    load-dependent Coulomb) on all joints and the Coulomb smoothing widths the fits used (a record's, chosen
    per joint by :mod:`.coulomb_width`) (:func:`.outcome.identified_robot`); the joints left out keep
    ``robot``'s values (:func:`with_unmeasured_joints_kept`), the joints ``fits.stated_rotor_joints``
    ``robot``'s rotor inertia (:func:`unseen_rotor_inertia_joints`)."""
    nq = robot.nq
    p = with_stated_rotor_inertia(robot, with_unmeasured_joints_kept(robot, regs.selection, fits.phys.p),
                                  fits.stated_rotor_joints)
    handed = identified_robot(robot, p,
                              None if fits.stribeck is None else expand_to_joints(fits.stribeck, regs.used, nq),
                              None if fits.load is None else load_to_joints(fits.load.load, regs.used, nq),
                              regs.reg.joint_coulomb_width_rad_s)
    kept = np.union1d(fits.stated_rotor_joints, np.array(sorted(regs.selection.left_out), int)).astype(int)
    label_assumed_rotor_inertia(robot, handed, kept)
    return handed


#: robot.yaml's rotor inertia (its ``assumed`` key)
ROTOR_INERTIA_KEY = "actuation.rotor_inertia_kgm2"
#: a fitted rotor inertia below this multiple of its lower bound (:data:`.estimate.POSITIVE_LOWER_BOUND`)
#: sits on the bound (IPOPT's interior point ends a hair inside or outside it)
ON_BOUND_FACTOR = 2.0


def unseen_rotor_inertia_joints(regs: Regressors, p: np.ndarray) -> np.ndarray:
    """0-based measured joints whose torques show no inertia of the rotor: the physically consistent
    fit ``p`` put the joint's rotor inertia ``I_a,j`` on its lower bound (``<`` :data:`ON_BOUND_FACTOR` x
    :data:`.estimate.POSITIVE_LOWER_BOUND`).

    The rotor of a geared drive has an inertia ``I_m r^2`` well above the links' on the wrist; torques
    that carry no ``I_a,j qdd_j`` (a drive that logs its effort without the rotor's) leave it unidentified,
    not 0, and a model handed on with 1e-6 kg m^2 there gives the elastic plant's motor side nothing to
    move and a servo loop nothing to act on. A rotor inertia grouped with a link's (``I_a,1 + ZZ_1`` of a
    first vertical axis) sits on its bound only when the torques leave the sum no more than the link's
    own inertia, which the fit pulls towards the nominal one: they show no rotor there either."""
    ia = p[10 * (regs.reg.model.njoints - 1) + regs.used]
    return np.asarray(regs.used, int)[ia < ON_BOUND_FACTOR * est_mod.POSITIVE_LOWER_BOUND]


def keep_unseen_rotor_inertia(cfg: Config, regs: Regressors, fits: Fits) -> None:
    """With ``unseen_rotor_inertia: stated`` (default) set ``fits.stated_rotor_joints`` to the joints of
    :func:`unseen_rotor_inertia_joints` on the handed-on fit, so the robot handed on keeps robot.yaml's
    rotor inertia there (:func:`handed_on_robot`); with ``fitted`` none."""
    fits.stated_rotor_joints = (unseen_rotor_inertia_joints(regs, fits.phys.p) if cfg.unseen_rotor_inertia == "stated"
                                else np.zeros(0, int))


def with_stated_rotor_inertia(robot: RobotModel, p: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Standard parameters ``p`` with ``robot``'s rotor inertia on the 0-based ``joints`` (a copy)."""
    out = np.array(p, float)
    out[10 * (robot.model.njoints - 1) + np.asarray(joints, int)] = np.asarray(
        robot.actuation.rotor_inertia_kgm2, float)[np.asarray(joints, int)]
    return out


def label_assumed_rotor_inertia(robot: RobotModel, handed: RobotModel, joints: np.ndarray) -> None:
    """Where ``robot``'s rotor inertia is ``robot init``'s assumption and ``handed`` keeps it on ``joints``
    (0-based: torques that show none, joints left out of the fit), the assumption stays in force on
    ``handed``'s robot.yaml: its ``assumed`` entry gets the digest of the values handed on and a rule naming
    those joints, so a placeholder read back is still a placeholder (:mod:`pipeline.robot.assumed_values`;
    the whole vector is then assumed, the fitted joints' values included, and a later fit is not pulled
    towards any of them)."""
    entry = robot.spec.assumed.get(ROTOR_INERTIA_KEY)
    if entry is None or not len(joints):
        return
    values = [float(v) for v in handed.actuation.rotor_inertia_kgm2]
    which = ", ".join(str(int(j) + 1) for j in joints)
    handed.spec.assumed[ROTOR_INERTIA_KEY] = {
        "rule": f"{entry['rule']} on joint(s) {which}, which no torque identified; the others identified",
        "sha256": value_digest(values)}


def unseen_rotor_note(robot: RobotModel, joints: np.ndarray) -> str:
    """One line for the summary's warnings: the joints whose rotor inertia the handed-on model takes from
    robot.yaml, with its values and whether they are ``robot init``'s assumption ("" when none)."""
    if not len(joints):
        return ""
    ia = np.asarray(robot.actuation.rotor_inertia_kgm2, float)
    assumed = ROTOR_INERTIA_KEY in robot.spec.assumed
    which = ", ".join(f"joint {j + 1} {ia[j]:.3g} kg m²" for j in joints)
    return (f"the torques show no rotor inertia on joint(s) {', '.join(str(j + 1) for j in joints)} "
            f"(the physically consistent fit puts it on its bound {est_mod.POSITIVE_LOWER_BOUND:g} kg m²): the robot "
            f"handed on keeps robot.yaml's {which}"
            f"{' (ASSUMED by robot init)' if assumed else ''}, which no torque validated "
            "(identification.unseen_rotor_inertia: fitted hands on the fit's)")


def with_unmeasured_joints_kept(robot: RobotModel, selection: JointSelection, p: np.ndarray) -> np.ndarray:
    """Standard parameters ``p`` with, for every joint left out of the fit, ``robot``'s values of its
    link's inertial parameters and of its drive train (rotor inertia, viscous and Coulomb friction).

    The fit sees those parameters only through the torques of the joints before them in the chain,
    in combinations (a one-joint fit puts a link mass 40 % off and a wrist inertia on its bound):
    handed on, they would give a later stage the wrong dynamics on the joints no torque validated."""
    if selection.all_used:
        return p
    nq, n_links = robot.nq, robot.model.njoints - 1
    act = robot.actuation
    kept = standard_parameters(robot.model, act.rotor_inertia_kgm2, act.viscous_Nms_rad, act.coulomb_Nm)
    out = np.array(p, float)
    for j in selection.left_out:
        for idx in ([*range(10 * j, 10 * j + 10)] if j < n_links else []) + [10 * n_links + g * nq + j
                                                                               for g in range(3)]:
            out[idx] = kept[idx]
    return out


def unmeasured_joints_note(sel: JointSelection) -> str:
    """One line for the summary's warnings: which joints the handed-on model keeps nominal ("" when none)."""
    if sel.all_used:
        return ""
    left = ", ".join(sel.names[j] for j in sorted(sel.left_out))
    return (f"identified joint(s) {', '.join(sel.names[j] for j in sel.used)} only: the handed-on model keeps "
            f"the previous (nominal or calibrated) link inertias and drive values of {left}")
