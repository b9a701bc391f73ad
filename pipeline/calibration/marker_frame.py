"""Orientation of a 6-D marker frame on the flange, in closed form, before the fit.

A motion-capture body or 6-DOF probe is rarely mounted with its axes along the flange's: the
reading is ``R_k = R_tb^T R_refl(q_k) R_m`` with ``R_m`` the marker frame's fixed rotation in the
reflector (flange-aligned) frame, often tens of degrees. The fitted marker-point model
(:func:`pipeline.calibration.measure.expand_orientation`) linearises the orientation about the
reflector frame, so a large ``R_m`` must be known first:

1. register the tracker on the marker origins alone (Kabsch, :func:`register_points`; the
   virtual points along a turned marker's axes would bias it);
2. ``R_m`` is the chordal L2 mean of ``A_k = R_refl(q_k)^T R_tb R_k`` over the poses: the
   rotation nearest to ``sum A_k`` (projection onto SO(3) by SVD; Hartley, Trumpf, Dai & Li,
   "Rotation averaging", IJCV 103, 2013, §5.3);
3. the readings are re-expressed as ``R_k R_m^T``: the record then reads the reflector frame,
   whose small remaining rotation the fit's tool rotations (``tool.rx..rz``, set-up parameters of
   a 6-D record, :mod:`pipeline.calibration.subsets`) refine together with the arm.

The mount rotation is reported (``R_m`` composed with the fitted tool rotation); it is a fact of
the marker's mounting, not of the arm.

Step 1 registers the tracker on the marker origins the record itself gives
(:func:`record_marker_origin`), not on robot.yaml's nominal reflector offset. An offset assumed on
the last joint's axis, where the real marker sits 12 cm off it (FIGAROH's UR10 record), biases the
registration and so ``R_m`` (by 1.6 deg there), a bias the fit's tool rotations do not fully
undo: the calibrated figures then depended on the assumed offset. The origin correction ``d``
(reflector frame) is the least-squares solution of ``Y_k = R (P_k + R_k d) + t`` over the tracker
pose ``(R, t)`` and ``d``, with the nominal reflector positions ``P_k`` and rotations ``R_k``, by
block coordinate descent: Kabsch's rotation (Arun, Huang & Blostein, IEEE TPAMI 9(5), 1987) for
fixed ``d``, then ``(d, t)`` by linear least squares for fixed ``R``; each step lowers the sum of
squares, so the descent converges, and its fixed point does not depend on robot.yaml's offset.
The fit still estimates the reflector's correction from robot.yaml's value.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.calibration import measure as ms
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import register_points
from pipeline.robot.model import RobotModel


def project_to_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation nearest to ``M`` in the Frobenius norm (SVD, determinant +1)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, float))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def marker_rotation_on_flange(mm: MeasurementModel, meas: ms.Measurements) -> np.ndarray:
    """``R_m`` (3, 3): the marker frame in the reflector frame, steps 1-2 of the module docstring
    (nominal kinematics, the tracker registered on the record's own marker origins); identity for a
    record without orientations."""
    if meas.rotvec is None:
        return np.eye(3)
    P_nom, R_refl = mm.base_positions(meas.Q, np.zeros(mm.n), meas.payload_mounted,
                                      np.zeros((len(meas), 3)) if mm.marker_points else None)
    origin = record_marker_origin(P_nom, R_refl, meas.Y)
    if origin is not None:
        P_nom = P_nom + np.einsum("nij,j->ni", R_refl, origin)
    T_tb = register_points(meas.Y, P_nom)
    R_meas = Rotation.from_rotvec(meas.rotvec).as_matrix()
    A = np.einsum("nji,jk,nkl->nil", R_refl, T_tb.rotation, R_meas)
    return project_to_rotation(A.sum(axis=0))


def aligned(meas: ms.Measurements, R_m: np.ndarray) -> ms.Measurements:
    """The record with each orientation re-expressed in the reflector frame, ``R_k R_m^T``."""
    if meas.rotvec is None:
        return meas
    R = Rotation.from_rotvec(meas.rotvec).as_matrix() @ np.asarray(R_m, float).T
    return ms.Measurements(meas.Q, meas.Y, meas.sigma_m, meas.source, Rotation.from_matrix(R).as_rotvec(),
                           meas.n_requested, meas.invisible, meas.payload_mounted, meas.lines, meas.offset_m,
                           meas.pose_index)


def mount_rotation_deg(R_m: np.ndarray) -> float:
    """Angle of the marker frame against the flange axes (deg)."""
    return float(np.degrees(np.linalg.norm(Rotation.from_matrix(project_to_rotation(R_m)).as_rotvec())))


def align_records(robot: RobotModel, user: ms.Measurements, validation: ms.Measurements | None
                  ) -> tuple[np.ndarray, ms.Measurements, ms.Measurements | None]:
    """``R_m`` of the calibration record ``user`` and both records re-expressed in the reflector frame."""
    R_m = marker_rotation_on_flange(MeasurementModel(robot, marker_points=True), user)
    return R_m, aligned(user, R_m), None if validation is None else aligned(validation, R_m)


#: block-coordinate steps of :func:`record_marker_origin` (it converges in 10-20 on arm records)
MARKER_ORIGIN_MAX_STEPS = 200


def _kabsch(Y: np.ndarray, P: np.ndarray) -> np.ndarray:
    """The rotation ``R`` minimising ``sum |Y_k - R P_k - t|^2`` (Arun et al. 1987)."""
    H = (P - P.mean(axis=0)).T @ (Y - Y.mean(axis=0))
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    return Vt.T @ D @ U.T


def record_marker_origin(P: np.ndarray, R: np.ndarray, Y: np.ndarray) -> np.ndarray | None:
    """The origin correction ``d`` (3,) of the module docstring from the nominal reflector positions
    ``P`` (N, 3) and rotations ``R`` (N, 3, 3) and the readings ``Y`` (N, 3); None when the rotations
    do not determine it (fewer than 4 poses, or singular normal equations)."""
    P, R, Y = (np.asarray(a, float) for a in (P, R, Y))
    n = len(Y)
    if n < 4:
        return None
    d = np.zeros(3)
    for _ in range(MARKER_ORIGIN_MAX_STEPS):
        R_tb = _kabsch(Y, P + np.einsum("nij,j->ni", R, d))
        A = np.concatenate([np.einsum("ij,njk->nik", R_tb, R), np.broadcast_to(np.eye(3), (n, 3, 3))],
                           axis=2).reshape(-1, 6)
        normal = A.T @ A
        if np.linalg.cond(normal) > 1e12:
            return None
        step = np.linalg.solve(normal, A.T @ (Y - P @ R_tb.T).reshape(-1))[:3] - d
        d = d + step
        if np.linalg.norm(step) < 1e-12:
            break
    return d
