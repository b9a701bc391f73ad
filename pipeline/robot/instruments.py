"""What the measuring instruments can see, from the nominal geometry: the laser tracker's beam and
the optical 6-D tracker's diodes, and the optical tracker's stated noise.

Planners (the calibration stage) call these with the nominal model and the estimated instrument
pose; the simulated sensors (:mod:`pipeline.sim.sensors`, :mod:`pipeline.sim.optical_tracker`)
call the same functions with the hidden robot.

- **laser tracker** (paper 000 §2, tracker and incidence constraint): the reflector is seen if the
  incidence angle between the reflector axis and the beam is <= ``max_incidence_rad`` (30 deg) and
  no link capsule blocks the beam (:func:`tracker_visibility`).
- **optical tracker** (paper 004 §3.4): diode ``i`` is seen by camera ``c`` if it lies inside the
  camera's field-of-view cone (half angle about the bar's +z axis), at a distance within
  ``range_m``, the camera lies inside the diode's emission cone (half angle about the probe's
  emission axis), and the sight line camera -> diode is clear of every link capsule (capsules of the
  probe's own rigid body, on the last joint, are left out: the probe is built so its diodes show past
  the tool). A diode's 3-D position needs all cameras (three linear CCDs each fix one plane); the
  pose needs ``min_diodes`` (>= 3, not collinear) such diodes (:func:`optical_visibility`; the
  batched core :func:`diode_visibility` takes world frames, so the candidate filter of millions of
  grid configurations can call it with its own numpy kinematics).
- **stated 6-D noise** of the optical tracker (first order, the fit's covariance averaged over
  axes): with ``r_i`` the seen diodes about their centroid ``c`` and ``S = sum |r_i|^2``,
  orientation ``sigma_rad = sigma_d / sqrt(2 S / 3)`` per axis and origin
  ``sigma_m = sqrt(sigma_d^2 / n + 2/3 |c|^2 sigma_rad^2)`` (the lever from the centroid to the
  marker origin; :func:`stated_sigmas`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.robot.collision import segment_distances
from pipeline.robot.model import RobotModel
from pipeline.robot.spec import OpticalTrackerSpec

#: the beam is checked for blockage up to this distance before the reflector (its holder)
BEAM_END_CLEARANCE_M = 0.02


@dataclass
class Visibility:
    """Why a configuration can or cannot be measured."""

    visible: np.ndarray  # (N,) bool
    incidence_rad: np.ndarray  # (N,)
    beam_clearance_m: np.ndarray  # (N,) smallest capsule clearance to the beam (negative: blocked)
    range_m: np.ndarray  # (N,)


def tracker_visibility(robot: RobotModel, transform_tracker_to_base: pin.SE3, Q: np.ndarray,
                       max_incidence_rad: float | None = None) -> Visibility:
    """Incidence angle, beam blockage and range of the reflector seen from the tracker.

    Incidence: angle between the reflector's opening axis (``robot.reflector_axis`` in the
    flange frame, rotated to the base) and the direction reflector -> tracker. Blockage: the
    beam segment (tracker -> a point ``BEAM_END_CLEARANCE_M`` before the reflector) against
    every link capsule.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    max_incidence = robot.tracker.max_incidence_rad if max_incidence_rad is None else max_incidence_rad
    positions, rotations = robot.poses(Q, robot.frame_reflector)
    tracker_position = transform_tracker_to_base.translation
    beam = tracker_position - positions
    range_m = np.linalg.norm(beam, axis=1)
    direction = beam / range_m[:, None]
    axis_world = rotations @ robot.reflector_axis
    incidence = np.arccos(np.clip(np.einsum("ij,ij->i", axis_world, direction), -1.0, 1.0))
    segments = robot.capsule_segments(Q)
    radii = np.array([c.radius_m for c in robot.capsules])
    beam_end = positions + BEAM_END_CLEARANCE_M * direction
    start = np.broadcast_to(tracker_position, beam_end.shape)
    clearance = segment_distances(start[:, None, :], beam_end[:, None, :], segments[:, :, 0], segments[:, :, 1])
    clearance = (clearance - radii).min(axis=1) if radii.size else np.full(len(Q), np.inf)
    visible = (incidence <= max_incidence) & (clearance > 0.0)
    return Visibility(visible, incidence, clearance, range_m)


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
    spec = spec if spec is not None else optical_spec(robot)
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


def optical_spec(robot: RobotModel) -> OpticalTrackerSpec:
    """The robot's declared optical tracker (robot.yaml ``optical_tracker``); ValueError if none."""
    spec = robot.spec.optical_tracker
    if spec is None:
        raise ValueError(f"{robot.name}: robot.yaml declares no optical_tracker")
    return spec
