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
    (nominal kinematics); identity for a record without orientations."""
    if meas.rotvec is None:
        return np.eye(3)
    P_nom, R_refl = mm.base_positions(meas.Q, np.zeros(mm.n), meas.payload_mounted,
                                      np.zeros((len(meas), 3)) if mm.marker_points else None)
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
