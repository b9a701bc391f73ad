"""Calibration with the optical 6-D tracker (:mod:`pipeline.sim.optical_tracker`).

Any robot whose robot.yaml declares ``optical_tracker`` can be calibrated from its 6-D readings:

- **candidates**: the joint grid filtered by limits, collisions and the *predicted* optical
  visibility (nominal model, nominal camera pose, :class:`OpticalMargins` to stay visible on the
  hidden robot whose kinematics and camera pose differ), via the batched numpy chain of
  :func:`pipeline.calibration.candidates.filter_grid`;
- **design blocks**: a 6-D reading enters the fit as three points, the marker origin and two virtual
  points one lever along the measured marker x and y axes (:func:`pipeline.calibration.measure.
  expand_orientation`); the whitened Jacobian block of a candidate is the same nine rows (origin /
  ``sigma_m``, virtual points / ``sqrt(sigma_m^2 + (L sigma_rad)^2)``), so the information matrix
  the design maximises is the one the estimator sees;
- **measurement**: :func:`measure_optical` reads the hidden robot's optical tracker and keeps the
  visible rows (:class:`pipeline.calibration.measure.Measurements` with ``rotvec``);
- **validation** (paper 004 Table 2 layout): held-out poses visible on the hidden robot; position
  errors per base axis and orientation errors as Cardan angles (intrinsic x-y'-z'' of the error
  rotation ``R_meas R_pred^T`` in the base frame), maximum and half peak-to-peak, before
  (nominal, registered camera pose) and after calibration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pipeline.calibration import candidates as cd
from pipeline.calibration import measure as ms
from pipeline.calibration.error_model import MeasurementModel
from pipeline.calibration.estimate import Estimate, estimate, register_points
from pipeline.robot import instruments as inst
from pipeline.robot.model import RobotModel

#: the three marker points of a 6-D reading (origin, lever along x, lever along y), marker frame
MARKER_OFFSETS_M = ms.MARKER_LEVER_M * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def chain_visibility(robot: RobotModel, chain: cd.Chain, transform_camera_to_base: pin.SE3,
                     margins: inst.OpticalMargins = inst.NO_MARGINS):
    """``visibility(kinematics, segments) -> mask`` for :func:`candidates.filter_grid`."""
    spec = inst.optical_spec(robot)
    occluders = inst.probe_occluders(robot)
    frames = robot.model.frames
    R_rel = (frames[robot.frame_id(robot.frame_flange)].placement.inverse()
             * frames[robot.frame_id(robot.frame_reflector)].placement).rotation   # marker axes in the flange

    def visible(kin: cd.Kinematics, seg: np.ndarray) -> np.ndarray:
        diodes, axis = inst.probe_points(spec, kin.p_reflector, kin.R_flange @ R_rel)
        return inst.diode_visibility(spec, transform_camera_to_base, diodes, axis, seg, chain.capsule_r, occluders,
                                   margins).visible
    return visible


def visible_grid(robot: RobotModel, n_per_axis: int, margins: inst.OpticalMargins = inst.NO_MARGINS,
                 collision_margin_m: float = 0.01) -> tuple[np.ndarray, np.ndarray, dict]:
    """Grid configurations (grid order) the nominal optical tracker sees, their flat grid indices, counts."""
    chain = cd.chain_from_robot(robot)
    camera = inst.optical_spec(robot).transform_camera_to_base
    return cd.filter_grid(chain, n_per_axis, cd.FilterMargins(collision_m=collision_margin_m),
                          visibility=chain_visibility(robot, chain, camera, margins))


def visible_mask(robot: RobotModel, Q: np.ndarray, transform_camera_to_base: pin.SE3 | None = None,
                 margins: inst.OpticalMargins = inst.NO_MARGINS, collision_margin_m: float = 0.01) -> np.ndarray:
    """Configurations inside the limits, collision-free and predicted visible (numpy chain)."""
    chain = cd.chain_from_robot(robot)
    T = (transform_camera_to_base if transform_camera_to_base is not None
         else inst.optical_spec(robot).transform_camera_to_base)
    Q = np.atleast_2d(np.asarray(Q, float))
    ok, _ = cd.filter_configurations(chain, Q, cd.FilterMargins(collision_m=collision_margin_m), visibility=False)
    idx = np.flatnonzero(ok)
    if idx.size:
        kin = cd.kinematics(chain, Q[idx])
        ok[idx] = chain_visibility(robot, chain, T, margins)(kin, cd.capsule_segments(chain, kin))
    return ok


def nominal_sigmas(robot: RobotModel, Q: np.ndarray, transform_camera_to_base: pin.SE3
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Stated ``(sigma_m, sigma_rad)`` of readings at ``Q`` (nominal model, every diode seen)."""
    spec = inst.optical_spec(robot)
    origin, _ = robot.poses(np.atleast_2d(Q), robot.frame_reflector)
    dist = np.linalg.norm(origin - transform_camera_to_base.translation, axis=1)
    sigma_d = spec.noise_const_m + spec.noise_per_m * dist
    return inst.stated_sigmas(spec, np.ones((len(Q), len(spec.probe_diodes_m)), bool), sigma_d)


def design_blocks(mm: MeasurementModel, robot: RobotModel, Q: np.ndarray, basis: np.ndarray,
                  transform_camera_to_base: pin.SE3, orientation_sigma_rad: float) -> np.ndarray:
    """Whitened (N, 9, p) Jacobian blocks of 6-D readings at ``Q`` (module docstring)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    n = len(Q)
    offsets = np.repeat(MARKER_OFFSETS_M, n, axis=0)
    _, J = mm.jacobian(np.concatenate([Q] * 3), np.zeros(mm.n), transform_camera_to_base, basis, offsets=offsets)
    sigma_m, _ = nominal_sigmas(robot, Q, transform_camera_to_base)
    s_virtual = np.sqrt(sigma_m ** 2 + (ms.MARKER_LEVER_M * orientation_sigma_rad) ** 2)
    blocks = [J[:n] / sigma_m[:, None, None], J[n : 2 * n] / s_virtual[:, None, None],
              J[2 * n :] / s_virtual[:, None, None]]
    return np.concatenate(blocks, axis=1)


def measure_optical(real, Q: np.ndarray, rng: np.random.Generator) -> tuple[ms.Measurements, float]:
    """Command ``Q`` on the hidden robot and read its optical tracker; visible rows only, and the
    median stated orientation sigma (rad) of those readings."""
    Q = np.atleast_2d(np.asarray(Q, float))
    r = real.optical_tracker.measure(Q, rng)
    v = np.asarray(r.visible, bool)
    meas = ms.Measurements(Q[v], r.position_m[v], r.sigma_m[v], "simulated optical tracker", r.rotvec[v],
                           len(Q), Q[~v])
    return meas, float(np.median(r.sigma_rad[v])) if v.any() else float("nan")


def register_camera(robot: RobotModel, real, Q_pool: np.ndarray, rng: np.random.Generator, n_pilot: int = 8,
                    tries: int = 10) -> tuple[pin.SE3, int]:
    """Camera-bar pose from a few pilot readings: ``n_pilot`` configurations drawn from ``Q_pool``
    (predicted visible with the nominal pose), read on the hidden robot, the visible ones registered
    onto the nominal marker positions (closed form, :func:`estimate.register_points`). Returns the
    pose and the number of pilot configurations commanded (the visibility of the design is then
    predicted with this pose, not the nominal one)."""
    commanded = 0
    Y, P = np.zeros((0, 3)), np.zeros((0, 3))
    for _ in range(tries):
        Q = Q_pool[rng.choice(len(Q_pool), size=min(n_pilot, len(Q_pool)), replace=False)]
        meas, _ = measure_optical(real, Q, rng)
        commanded += len(Q)
        Y = np.concatenate([Y, meas.Y])
        P = np.concatenate([P, robot.poses(meas.Q, robot.frame_reflector)[0]])
        if len(Y) >= 3:
            return register_points(Y, P), commanded
    raise ValueError(f"{robot.name}: fewer than 3 of {commanded} pilot configurations were visible")


def calibrate_6d(mm: MeasurementModel, meas: ms.Measurements, orientation_sigma_rad: float,
                 basis: np.ndarray) -> Estimate:
    """Registration + Levenberg-Marquardt on the three marker points of every 6-D reading."""
    rec = ms.expand_orientation(meas, orientation_sigma_rad)
    return estimate(mm, rec.Q, rec.Y, rec.sigma_m, basis, rec.source, offsets=rec.offset_m)


@dataclass
class PoseErrors:
    """Held-out 6-D errors in the base frame: (N, 3) positions (m) and (N, 3) Cardan angles (rad)."""

    position_m: np.ndarray
    cardan_rad: np.ndarray

    def table(self) -> dict[str, dict[str, float]]:
        """Maximum |e| and half peak-to-peak per axis (paper 004 Table 2), plus RMS of |e_p|."""
        out: dict[str, dict[str, float]] = {}
        for name, e in (("x", self.position_m[:, 0]), ("y", self.position_m[:, 1]), ("z", self.position_m[:, 2]),
                        ("alpha", self.cardan_rad[:, 0]), ("beta", self.cardan_rad[:, 1]),
                        ("gamma", self.cardan_rad[:, 2])):
            out[name] = {"max_abs": float(np.abs(e).max()), "half_peak_to_peak": float(0.5 * (e.max() - e.min()))}
        norm = np.linalg.norm(self.position_m, axis=1)
        out["position"] = {"rms": float(np.sqrt(np.mean(norm ** 2))), "max": float(norm.max())}
        ang = Rotation.from_euler("XYZ", self.cardan_rad).magnitude()
        out["orientation"] = {"rms": float(np.sqrt(np.mean(ang ** 2))), "max": float(ang.max())}
        return out


def pose_errors(mm: MeasurementModel, x: np.ndarray, transform_camera_to_base: pin.SE3,
                meas: ms.Measurements) -> PoseErrors:
    """Errors of the 6-D readings against the model with parameters ``x`` and camera pose ``T``."""
    p_base, R_base = mm.base_positions(meas.Q, x)
    T = transform_camera_to_base
    y_base = meas.Y @ T.rotation.T + T.translation
    R_meas = np.einsum("ij,njk->nik", T.rotation, Rotation.from_rotvec(meas.rotvec).as_matrix())
    R_err = np.einsum("nij,nkj->nik", R_meas, R_base)
    return PoseErrors(y_base - p_base, Rotation.from_matrix(R_err).as_euler("XYZ"))


def heldout(robot: RobotModel, real, transform_camera_to_base: pin.SE3, n: int, rng: np.random.Generator,
            margins: inst.OpticalMargins = inst.NO_MARGINS) -> ms.Measurements:
    """``n`` random configurations predicted visible with the camera pose ``transform_camera_to_base``
    (nominal or identified), read on the hidden robot (visible rows kept, drawn until ``n``)."""
    chain = cd.chain_from_robot(robot)
    parts = []
    have = 0
    for _ in range(20):
        Q, _ = cd.random_candidates(chain, max(4 * (n - have), 200), rng, visibility=False)
        Q = Q[visible_mask(robot, Q, transform_camera_to_base, margins)]
        m, _ = measure_optical(real, Q, rng)
        parts.append(m)
        have += len(m)
        if have >= n:
            break
    cat = ms.Measurements(np.concatenate([p.Q for p in parts])[:n], np.concatenate([p.Y for p in parts])[:n],
                          np.concatenate([p.sigma_m for p in parts])[:n], "simulated optical tracker (held-out)",
                          np.concatenate([p.rotvec for p in parts])[:n])
    return cat
