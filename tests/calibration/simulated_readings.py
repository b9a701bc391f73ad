"""Simulated tracker readings of the RX130L for the calibration tests: the geometric parameter set and
readings at random configurations of the middle half of each joint range (a region a residual map
can cover), exact nominal model plus an optional smooth field and the tracker noise."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pipeline.calibration import error_model as em
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.robot.model import RobotModel

SIGMA_M = 10e-6


def rx130l_readings(n_poses: int, source: str, field_m: Callable[[np.ndarray], np.ndarray] | None = None,
                    seed: int = 7) -> tuple[RobotModel, em.MeasurementModel, np.ndarray, ms.Measurements,
                                            np.random.Generator]:
    """``(robot, measurement model, geometric basis, readings, the generator they were drawn from)``;
    ``field_m(Q)`` (N, 3, base frame) adds an error no kinematic parameter fits."""
    robot = RobotModel.load("rx130l")
    mm = em.MeasurementModel(robot)
    rng = np.random.default_rng(seed)
    _, basis = st.identify_parameter_set(robot, mm, st.Config(parameters="geometric"), rng)
    T = robot.tracker.transform_tracker_to_base
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    mid, half = 0.5 * (lo + hi), 0.25 * (hi - lo)
    Q = rng.uniform(mid - half, mid + half, (n_poses, robot.nq))
    Y = mm.predict(Q, np.zeros(mm.n), T) + SIGMA_M * rng.standard_normal((len(Q), 3))
    if field_m is not None:
        Y = Y + field_m(Q) @ T.rotation
    return robot, mm, basis, ms.Measurements(Q, Y, np.full(len(Q), SIGMA_M), source), rng
