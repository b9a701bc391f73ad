"""What the calibration stage computed (stage, studies, notebook and the report share it), and
what its steps hand each other (:mod:`pipeline.calibration.stage`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import error_model as em
from pipeline.calibration import indices as ix
from pipeline.calibration import measure as ms
from pipeline.calibration import noise_model as nm
from pipeline.calibration.config import Config
from pipeline.calibration.estimate import Estimate
from pipeline.calibration.gradient_design import GradientDesignResult
from pipeline.calibration.gravity_uncertainty import GravityCovariance
from pipeline.calibration.robust import Rejection
from pipeline.robot.model import RobotModel


@dataclass
class CalibrationOutcome:
    """Everything the stage computed (also used by studies and the notebook)."""

    report: em.IdentifiabilityReport
    names: list[str]
    candidates: cd.CandidateSet | None
    selection: ds.SelectionResult | None
    measurements: ms.Measurements
    estimate: Estimate
    validation: dict | None         # None: no held-out validation (measurement file, no validation file)
    robot: RobotModel
    timings_s: dict[str, float]
    gradient: GradientDesignResult | None = None
    working_Q: np.ndarray | None = None
    #: index of the configurations actually measured (``method`` "user file" for a measurement file)
    measured_design: dict | None = None
    #: in-sample fit residuals (:func:`pipeline.calibration.validate.fit_residuals`)
    fit: dict | None = None
    #: covariance-predicted error over random visible poses (only when there is no held-out set)
    prediction: dict | None = None
    #: readings rejected by the outlier test (pipeline.calibration.robust)
    rejection: Rejection | None = None
    #: extra report sections (e.g. the comparison with the geometric-only fit)
    notes: dict = field(default_factory=dict)
    #: the chosen design against baselines of the same size (pipeline.calibration.design_table)
    design_table: dict | None = None


@dataclass
class UserRecords:
    """The user's tracker files (None: none given, the readings are simulated)."""

    measurements: ms.Measurements | None
    validation: ms.Measurements | None
    #: 6-D readings fitted as marker points (calibration.use_orientation)
    six_d: bool


@dataclass
class ModelSetUp:
    """The measurement model and its identifiable parameters ``x = basis theta``."""

    #: the section, with the parameter subset the model selection chose
    cfg: Config
    mm: em.MeasurementModel
    report: em.IdentifiabilityReport
    basis: np.ndarray
    #: the pose design's basis (:func:`pipeline.calibration.elastostatic.design_basis`)
    design_basis: np.ndarray
    #: the robot of calibration.gravity_model (None: none given)
    upstream_gravity: RobotModel | None


@dataclass
class Design:
    """The configurations chosen for measuring from the candidate set."""

    candidates: cd.CandidateSet
    spec: ix.IndexSpec
    working_Q: np.ndarray | None
    selection: ds.SelectionResult
    #: the pilot measurement of the gradient design (None: no gradient design)
    pilot: ms.Measurements | None
    #: the configurations to measure (after the gradient refinement)
    Q: np.ndarray
    gradient: GradientDesignResult | None


@dataclass
class Fit:
    """The robust fit with the noise model and the readings it was fitted to."""

    record: ms.Measurements
    gravity: GravityCovariance
    estimate: Estimate
    rejection: Rejection
    noise: nm.NoiseModel
