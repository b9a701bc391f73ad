"""What the calibration stage computed (stage, studies, notebook and the report share it)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.calibration import candidates as cd
from pipeline.calibration import design as ds
from pipeline.calibration import error_model as em
from pipeline.calibration import measure as ms
from pipeline.calibration.estimate import Estimate
from pipeline.calibration.gradient_design import GradientDesignResult
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
