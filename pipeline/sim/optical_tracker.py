"""Camera-based 6-D tracker: a probe of infrared diodes on the tool seen by several cameras.

Paper 004 §3.4 measured its calibration poses with the 3D-Creator (Boulder Innovation Group): "a
probe emitting infrared light by 4 diodes is mounted on the end-effector; this light is recorded by
three CCD cameras and the position and orientation in world coordinates are calculated by
stereovision"; configurations the system cannot see were removed from the candidate grid. The
sensor kind is declared by any robot.yaml (``optical_tracker``, :class:`OpticalTrackerSpec`); this
module is its physics:

- **visibility** of diode ``i`` by camera ``c`` (every test must hold): the diode lies inside the
  camera's field-of-view cone (half angle about the bar's +z axis), at a distance within
  ``range_m``, the camera lies inside the diode's emission cone (half angle about the probe's
  emission axis), and the sight line camera -> diode is clear of every link capsule (capsules of the
  probe's own rigid body, on the last joint, are left out: the probe is built so its diodes show past
  the tool). A diode's 3-D position needs all cameras (three linear CCDs each fix one plane); the
  pose needs ``min_diodes`` (>= 3, not collinear) such diodes.
- **reading**: every seen diode's camera-frame position plus isotropic Gaussian noise
  ``sigma_d = noise_const_m + noise_per_m * distance``; the pose (marker origin and rotation vector,
  the format of :mod:`pipeline.calibration.measure`) is the least-squares rigid fit (Kabsch) of the
  probe geometry to the seen diodes.
- **stated 6-D noise** (first order, the fit's covariance averaged over axes): with ``r_i`` the seen
  diodes about their centroid ``c`` and ``S = sum |r_i|^2``, orientation ``sigma_rad = sigma_d /
  sqrt(2 S / 3)`` per axis and origin ``sigma_m = sqrt(sigma_d^2 / n + 2/3 |c|^2 sigma_rad^2)``
  (the lever from the centroid to the marker origin). tests/robot/test_optical_tracker.py checks it
  against the scatter of simulated readings.

The visibility is a function of a robot model and a camera placement (:func:`optical_visibility`),
so planners use it with the nominal model and the real sensor with the hidden robot; the batched
core (:func:`diode_visibility`) takes world frames, so the candidate filter of millions of grid
configurations can call it with its own numpy kinematics.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pipeline.robot.collision import segment_distances
from pipeline.robot.model import RobotModel
from pipeline.robot.payload import Payload
from pipeline.robot.sensors import LinkSideSensor
from pipeline.robot.spec import OpticalTrackerSpec

#: sight lines are checked for blockage up to this distance before the diode (its holder)
SIGHT_END_CLEARANCE_M = 0.01


@dataclass(frozen=True)
class OpticalMargins:
    """Conservative margins of a *predicted* visibility (planning with the nominal model)."""

    angle_rad: float = 0.0      # off the field-of-view and emission half angles
    range_m: float = 0.0        # off both ends of the range
    occlusion_m: float = 0.0    # clearance of every sight line from every capsule


#: the sensor's own decision (no margin)
NO_MARGINS = OpticalMargins()


@dataclass
class OpticalVisibility:
    """Why configurations can or cannot be measured."""

    visible: np.ndarray   # (N,) bool: at least min_diodes diodes seen by every camera
    seen: np.ndarray      # (N, d) bool
    n_seen: np.ndarray    # (N,) int


@dataclass
class PoseReading:
    """6-D readings of the marker frame in the camera-bar frame; NaN where not visible."""

    position_m: np.ndarray   # (N, 3) marker origin
    rotvec: np.ndarray       # (N, 3) rotation vector of R (marker axes -> camera axes)
    visible: np.ndarray      # (N,) bool
    sigma_m: np.ndarray      # (N,) isotropic 1-sigma of the position (module docstring)
    sigma_rad: np.ndarray    # (N,) 1-sigma per axis of the orientation
    n_seen: np.ndarray       # (N,) diodes used


def probe_points(spec: OpticalTrackerSpec, origin: np.ndarray, R_marker: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """World diodes (N, d, 3) and emission axes (N, 3) of markers at ``origin`` (N, 3) with
    rotation ``R_marker`` (N, 3, 3) (the reflector frame: flange axes at the reflector offset)."""
    diodes = origin[:, None, :] + np.einsum("nij,dj->ndi", R_marker, spec.probe_diodes_m)
    return diodes, R_marker @ spec.diode_axis


def camera_centres(spec: OpticalTrackerSpec, transform_camera_to_base: pin.SE3) -> np.ndarray:
    """(k, 3) camera positions in the base frame."""
    T = transform_camera_to_base
    return spec.camera_positions_m @ T.rotation.T + T.translation


def diode_visibility(spec: OpticalTrackerSpec, transform_camera_to_base: pin.SE3, diodes: np.ndarray,
                     axis: np.ndarray, segments: np.ndarray, radii: np.ndarray, occluders: np.ndarray,
                     margins: OpticalMargins = NO_MARGINS) -> OpticalVisibility:
    """Batched visibility (module docstring) of world diodes (N, d, 3) with emission axes (N, 3);
    ``segments`` (N, nc, 2, 3) world capsule ends, ``occluders`` the capsule indices checked."""
    N, d = diodes.shape[:2]
    cams = camera_centres(spec, transform_camera_to_base)
    view = transform_camera_to_base.rotation[:, 2]
    cos_fov = np.cos(max(spec.field_of_view_half_angle_rad - margins.angle_rad, 0.0))
    cos_em = np.cos(max(spec.emission_half_angle_rad - margins.angle_rad, 0.0))
    lo, hi = spec.range_m[0] + margins.range_m, spec.range_m[1] - margins.range_m
    seen = np.ones((N, d), bool)
    for c in cams:
        v = diodes - c                                   # camera -> diode
        dist = np.linalg.norm(v, axis=2)
        u = v / np.maximum(dist, 1e-12)[..., None]
        ok = (u @ view >= cos_fov) & (dist >= lo) & (dist <= hi)
        ok &= -np.einsum("ndi,ni->nd", u, axis) >= cos_em
        idx = np.argwhere(ok & seen)
        if idx.size and len(occluders):
            end = diodes[idx[:, 0], idx[:, 1]] - SIGHT_END_CLEARANCE_M * u[idx[:, 0], idx[:, 1]]
            start = np.broadcast_to(c, end.shape)
            for k in occluders:
                seg = segments[idx[:, 0], k]
                gap = segment_distances(start, end, seg[:, 0], seg[:, 1]) - radii[k]
                ok[idx[gap < margins.occlusion_m, 0], idx[gap < margins.occlusion_m, 1]] = False
        seen &= ok
    n_seen = seen.sum(axis=1)
    return OpticalVisibility(n_seen >= spec.min_diodes, seen, n_seen)


def probe_occluders(robot: RobotModel) -> np.ndarray:
    """Indices of the capsules that can hide a diode: all but those of the probe's rigid body
    (capsules whose frame hangs on the last joint, like the flange)."""
    model = robot.model
    last = model.frames[robot.frame_id(robot.frame_flange)].parentJoint
    return np.array([k for k, c in enumerate(robot.capsules)
                     if model.frames[robot.frame_id(c.frame)].parentJoint != last], int)


def optical_visibility(robot: RobotModel, transform_camera_to_base: pin.SE3, Q: np.ndarray,
                       margins: OpticalMargins = NO_MARGINS,
                       spec: OpticalTrackerSpec | None = None) -> OpticalVisibility:
    """Visibility of configurations ``Q`` of ``robot`` (Pinocchio kinematics) for the cameras at
    ``transform_camera_to_base`` (the robot's declared tracker unless ``spec`` is given)."""
    spec = spec if spec is not None else _spec_of(robot)
    Q = np.atleast_2d(np.asarray(Q, float))
    origin, R_marker = robot.poses(Q, robot.frame_reflector)
    diodes, axis = probe_points(spec, origin, R_marker)
    radii = np.array([c.radius_m for c in robot.capsules])
    return diode_visibility(spec, transform_camera_to_base, diodes, axis, robot.capsule_segments(Q), radii,
                            probe_occluders(robot), margins)


def stated_sigmas(spec: OpticalTrackerSpec, seen: np.ndarray, sigma_diode_m: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``(sigma_m, sigma_rad)`` of each pose from the diodes it used (module docstring)."""
    w = np.asarray(seen, float)
    n = np.maximum(w.sum(axis=1), 1.0)
    centroid = (w @ spec.probe_diodes_m) / n[:, None]
    r = spec.probe_diodes_m[None] - centroid[:, None]
    S = np.einsum("nd,ndi,ndi->n", w, r, r)
    sigma_rad = sigma_diode_m / np.sqrt(np.maximum(2.0 * S / 3.0, 1e-300))
    lever2 = np.einsum("ni,ni->n", centroid, centroid)
    sigma_m = np.sqrt(sigma_diode_m ** 2 / n + 2.0 / 3.0 * lever2 * sigma_rad ** 2)
    return sigma_m, sigma_rad


def fit_poses(model_points: np.ndarray, measured: np.ndarray, weights: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Weighted rigid fits ``measured ~ R model + t`` (Kabsch, batched): ``R`` (N, 3, 3), ``t`` (N, 3)."""
    w = np.asarray(weights, float)
    n = np.maximum(w.sum(axis=1), 1e-300)[:, None]
    a_bar = (w @ model_points) / n
    b_bar = np.einsum("nd,ndi->ni", w, measured) / n
    A = model_points[None] - a_bar[:, None]
    B = measured - b_bar[:, None]
    H = np.einsum("nd,ndi,ndj->nij", w, A, B)
    U, _, Vt = np.linalg.svd(H)
    D = np.ones((len(H), 3))
    D[:, 2] = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))
    R = np.einsum("nji,nj,nkj->nik", Vt, D, U)
    return R, b_bar - np.einsum("nij,nj->ni", R, a_bar)


def _spec_of(robot: RobotModel) -> OpticalTrackerSpec:
    spec = robot.spec.optical_tracker
    if spec is None:
        raise ValueError(f"{robot.name}: robot.yaml declares no optical_tracker")
    return spec


class OpticalTracker(LinkSideSensor):
    """The optical 6-D tracker at a fixed (unknown to the stages) camera pose, measuring the probe."""

    def __init__(self, robot: RobotModel, transform_camera_to_base: pin.SE3,
                 link_angles: Callable[[np.ndarray, Payload | None], np.ndarray] | None = None) -> None:
        self._robot = robot
        self._transform_camera_to_base = transform_camera_to_base
        self._link_angles = link_angles
        self.spec = _spec_of(robot)

    def visible(self, Q: np.ndarray, payload: Payload | None = None) -> np.ndarray:
        """Whether each configuration can be measured (``min_diodes`` diodes seen by every camera)."""
        return optical_visibility(self._robot, self._transform_camera_to_base, self._link(Q, payload)).visible

    def measure(self, Q: np.ndarray, rng: np.random.Generator, payload: Payload | None = None) -> PoseReading:
        """6-D readings at commanded angles ``Q``; invisible rows NaN. Noise is drawn for every diode
        of every row, so a row's noise does not depend on which others are visible."""
        Q = self._link(Q, payload)
        spec, robot, T = self.spec, self._robot, self._transform_camera_to_base
        vis = optical_visibility(robot, T, Q, spec=spec)
        origin, R_marker = robot.poses(Q, robot.frame_reflector)
        diodes, _ = probe_points(spec, origin, R_marker)
        inv = T.inverse()
        in_bar = diodes @ inv.rotation.T + inv.translation
        sigma_d = spec.noise_const_m + spec.noise_per_m * np.linalg.norm(origin @ inv.rotation.T + inv.translation,
                                                                         axis=1)
        noisy = in_bar + sigma_d[:, None, None] * rng.standard_normal(in_bar.shape)
        weights = np.where(vis.visible[:, None], vis.seen, True)
        R, t = fit_poses(spec.probe_diodes_m, noisy, weights)
        sigma_m, sigma_rad = stated_sigmas(spec, weights, sigma_d)
        position, rotvec = t, Rotation.from_matrix(R).as_rotvec()
        position[~vis.visible] = np.nan
        rotvec[~vis.visible] = np.nan
        return PoseReading(position, rotvec, vis.visible, sigma_m, sigma_rad, vis.n_seen)
