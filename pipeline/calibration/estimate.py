"""Estimation: closed-form tracker registration, then Levenberg-Marquardt on the identifiable set.

1. Registration (paper 003 §2.2 "ideal pose transformation matrix ... by least squares"):
   find ``T_tb`` minimising ``sum |T_tb y_k - p_k|^2`` between the tracker readings ``y_k`` and the
   nominal base-frame reflector positions ``p_k`` (Kabsch/Umeyama without scale, via
   ``scipy.spatial.transform.Rotation.align_vectors`` on the centred point sets).
2. Levenberg-Marquardt (paper 003 eq. 27; paper 002 eq. 12 Gauss-Newton steps) on the identifiable
   parameters ``theta = x[cols]`` with the exact CasADi Jacobian and whitened residuals
   ``r_k = (y_k - h(q_k, x, T_tb)) / sigma_k`` (with the gravity-model uncertainty of the
   elastostatic model, ``factors``: ``r_k = W_k (y_k - h)`` with each reading's covariance block,
   :class:`pipeline.calibration.gravity_uncertainty.Whitener`):
   ``(J^T J + lambda diag(J^T J)) d = J^T r``, lambda adapted (Marquardt/Nielsen).
3. Covariance from the noise model: ``C = (J^T J)^-1`` of the whitened Jacobian at the solution
   (paper 000 eq. 5); ``chi2 / dof`` is reported as a check of the noise model. With gravity
   factors the covariance is the sandwich ``K D K^T + M M^T`` of the weighted estimator (the
   readings' errors are correlated through the common inertial error, ``Whitener.sandwich``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.gravity_uncertainty import Whitener
from pipeline.core.errors import SolverError
from pipeline.robot.model import RobotModel
from pipeline.robot.parameters import apply_kinematic_errors
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad

#: the estimate's regularity test: smallest / largest eigenvalue of the column-normalised
#: information matrix (exact dependencies give ~1e-16; the design's identifiable set is cut at
#: :data:`pipeline.calibration.design_identifiable.POOL_REL_TOL` on singular values, 1e-10 here)
REGULAR_EIGENVALUE_RATIO = 1e-12


def register_points(tracker_points: np.ndarray, base_points: np.ndarray) -> pin.SE3:
    """Closed-form ``T`` with ``base ≈ R tracker + t`` (Kabsch / Umeyama, no scale)."""
    Y = np.asarray(tracker_points, float)
    P = np.asarray(base_points, float)
    if Y.shape != P.shape or Y.shape[0] < 3:
        raise SolverError(None, "registration", f"need >= 3 point pairs of equal shape, got {Y.shape}, {P.shape}")
    yc, pc = Y.mean(axis=0), P.mean(axis=0)
    rot, _ = Rotation.align_vectors(P - pc, Y - yc)
    R = rot.as_matrix()
    return pin.SE3(R, pc - R @ yc)


@dataclass
class Estimate:
    """Identified parameters and their uncertainty."""

    x: np.ndarray                  # full parameter vector (model.names), ``x = basis @ theta``
    theta: np.ndarray              # identified parameters
    basis: np.ndarray              # (n_full, p)
    covariance: np.ndarray         # (p,p) of theta, from the noise model
    transform_tracker_to_base: pin.SE3   # identified
    registration: pin.SE3          # closed-form initial tracker pose (nominal kinematics)
    iterations: int
    chi2_per_dof: float
    residual_rms_m: float
    converged: bool
    cost_history: list[float]
    #: gain ``M = K B`` (p, r) of the inertial error on the estimate (gravity factors; else None)
    gravity_gain: np.ndarray | None = None

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))

    @property
    def readings_covariance(self) -> np.ndarray:
        """The readings' share of :attr:`covariance`: without the inertial error's part ``M M^T``
        (``M`` = :attr:`gravity_gain`; the whole covariance without one)."""
        C = np.asarray(self.covariance, float)
        return C if self.gravity_gain is None else C - self.gravity_gain @ self.gravity_gain.T


def levenberg_marquardt(mm: MeasurementModel, Q: np.ndarray, Y: np.ndarray, sigma: np.ndarray,
                        basis: np.ndarray, T0: pin.SE3, max_iterations: int = 50,
                        tol: float = 1e-10, mounted: np.ndarray | None = None,
                        offsets: np.ndarray | None = None, whitener: Whitener | None = None,
                        theta0: np.ndarray | None = None, first: tuple[np.ndarray, np.ndarray] | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, bool, list[float]]:
    """Minimise ``|L^-1 (Y - h(Q, basis @ theta, T0))|^2`` over ``theta`` (``whitener``; None:
    ``sum |(Y - h) / sigma|^2``) from ``theta0`` (None: 0; a warm start, e.g. the fit of a
    neighbouring fold or of the previous noise-model round); ``first``: the predictions and
    Jacobian blocks already evaluated at the start."""
    P = np.asarray(basis, float)
    theta = np.zeros(P.shape[1]) if theta0 is None else np.asarray(theta0, float).copy()
    wh = whitener if whitener is not None else Whitener(sigma)

    def resid_jac(th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pred, J = mm.jacobian(Q, P @ th, T0, P, mounted, offsets)
        return wh.vector(Y - pred), wh.matrix(J)

    if first is not None:
        r, J = wh.vector(Y - first[0]), wh.matrix(first[1])
    else:
        r, J = resid_jac(theta)
    cost = float(r @ r)
    hist = [cost]
    lam = 1e-3
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 - the count is returned
        A = J.T @ J
        g = J.T @ r
        D = np.diag(np.maximum(np.diag(A), 1e-12 * max(np.diag(A).max(), 1e-300)))
        while True:
            try:
                d = np.linalg.solve(A + lam * D, g)
            except np.linalg.LinAlgError:
                lam *= 10
                if lam > 1e12:
                    raise SolverError(None, "levenberg-marquardt", "singular normal equations") from None
                continue
            th_new = theta + d
            r_new, J_new = resid_jac(th_new)
            cost_new = float(r_new @ r_new)
            if cost_new <= cost or lam > 1e12:
                break
            lam *= 10
        if cost_new > cost:
            converged = True  # no descent direction left at machine precision
            break
        rel = (cost - cost_new) / max(cost, 1e-300)
        theta, r, J, cost = th_new, r_new, J_new, cost_new
        hist.append(cost)
        lam = max(lam / 10, 1e-12)
        if rel < tol:
            converged = True
            break
    return theta, P @ theta, J, it, converged, hist


def estimate(mm: MeasurementModel, Q: np.ndarray, Y: np.ndarray, sigma: np.ndarray, basis: np.ndarray,
             source: str = "measurements", max_iterations: int = 50, mounted: np.ndarray | None = None,
             offsets: np.ndarray | None = None, factors: np.ndarray | None = None,
             theta0: np.ndarray | None = None) -> Estimate:
    """Registration + LM + covariance (see module docstring); ``mounted``: rows read with the payload;
    ``factors`` (N, 3, r): gravity-model covariance factors ``B_k`` of the readings
    (:class:`pipeline.calibration.gravity_uncertainty.GravityCovariance`; None: ``sigma_k^2 I``);
    ``theta0``: LM's start (None: the nominal model, whose Jacobian the regularity check evaluates
    once for both)."""
    Q = np.asarray(Q, float)
    Y = np.asarray(Y, float)
    P = np.asarray(basis, float)
    p = P.shape[1]
    if 3 * len(Q) < p:
        raise SolverError(source, "measurements",
                          f"{len(Q)} points give {3 * len(Q)} equations for {p} identifiable parameters")
    P_nom, _ = mm.base_positions(Q, np.zeros(mm.n), mounted, offsets)
    T_reg = register_points(Y, P_nom)
    # regularity of the information matrix before iterating
    pred0, J0_raw = mm.jacobian(Q, np.zeros(mm.n), T_reg, P, mounted, offsets)
    wh = Whitener(np.asarray(sigma, float), factors)
    J0 = wh.matrix(J0_raw)
    # column-normalised: the test does not depend on the parameters' units (a compliance in
    # rad/(N m) has columns 10^2-10^3 times a length's, which alone made a regular set "singular")
    norms = np.linalg.norm(J0, axis=0)
    Jn = J0 / np.where(norms > 0, norms, 1.0)
    ev = np.linalg.eigvalsh(Jn.T @ Jn)
    if not (ev[0] > REGULAR_EIGENVALUE_RATIO * ev[-1] and np.all(norms > 0)):
        raise SolverError(source, "information matrix",
                          f"singular (smallest/largest eigenvalue {max(ev[0], 0.0) / ev[-1]:.3g} of the "
                          f"column-normalised matrix): the configurations do not excite all {p} identifiable "
                          "parameters")
    start = None if theta0 is not None and np.any(theta0) else (pred0, J0_raw)
    theta, x, J, it, conv, hist = levenberg_marquardt(mm, Q, Y, sigma, P, T_reg, max_iterations, mounted=mounted,
                                                      offsets=offsets, whitener=wh, theta0=theta0, first=start)
    A = J.T @ J
    C = np.linalg.inv(A)
    C = 0.5 * (C + C.T)
    dof = max(J.shape[0] - p, 1)
    chi2 = hist[-1] / dof
    pred = mm.predict(Q, x, T_reg, mounted, offsets)
    res = np.linalg.norm(Y - pred, axis=1)
    T_id = T_reg * pin.exp6(x[mm.sl_tracker])
    C, M = wh.sandwich(J, C)
    return Estimate(x, theta, P, C, T_id, T_reg, it, float(chi2), float(np.sqrt(np.mean(res ** 2))), conv, hist, M)


#: a compliance known to worse than this relative standard deviation is not handed on: the nominal
#: stiffness rule (:mod:`pipeline.robot.stiffness`) is about as good (it spreads by ~30 % between
#: arms of one type), and a poorly determined estimate can be several times off (a soft wrist
#: joint would then ruin the elastic feedforward)
MAX_COMPLIANCE_RELATIVE_STD = 0.3


def identified_compliance(mm: MeasurementModel, x: np.ndarray, basis: np.ndarray | None = None,
                          covariance: np.ndarray | None = None) -> np.ndarray:
    """``(nq,)`` bool: joints whose compliance the fit identified (in the basis), found positive and,
    given the covariance of ``theta`` (``x = basis theta``), determined to better than
    :data:`MAX_COMPLIANCE_RELATIVE_STD`; all False for a rigid error model."""
    if not mm.compliance:
        return np.zeros(mm.nq, bool)
    rows = np.ones(mm.n, bool) if basis is None else np.any(np.asarray(basis) != 0, axis=1)
    c = np.asarray(x, float)[mm.sl_compliance]
    known = rows[mm.sl_compliance] & (c > 0)
    if covariance is not None and basis is not None:
        B = np.asarray(basis, float)[mm.sl_compliance]
        std = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", B, np.asarray(covariance, float), B), 0.0))
        known &= std < MAX_COMPLIANCE_RELATIVE_STD * np.abs(c)
    return known


def calibrated_robot(robot: RobotModel, mm: MeasurementModel, x: np.ndarray, basis: np.ndarray | None = None,
                     covariance: np.ndarray | None = None):
    """``RobotModel`` with the identified kinematic errors (lead's conventions, docs/requests/calibration.md).

    - Joint placements and zero offsets: the identified ``j{i}.*`` errors (``apply_kinematic_errors``).
      Base frame = joint 1's frame: ``j1.*`` and ``base.*`` are not identifiable from tracker
      readings (they are the unknown tracker pose) and stay zero.
    - Rigid tool: the identified reflector-offset correction ``dr`` (reflector frame) is applied as a
      tool *translation* ``tool.dx,dy,dz = R_flange_reflector dr`` in the flange frame, so the TCP moves
      with the reflector. Tool rotations are unobservable from positions of one reflector and stay
      nominal; 6-D readings (marker orientation) identify them (``tool.rx..rz``, applied with the rest).
    - Joint compliances (elastostatic model): ``actuation.joint_stiffness_Nm_rad = 1 / c_i`` for each
      identified positive compliance; a joint whose compliance was not identified (no gravity
      load, or not in the parameter subset), came out non-positive or, given ``covariance``, is
      not determined to :data:`MAX_COMPLIANCE_RELATIVE_STD` keeps the nominal stiffness
      (:func:`pipeline.robot.stiffness.nominal_joint_stiffness_Nm_rad`).
    The robot.yaml facts (TCP and reflector in robot.yaml's ``flange_frame``,
    :meth:`RobotModel.tool_facts`) are updated to match, so ``save``/``load`` reproduce the model.
    """
    x = np.asarray(x, float)
    x_kin = x[mm.sl_kin].copy()
    fl_id = robot.model.getFrameId(robot.frame_flange)
    rf_id = robot.model.getFrameId(robot.frame_reflector)
    rel0 = robot.model.frames[fl_id].placement.inverse() * robot.model.frames[rf_id].placement
    tool = mm.sym.kin.tool
    x_kin[tool.start : tool.start + 3] += rel0.rotation @ x[mm.sl_reflector]
    model = apply_kinematic_errors(robot.model, x_kin, robot.frame_flange,
                                   (robot.frame_tcp, robot.frame_reflector))
    new = robot.with_model(model)
    # the stated flange frame's facts (the reflector's axis stays in its frame, which turned with the tool)
    new.spec.tool.transform_tcp_to_flange, new.spec.tool.reflector_offset_m, _ = new.tool_facts()
    if mm.compliance:
        c = x[mm.sl_compliance]
        known = identified_compliance(mm, x, basis, covariance)
        k = nominal_joint_stiffness_Nm_rad(robot)
        k[known] = 1.0 / c[known]
        new.spec.actuation.joint_stiffness_Nm_rad = k
    return new
