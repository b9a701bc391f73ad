"""Camera-based 6-D tracker: a probe of infrared diodes on the tool seen by several cameras.

Paper 004 §3.4 measured its calibration poses with the 3D-Creator (Boulder Innovation Group): "a
probe emitting infrared light by 4 diodes is mounted on the end-effector; this light is recorded by
three CCD cameras and the position and orientation in world coordinates are calculated by
stereovision"; configurations the system cannot see were removed from the candidate grid. The
sensor kind is declared by any robot.yaml (``optical_tracker``, :class:`OpticalTrackerSpec`); this
module is its physics:

- **visibility** of the diodes (field of view, range, emission cone, sight lines clear of the
  capsules; :func:`pipeline.robot.instruments.optical_visibility`).
- **reading**: every seen diode's camera-frame position plus isotropic Gaussian noise
  ``sigma_d = noise_const_m + noise_per_m * distance``; the pose (marker origin and rotation vector,
  the format of :mod:`pipeline.calibration.measure`) is the least-squares rigid fit (Kabsch) of the
  probe geometry to the seen diodes.
- **stated 6-D noise**: :func:`pipeline.robot.instruments.stated_sigmas` of the diodes used;
  tests/sim/test_optical_tracker.py checks it against the scatter of simulated readings.

The visibility and the stated noise are functions of a robot model and a camera placement
(:mod:`pipeline.robot.instruments`), so planners use them with the nominal model and this sensor
with the hidden robot.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pipeline.robot.instruments import optical_spec, optical_visibility, probe_points, stated_sigmas
from pipeline.robot.model import RobotModel
from pipeline.robot.payload import Payload
from pipeline.sim.sensors import LinkSideSensor


@dataclass
class PoseReading:
    """6-D readings of the marker frame in the camera-bar frame; NaN where not visible."""

    position_m: np.ndarray   # (N, 3) marker origin
    rotvec: np.ndarray       # (N, 3) rotation vector of R (marker axes -> camera axes)
    visible: np.ndarray      # (N,) bool
    sigma_m: np.ndarray      # (N,) isotropic 1-sigma of the position (module docstring)
    sigma_rad: np.ndarray    # (N,) 1-sigma per axis of the orientation
    n_seen: np.ndarray       # (N,) diodes used


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


class OpticalTracker(LinkSideSensor):
    """The optical 6-D tracker at a fixed (unknown to the stages) camera pose, measuring the probe."""

    def __init__(self, robot: RobotModel, transform_camera_to_base: pin.SE3,
                 link_angles: Callable[[np.ndarray, Payload | None], np.ndarray] | None = None) -> None:
        self._robot = robot
        self._transform_camera_to_base = transform_camera_to_base
        self._link_angles = link_angles
        self.spec = optical_spec(robot)

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
