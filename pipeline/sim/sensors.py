"""Simulated sensors of the real robot: laser tracker, joint encoders, motor-torque measurement.

Noise facts (DESIGN.md, "Sensors"):
- laser tracker: reflector position, isotropic sigma = 8 µm + 3 µm per metre of range, only
  if the incidence angle between the reflector axis and the beam is <= 30 deg and no link
  capsule blocks the beam (paper 000 §2, tracker and incidence constraint);
- the arm's repeatability (robot.yaml ``repeatability_m``, ISO 9283 RP; none without it): an
  isotropic scatter of RP / 3.616 per axis of the reflector at each commanded pose
  (:mod:`pipeline.robot.repeatability`), drawn after the tracker noise;
- encoders: sigma about 2 µrad joint side;
- motor torque from current: sigma about 1 % of the torque limit;
- gross tracker errors (:class:`GrossErrors`, all 0 by default here): a rate of readings off by
  millimetres in a random direction, and a rate of stale readings repeating the previous one.

The tracker sees the link-side pose: ``link_angles(Q, payload)`` maps the commanded (encoder)
angles to the deflected arm's angles (joint elasticity, transmission error; the identity for the
ideal robot).

What the tracker can see (incidence, beam blockage) is
:func:`pipeline.robot.instruments.tracker_visibility`, shared with the planners.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pipeline.robot.instruments import tracker_visibility
from pipeline.robot.model import RobotModel
from pipeline.robot.payload import Payload
from pipeline.robot.repeatability import repeatability_sigma_m


@dataclass
class TrackerReading:
    """Tracker measurements of the reflector in the TRACKER frame; NaN where not visible."""

    position_m: np.ndarray  # (N, 3)
    visible: np.ndarray  # (N,) bool
    sigma_m: np.ndarray  # (N,) isotropic 1-sigma noise of each reading
    #: tests only: readings given a gross error (outlier or stale); None when none can occur
    corrupted: np.ndarray | None = None


@dataclass(frozen=True)
class GrossErrors:
    """Gross tracker errors: outlier rate and magnitude (m), stale-reading rate (0 -> none)."""

    outlier_rate: float = 0.0
    outlier_magnitude_m: float = 0.0
    stale_rate: float = 0.0

    def apply(self, positions: np.ndarray, visible: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
        """Corrupt ``positions`` in place; returns the corrupted mask (None if both rates are 0).

        Outliers: ``y + magnitude * u`` with ``u`` a random unit vector. Stale: the previous visible
        reading repeated (the tracker kept its last value after the beam was blocked)."""
        if self.outlier_rate == 0.0 and self.stale_rate == 0.0:
            return None
        n = len(positions)
        outlier = (rng.random(n) < self.outlier_rate) & visible
        u = rng.standard_normal((n, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        positions[outlier] += self.outlier_magnitude_m * u[outlier]
        stale = (rng.random(n) < self.stale_rate) & visible
        previous = -1
        for k in range(n):
            if not visible[k]:
                continue
            if stale[k] and previous >= 0:
                positions[k] = positions[previous]
            else:
                stale[k] = False
            previous = k
        return outlier | stale


class LinkSideSensor:
    """A sensor that looks at the links: it reads the link-side joint angles of the commanded encoder
    angles ``Q`` (``link_angles(Q, payload)``: joint elasticity, gear error; None: the same)."""

    _link_angles: Callable[[np.ndarray, Payload | None], np.ndarray] | None = None

    def _link(self, Q: np.ndarray, payload: Payload | None) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, float))
        return Q if self._link_angles is None else self._link_angles(Q, payload)


class LaserTracker(LinkSideSensor):
    """A laser tracker at a fixed (unknown to the stages) pose, measuring the reflector."""

    def __init__(self, robot: RobotModel, transform_tracker_to_base: pin.SE3,
                 link_angles: Callable[[np.ndarray, Payload | None], np.ndarray] | None = None,
                 gross: GrossErrors | None = None,
                 reflector_positions: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        self._robot = robot
        #: where the reflector is at link angles Q (N, 3), base frame; default the robot model's kinematics
        self._reflector_positions = reflector_positions
        self._transform_tracker_to_base = transform_tracker_to_base
        self._link_angles = link_angles
        self._gross = gross if gross is not None else GrossErrors()
        self.noise_const_m = robot.tracker.noise_const_m
        self.noise_per_m = robot.tracker.noise_per_m
        self.max_incidence_rad = robot.tracker.max_incidence_rad
        #: the arm's own scatter at a commanded pose, 1-sigma per axis (robot.yaml repeatability_m)
        self.repeatability_sigma_m = repeatability_sigma_m(robot.spec.repeatability_m or 0.0)

    def visible(self, Q: np.ndarray, payload: Payload | None = None) -> np.ndarray:
        """Whether each configuration can be measured (incidence and beam blockage)."""
        return tracker_visibility(self._robot, self._transform_tracker_to_base, self._link(Q, payload)).visible

    def measure(self, Q: np.ndarray, rng: np.random.Generator, payload: Payload | None = None) -> TrackerReading:
        """Reflector positions in the tracker frame with range-dependent isotropic noise.

        ``Q`` are the commanded (encoder) angles, ``payload`` what is mounted on the flange.
        Invisible configurations give NaN rows. Noise is drawn for every row (visible or not)
        so the noise of a configuration does not depend on which others are visible; gross
        errors (:class:`GrossErrors`) are drawn after it.
        """
        Q = self._link(Q, payload)
        vis = tracker_visibility(self._robot, self._transform_tracker_to_base, Q)
        positions_base = (self._robot.positions(Q, self._robot.frame_reflector) if self._reflector_positions is None
                          else self._reflector_positions(Q))
        base_to_tracker = self._transform_tracker_to_base.inverse()
        positions = positions_base @ base_to_tracker.rotation.T + base_to_tracker.translation
        sigma = self.noise_const_m + self.noise_per_m * vis.range_m
        positions = positions + sigma[:, None] * rng.standard_normal(positions.shape)
        if self.repeatability_sigma_m > 0:   # the arm stops a little elsewhere each time (drawn only then)
            positions = positions + self.repeatability_sigma_m * rng.standard_normal(positions.shape)
        corrupted = self._gross.apply(positions, vis.visible, rng)
        positions[~vis.visible] = np.nan
        return TrackerReading(positions, vis.visible, sigma, corrupted)


class Encoders:
    """Joint-side encoders: Gaussian noise of ``noise_rad`` (and optional quantisation)."""

    def __init__(self, noise_rad: float, resolution_rad: float = 0.0) -> None:
        self.noise_rad = float(noise_rad)
        self.resolution_rad = float(resolution_rad)

    def read(self, q_true: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        q = np.asarray(q_true, float) + self.noise_rad * rng.standard_normal(np.shape(q_true))
        if self.resolution_rad > 0:
            q = np.round(q / self.resolution_rad) * self.resolution_rad
        return q


class TorqueSensor:
    """Joint torques from motor currents: ``tau + N(0, sigma_i)``, sigma_i a fraction of the limit."""

    def __init__(self, sigma_Nm: np.ndarray) -> None:
        self.sigma_Nm = np.asarray(sigma_Nm, float)

    def read(self, tau_true: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        tau = np.asarray(tau_true, float)
        return tau + self.sigma_Nm * rng.standard_normal(tau.shape)
