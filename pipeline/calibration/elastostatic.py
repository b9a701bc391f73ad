"""Stage pieces of the elastostatic calibration: the error model a parameter subset needs, the
pose design over geometry and compliances (design basis, payload poses), the known payload, and
the second pass with an upstream (identified) gravity model.

Data flow stays one-way: a calibration run uses the dynamic model it is given (``ctx.robot``:
nominal) for the gravity torques of ``q_link = q - c g(q)``; the identification stage runs after
it. A *second calibration pass* is a new run whose ``calibration.gravity_model`` names the robot
folder an identification stage wrote (``<runs>/<name>/identification/robot``): its inertias give
the gravity torques, and the report shows how much each compliance moved against the fit with the
run's own (nominal) gravity model. Gravity-model errors scale the compliance estimates (a 15 %
mass error gives a ~15 % compliance error), so this pass is what makes the stiffness estimate
trustworthy.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from pipeline.calibration import candidates as cd
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import subsets
from pipeline.calibration.config import Config
from pipeline.calibration.estimate import Estimate, estimate, identified_compliance
from pipeline.core.errors import ConfigError, PipelineError
from pipeline.robot.handoff import ElastostaticRecord
from pipeline.robot.model import RobotModel
from pipeline.robot.stiffness import DEFLECTION_AT_TORQUE_LIMIT_RAD, nominal_joint_stiffness_Nm_rad


def measurement_model(robot: RobotModel, cfg: Config, marker_points: bool = False) -> em.MeasurementModel:
    """The error model the parameter subset needs (elastostatic when it has compliances; marker
    points when the readings are 6-D, :func:`pipeline.calibration.measure.expand_orientation`)."""
    return em.MeasurementModel(robot, compliance=subsets.wants_compliance(cfg.parameters), payload=cfg.payload(),
                               marker_points=marker_points)


#: a compliance this many times the nominal one is the largest the identifiability check considers
PLAUSIBLE_COMPLIANCE_FACTOR = 3.0
#: ... and its effect must reach this fraction of the tracker noise to count as observable
OBSERVABLE_NOISE_FRACTION = 0.1


def negligible_compliances(mm: em.MeasurementModel, J: np.ndarray) -> np.ndarray:
    """(nq,) bool: joints whose compliance cannot move the readings measurably.

    ``J`` (rows, mm.n) is the identification Jacobian on sampled poses. A compliance ``c_i`` moves
    the readings by ``J[:, c_i] c_i``; with ``c_i`` = 3x the nominal compliance its RMS effect below a
    tenth of the tracker's constant noise means the joint carries (almost) no gravity torque (a
    vertical first axis, a wrist roll whose centre of mass is on its axis). The rank test alone
    would call such a column identifiable whenever its torque is not exactly zero (an identified
    gravity model puts a small first moment off every axis), and the design would then chase it."""
    cols = np.asarray(J, float)[:, mm.sl_compliance]
    plausible = PLAUSIBLE_COMPLIANCE_FACTOR / nominal_joint_stiffness_Nm_rad(mm.robot)
    effect_m = np.sqrt(np.mean(cols**2, axis=0)) * plausible
    return effect_m < OBSERVABLE_NOISE_FRACTION * float(mm.robot.tracker.noise_const_m)


def gravity_model_of(robot: RobotModel, upstream: RobotModel) -> pin.Model:
    """``robot``'s kinematics with ``upstream``'s link inertias (matched by joint name).

    The elastostatic model needs the gravity torques of the kinematics being calibrated: the
    upstream robot of a previous run carries that run's calibrated kinematics (a base tilted by
    a fraction of a milliradian would give a vertical first axis a spurious gravity torque and
    make its compliance look identifiable), so only its inertias are taken."""
    model = robot.model.copy()
    for jid in range(1, model.njoints):
        name = model.names[jid]
        if not upstream.model.existJointName(name):
            raise ConfigError(None, "calibration.gravity_model", f"the upstream robot has no joint {name!r}")
        model.inertias[jid] = upstream.model.inertias[upstream.model.getJointId(name)].copy()
    return model


def load_gravity_model(cfg: Config, robot: RobotModel) -> RobotModel | None:
    """The robot of ``calibration.gravity_model`` (same joints as ``robot``), or None."""
    if cfg.gravity_model is None:
        return None
    try:
        other = RobotModel.load(cfg.gravity_model)
    except PipelineError as exc:
        raise ConfigError(None, "calibration.gravity_model", f"cannot load {cfg.gravity_model}: {exc}") from None
    if other.nq != robot.nq:
        raise ConfigError(None, "calibration.gravity_model",
                          f"{cfg.gravity_model} has {other.nq} joints, {robot.name} has {robot.nq}")
    if not subsets.wants_compliance(cfg.parameters):
        raise ConfigError(None, "calibration.gravity_model",
                          f"only used by the elastostatic model, but calibration.parameters = {cfg.parameters!r} "
                          "has no compliance")
    return other


def gravity_pass(mm: em.MeasurementModel, meas: ms.Measurements, basis: np.ndarray, est: Estimate,
                 rejected: np.ndarray, cfg: Config, source: str) -> dict:
    """Second pass: how much the stiffness moved against the fit with this run's (nominal) gravity
    model. ``mm`` holds the upstream gravity model on return."""
    gravity = mm.gravity_model
    mm.set_gravity_model(mm.robot.model)
    keep = np.ones(len(meas), bool)
    keep[rejected] = False
    mounted = None if meas.payload_mounted is None else meas.payload_mounted[keep]
    offsets = None if meas.offset_m is None else meas.offset_m[keep]
    try:
        # compliances of joints the nominal gravity model does not load cannot be fitted with it
        tau = np.abs(mm.static_torques(meas.Q[keep], mounted)).max(axis=0)
        dead = np.flatnonzero(tau <= 1e-9 * tau.max())
        cols = ~np.any(basis[mm.sl_compliance][dead] != 0, axis=0)
        first = estimate(mm, meas.Q[keep], meas.Y[keep], meas.sigma_m[keep], basis[:, cols], "nominal gravity",
                         cfg.max_lm_iterations, mounted, offsets)
    finally:
        mm.set_gravity_model(gravity)
    names = [mm.names[i] for i in range(mm.n)]
    c_first, c_second = first.x[mm.sl_compliance], est.x[mm.sl_compliance]
    rows = [{"parameter": names[mm.sl_compliance][j], "compliance_nominal_gravity": float(c_first[j]),
             "compliance_upstream_gravity": float(c_second[j]),
             "relative_change": float((c_second[j] - c_first[j]) / c_first[j]) if c_first[j] != 0 else None}
            for j in range(len(c_first)) if np.any(basis[mm.sl_compliance][j] != 0)]
    return {"gravity_model": source, "chi2_per_dof_nominal_gravity": float(first.chi2_per_dof),
            "chi2_per_dof_upstream_gravity": float(est.chi2_per_dof), "compliances": rows}


def compliance_design_scale(robot: RobotModel) -> np.ndarray:
    """``(nq,)`` torque scale ``tau_s`` (N m) of the design's compliance unit ``theta_j = c_j tau_s_j``:
    the joint's torque limit (``robot.limits.effort_Nm``), or where none is given the torque that
    twists the nominal stiffness by :data:`pipeline.robot.stiffness.DEFLECTION_AT_TORQUE_LIMIT_RAD`."""
    effort = np.asarray(robot.limits.effort_Nm, float)
    rule = nominal_joint_stiffness_Nm_rad(robot) * DEFLECTION_AT_TORQUE_LIMIT_RAD
    return np.where(np.isfinite(effort) & (effort > 0), effort, rule)


def design_basis(mm: em.MeasurementModel, basis: np.ndarray) -> np.ndarray:
    """The pose design's basis: the identifiable ``basis`` (geometric and compliance columns) with
    each compliance as the twist (rad) it gives at the joint's torque scale,
    ``theta_j = c_j tau_s_j`` (:func:`compliance_design_scale`).

    The candidate and working Jacobians then carry the compliance columns
    (:func:`pipeline.calibration.candidates.with_compliance_columns`,
    :func:`pipeline.calibration.task_space.tcp_jacobian`), so every selector works on the extended
    parameter set. Why this unit: a compliance column is ``-tau_j(q) dy/dq_j``, so in this unit it
    is the joint-offset column ``dy/dq_j`` times ``tau_j / tau_s_j`` (a fraction of one), of the
    same order as the geometric columns (m, rad). No index is column-normalised
    (:mod:`pipeline.calibration.indices`): in the natural unit rad/(N m) the columns are 10^2-10^3
    times the geometric ones, in nominal compliances (``1/k``, a twist of ~2 mrad at the torque
    limit) ~10^-3 times, and the selectors' regularity test (eigenvalues above 1e-10 of the
    largest) then calls the set singular. The scale matters only to the unit-dependent indices
    (O1-O5, A, E; paper 003 §3); the default ``V`` criterion ``trace(W M^-1)`` and ``D`` rank
    designs independently of any column scale."""
    P = np.asarray(basis, float).copy()
    if mm.compliance:
        P[mm.sl_compliance] /= compliance_design_scale(mm.robot)[:, None]
    return P[:, np.any(P != 0, axis=0)]


def design_torques(mm: em.MeasurementModel) -> Callable[[np.ndarray], np.ndarray] | None:
    """The static torques the candidate Jacobians' compliance columns need (None: rigid model)."""
    return mm.static_torques if mm.compliance else None


def design_blocks(mm: em.MeasurementModel, Q: np.ndarray, dbasis: np.ndarray, transform_tracker_to_base,
                  mounted: np.ndarray | None = None) -> np.ndarray:
    """Whitened design Jacobian blocks ``(N, 3, p)`` of the configurations ``Q`` (nominal model),
    the compliance columns with the payload's torque where ``mounted``."""
    chain = cd.chain_from_robot(mm.robot)
    Q = np.atleast_2d(np.asarray(Q, float))
    G = cd.build_candidate_set(chain, Q, dbasis, transform_tracker_to_base, static_torques=design_torques(mm)).G
    if mounted is not None and np.any(mounted) and mm.compliance:
        m = np.asarray(mounted, bool)
        G[m] = cd.build_candidate_set(chain, Q[m], dbasis, transform_tracker_to_base,
                                      static_torques=lambda Qc: mm.static_torques(Qc, np.ones(len(Qc), bool))).G
    return G


def payload_poses(mm: em.MeasurementModel, Q: np.ndarray, k: int, dbasis: np.ndarray | None = None,
                  spec: ix.IndexSpec | None = None) -> np.ndarray:
    """Sorted indices of the ``k`` rows of ``Q`` to measure again with the payload mounted.

    With the design basis and index (``dbasis``, ``spec``; not the position-only ``Od``/``Oc``)
    the design chooses: greedy forward selection, each step adding the loaded reading that most
    improves the index of the information matrix of all readings so far (Atkinson, Donev & Tobias,
    *Optimum Experimental Designs*, 2007, §12.6 sequential construction; the loaded Jacobian's
    compliance columns carry the payload's torque). Ties (e.g. a singular start) and the other
    indices fall back to the payload's extra joint deflection ``|Delta tau / k_nom|``, largest first."""
    loaded = mm.static_torques(Q, np.ones(len(Q), bool))
    extra = (np.abs(loaded - mm.static_torques(Q)) / nominal_joint_stiffness_Nm_rad(mm.robot)).sum(axis=1)
    order = np.argsort(-extra, kind="stable")
    if dbasis is None or spec is None or spec.needs_positions or not mm.compliance:
        return np.sort(order[:k])
    T0 = mm.robot.tracker.transform_tracker_to_base
    free = design_blocks(mm, Q, dbasis, T0)[order]
    load = design_blocks(mm, Q, dbasis, T0, np.ones(len(Q), bool))[order]
    M = np.einsum("kmi,kmj->ij", free, free)
    info = np.einsum("kmi,kmj->kij", load, load)
    chosen: list[int] = []
    for _ in range(k):
        scores = np.array([-np.inf if c in chosen else ix.score(spec, M + info[c], len(Q) + len(chosen) + 1)
                           for c in range(len(Q))])
        best = int(np.argmax(np.nan_to_num(scores, nan=-np.inf, posinf=np.inf)))
        if not np.isfinite(scores[best]):
            best = next(c for c in range(len(Q)) if c not in chosen)
        chosen.append(best)
        M = M + info[best]
    return np.sort(order[chosen])


def measure_with_payload(mm: em.MeasurementModel, real, meas: ms.Measurements, cfg: Config,
                         rng: np.random.Generator, dbasis: np.ndarray | None = None,
                         spec: ix.IndexSpec | None = None) -> ms.Measurements:
    """Measure ``payload_fraction`` of the measured configurations again with the payload mounted,
    those the design chooses (:func:`payload_poses`); the same pose under two loads separates the
    compliances from the geometry."""
    payload = cfg.payload()
    if payload is None or cfg.payload_fraction == 0 or len(meas) == 0:
        return meas
    k = int(math.ceil(cfg.payload_fraction * len(meas)))
    idx = payload_poses(mm, meas.Q, k, dbasis, spec)
    with_load = ms.measure_simulated(real, meas.Q[idx], rng, payload)
    return ms.concatenate([meas, with_load], meas.source)


def static_torque_record(mm: em.MeasurementModel, meas: ms.Measurements, est: Estimate, basis: np.ndarray,
                         identifiable_names: list[str]) -> ElastostaticRecord:
    """What a later stage needs to re-express the identified stiffness for its own gravity model
    (:func:`pipeline.robot.stiffness.stiffness_for_gravity_model`): per measured configuration the
    static torques the fit used (payload included where mounted), the payload's share of them,
    which joints' compliance was identified (the others are nominal), and the standard deviation of
    each compliance (rad/(N m); NaN where not identified)."""
    used = mm.static_torques(meas.Q, meas.payload_mounted)
    std = dict(zip(identifiable_names, est.std, strict=True))
    names = mm.names[mm.sl_compliance]
    return ElastostaticRecord(
        stiffness_identified=identified_compliance(mm, est.x, basis, est.covariance),
        compliance_std_rad_Nm=np.array([float(std.get(n, np.nan)) for n in names]),
        configurations_rad=np.asarray(meas.Q, float), torques_Nm=used,
        payload_torques_Nm=used - mm.static_torques(meas.Q))
