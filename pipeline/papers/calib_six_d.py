"""Simulated 6-D readings of a motion-capture system (or a 6-DOF tracker probe) on the hidden robot.

A reading of configuration ``q`` is the pose of the marker frame (= the reflector frame of
robot.yaml: flange orientation, at the reflector offset) of the deflected arm
(``RealRobot.link_angles``: joint elasticity, gear error), in the frame of the measuring system
(the hidden tracker placement ``T_tb``, base = ``T_tb`` tracker):

- position ``y = T_tb^-1 p + n_p``, ``n_p ~ N(0, sigma_p^2 I)`` (m);
- orientation ``R_meas = R_tb^T R exp(w^)``, ``w ~ N(0, sigma_rot^2 I)`` (rad, marker frame: a
  right-multiplied small rotation), written as the rotation vector ``r`` with
  ``R_meas = exp(r^)`` (axis * angle, scipy ``Rotation.from_rotvec``), which maps marker-frame
  axes to measurement-frame axes: the CSV convention of :mod:`pipeline.calibration.measure`.

The defaults, ``sigma_p`` = 0.1 mm and ``sigma_rot`` = 1 mrad per axis, are a stated order of
magnitude for a marker cluster of a few hundred mm seen by an optical motion-capture system (not a
vendor's figure); paper 004 §3.4 calibrated with an optical 6-D tracker of this class. What such a
record can give is measured by ``benchmarks/bench_six_d.py``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.calibration import candidates as cd
from pipeline.calibration.config import Config
from pipeline.calibration.measure import Measurements, write_csv
from pipeline.calibration.outcome import CalibrationOutcome
from pipeline.calibration.stage import calibrate
from pipeline.robot.model import RobotModel


def simulate_six_d_record(real, Q: np.ndarray, rng: np.random.Generator, position_sigma_m: float = 1e-4,
                          orientation_sigma_rad: float = 1e-3, source: str = "simulated mocap") -> Measurements:
    """6-D readings (module docstring) of the hidden robot ``real`` at commanded angles ``Q``;
    every pose is seen (no visibility model). Zero sigmas give the exact poses."""
    Q = np.atleast_2d(np.asarray(Q, float))
    P, R = real.truth.poses(real.link_angles(Q), "reflector")
    T = real.transform_tracker_to_base.inverse()
    Y = P @ T.rotation.T + T.translation + position_sigma_m * rng.standard_normal(P.shape)
    noise = Rotation.from_rotvec(orientation_sigma_rad * rng.standard_normal((len(Q), 3)))
    rotvec = (Rotation.from_matrix(np.einsum("ij,njk->nik", T.rotation, R)) * noise).as_rotvec()
    return Measurements(Q, Y, np.full(len(Q), float(position_sigma_m)), source, rotvec, len(Q))


@dataclass
class SixDTrial:
    """One simulated 6-D calibration: the stage's outcome and the records it was given."""

    outcome: CalibrationOutcome
    config: Config
    fit: Measurements          # the noisy 6-D record fitted
    validation: Measurements   # exact held-out poses

    @property
    def gains(self) -> dict[str, float]:
        """Held-out RMS before / after (m, rad) and their ratios (position and orientation)."""
        v = self.outcome.validation
        b, a = v["before"], v["after"]
        bo, ao = b["orientation_rad"], a["orientation_rad"]
        return {"position_before_m": b["rms"], "position_after_m": a["rms"], "position_gain": b["rms"] / a["rms"],
                "orientation_before_rad": bo["rms"], "orientation_after_rad": ao["rms"],
                "orientation_gain": bo["rms"] / ao["rms"],
                "orientation_predicted_rad": ao.get("predicted_model_rms", float("nan"))}


def six_d_trial(robot: RobotModel, real, n_poses: int, rng: np.random.Generator, folder: str | Path,
                position_sigma_m: float = 1e-4, orientation_sigma_rad: float = 1e-3, n_validation: int = 200,
                **config: Any) -> SixDTrial:  # Any: settings of the calibration section, checked by Config
    """Calibrate ``all`` parameters from ``n_poses`` random 6-D readings of ``real``
    (:func:`simulate_six_d_record`, written to ``folder/fit.csv`` and read back as a user file) and
    validate on ``n_validation`` exact poses (``folder/validation.csv``: the nominal orientation
    error is only a few times a mocap's noise, so the gain is measured against the true poses);
    ``config``: further :class:`pipeline.calibration.config.Config` fields."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    chain = cd.chain_from_robot(robot)
    fit = simulate_six_d_record(real, cd.random_candidates(chain, n_poses, rng, visibility=False)[0], rng,
                                position_sigma_m, orientation_sigma_rad)
    val = simulate_six_d_record(real, cd.random_candidates(chain, n_validation, rng, visibility=False)[0], rng,
                                0.0, 0.0, "exact poses")
    config.setdefault("parameters", "all")
    cfg = Config(measurements_csv=str(write_csv(folder / "fit.csv", fit)), figures=False,
                 validation_csv=str(write_csv(folder / "validation.csv", val)), position_sigma_m=position_sigma_m,
                 orientation_sigma_rad=orientation_sigma_rad, **config)
    cfg.validate()
    return SixDTrial(calibrate(robot, None, cfg, rng), cfg, fit, val)
