"""What the calibration stage computed (stage, studies, notebook and the report share it), and
what its steps hand each other (:mod:`pipeline.calibration.stage`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

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
from pipeline.calibration.selection_scores import ModelSelection
from pipeline.robot.handoff import ElastostaticRecord
from pipeline.robot.model import RobotModel
from pipeline.robot.residual_map import ResidualMap


@dataclass
class CalibrationNotes:
    """What the stage's steps record beside the fit for the report, the summary and the arrays
    (:mod:`pipeline.calibration.stage` fills it step by step; None: the step did not run or found nothing)."""

    #: ``R_m``, the marker's rotation on the flange (3, 3) of 6-D readings
    #: (:func:`pipeline.calibration.marker_frame.align_records`)
    marker_rotation_on_flange: np.ndarray | None = None
    #: the parameter subset chosen on a measurement file
    #: (:func:`pipeline.calibration.model_selection.choose_parameters`)
    model_selection: ModelSelection | None = None
    #: parameters the feasible configurations cannot identify, dropped before the design (``ModelSetUp.dropped``:
    #: :class:`pipeline.calibration.design_identifiable.DroppedParameter`, which imports this module)
    design_dropped: list = field(default_factory=list)
    #: the fitted rows of 6-D readings (three per pose; None: the measurements themselves)
    fit_record: ms.Measurements | None = None
    noise_model: nm.NoiseModel | None = None
    #: the Gaussian-process map of the fit residuals handed on to later stages
    residual_map: ResidualMap | None = None
    #: the map's noise floor from the readings' known noise (measurement file only)
    residual_map_floor_m: float | None = None
    #: k-fold cross-validation figures of a measurement file (pipeline.calibration.crossval)
    cross_validation: dict[str, Any] | None = None
    #: second pass with the upstream gravity model (:func:`pipeline.calibration.elastostatic.gravity_pass`)
    gravity_pass: dict[str, Any] | None = None
    #: static torques for later gravity models (elastostatic model only)
    static_torques: ElastostaticRecord | None = None
    #: the held-out configurations (n, nq), drawn by the viewer
    heldout_configurations: np.ndarray | None = None


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
    #: what the steps recorded beside the fit (model selection, residual map, cross-validation, ...)
    notes: CalibrationNotes = field(default_factory=CalibrationNotes)
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
    #: parameters the feasible configurations cannot identify, dropped before the design
    #: (:class:`pipeline.calibration.design_identifiable.DroppedParameter`)
    dropped: list = field(default_factory=list)


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
