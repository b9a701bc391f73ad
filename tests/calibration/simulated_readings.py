"""Simulated tracker readings for the calibration tests: the RX130L's geometric parameter set and
readings at random configurations of the middle half of each joint range (a region a residual map
can cover), exact nominal model plus an optional smooth field and the tracker noise; and a recorded
pair of files of a soft hidden arm."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import error_model as em
from pipeline.calibration import measure as ms
from pipeline.calibration import stage as st
from pipeline.calibration.outcome import Fit, ModelSetUp
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot, TruthConfig

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


#: the soft hidden arm's joints, times the compliance its robot.yaml states
SOFT_COMPLIANCE_SCALE = 5.0


def soft_arm_record(robot_name: str, seed: int, folder: Path, transmission_error_rad: float
                    ) -> tuple[RobotModel, st.Config, RealRobot]:
    """``(robot, calibration settings, hidden arm)``: 300 recorded readings and 100 held-out ones
    (:func:`pipeline.calibration.measure.write_simulated_record`) at random feasible configurations of a hidden arm
    :data:`SOFT_COMPLIANCE_SCALE` times as compliant as stated (the inertias 15 % / 20 mm off, a cyclic
    transmission error of the given amplitude), the settings reading them with every parameter."""
    robot = RobotModel.load(robot_name)
    real = RealRobot.create(robot, seed, TruthConfig(joint_compliance_scale=SOFT_COMPLIANCE_SCALE,
                                                     transmission_error_amplitude_rad=transmission_error_rad))
    rng = np.random.default_rng(seed)
    Q, _ = cd.random_candidates(cd.chain_from_robot(robot), 400, rng)
    fit, validation = ms.write_simulated_record(real, Q[:300], Q[300:], folder, rng)
    return robot, st.Config(measurements_csv=str(fit), validation_csv=str(validation), parameters="all"), real


def fitted_record(robot: RobotModel, cfg: st.Config, seed: int) -> tuple[ModelSetUp, Fit, ms.Measurements]:
    """The stage's model set-up and fit of the measurement file of ``cfg`` (before any validation),
    and the readings fitted."""
    rng = np.random.default_rng(seed)
    records, notes = st.read_records(robot, cfg)
    model = st.set_up_model(robot, cfg, records, rng, notes)
    return model, st.fit_model(robot, model, records, records.measurements, rng, notes), records.measurements
