"""Configuration of stage ``calibration`` (section ``calibration:`` of the run YAML).

Robot-independent checks in :meth:`Config.validate` (called at load time); the ones that need the
robot (the number of identifiable parameters, the tracker's incidence limit) in
:func:`check_robot_fields` and :func:`check_design_size`, which :func:`pipeline.calibration.stage.check` calls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal, get_args

from pipeline.calibration import indices as ix
from pipeline.calibration.gravity_uncertainty import GravityPrior
from pipeline.calibration.robust import Loss
from pipeline.calibration.subsets import check_parameters
from pipeline.calibration.task_space import check_task_fields
from pipeline.core.errors import ConfigError
from pipeline.core.typed_config import FileInput, check_choices
from pipeline.robot.iso_search import POSE_AXES
from pipeline.robot.model import RobotModel
from pipeline.robot.payload import Payload

#: values per axis of the paper's 6-axis grid (paper 004 §3: 13⁶ configurations)
GRID_VALUES_PAPER = 13

SelectionMethod = Literal["remove_and_replace", "detmax", "bsaa", "random", "gradient"]
SELECTION_METHODS: tuple[SelectionMethod, ...] = get_args(SelectionMethod)
#: start of remove-and-replace: the rounded optimal approximate design (pipeline.calibration.design_rounding)
#: or paper 004's random regular subset
DesignStart = Literal["approximate", "random"]
CandidateKind = Literal["grid", "random"]
ErrorModel = Literal["se3", "mdh_hayati"]
DESIGN_STARTS: tuple[DesignStart, ...] = get_args(DesignStart)
CANDIDATE_KINDS: tuple[CandidateKind, ...] = get_args(CandidateKind)
ERROR_MODELS: tuple[ErrorModel, ...] = get_args(ErrorModel)
#: indices the gradient design (IPOPT) can optimise
GRADIENT_INDICES = ix.TRACE_INDICES
#: largest candidate set (random candidates or grid points): beyond it the filtering and the
#: whitened Jacobians of the feasible candidates take too much time and memory
MAX_CANDIDATES = 20_000_000
#: calibration.second_pass values (pipeline.run.second_pass)
SecondPassMode = Literal["auto", "always", "never"]
SECOND_PASS_MODES: tuple[SecondPassMode, ...] = get_args(SecondPassMode)


@dataclass
class Config:
    """Settings of the calibration stage (defaults = the full profile)."""

    #: "grid" (``grid_per_axis`` values per axis, paper 004: 13) or "random"
    candidates: CandidateKind = "grid"
    #: None: derived from the number of axes (:meth:`grid_points_per_axis`)
    grid_per_axis: int | None = None
    n_random_candidates: int = 20000
    #: remove_and_replace | detmax | bsaa | random | gradient (remove-and-replace + IPOPT refinement)
    selection_method: SelectionMethod = "remove_and_replace"
    #: O1..O5, D, A, E, Od, Oc, tcp_A, tcp_A_mixed, V (see pipeline.calibration.indices); V: the
    #: predicted TCP variance over the working region (pipeline.calibration.task_space)
    index_name: str = "V"
    n_configurations: int = 50
    #: initial subset size of remove-and-replace's random start (None: 2/3 of n_configurations)
    n_initial: int | None = None
    #: remove-and-replace (and the gradient design's start) on a trace index (V, A, tcp_A): "approximate"
    #: also polishes the efficient rounding of the optimal approximate design and keeps the better
    #: design (pipeline.calibration.design_rounding); "random": paper 004's random start only
    design_start: DesignStart = "approximate"
    #: remove-and-replace runs from random starts next to the rounded start (design_start approximate)
    design_restarts: int = 1
    #: working configurations for the TCP-covariance criterion (random feasible poses)
    n_working_configurations: int = 5
    #: "se3": 6 errors per joint placement + zero offsets; "mdh_hayati": modified DH + Hayati beta
    error_model: ErrorModel = "se3"
    identifiability_samples: int = 200
    identifiability_rel_tol: float = 1e-7
    n_heldout: int = 1000
    margin_collision_m: float = 0.01
    margin_incidence_deg: float = 3.0
    margin_beam_m: float = 0.02
    max_lm_iterations: int = 50
    gradient_max_iterations: int = 200
    #: gradient design only: random configurations measured first to register the tracker pose
    #: (visibility constraints need it); they count towards n_configurations and are used in the fit
    n_pilot: int = 8
    #: user data instead of the simulated tracker (format: pipeline.calibration.measure)
    measurements_csv: Annotated[str | None, FileInput] = None
    #: the same as a CSV or a ROS 2 bag (folder, .db3, .mcap) of JointState + a tracker topic
    #: (PointStamped / PoseStamped / TransformStamped); a bag is read in its stationary windows
    #: (pipeline.exchange.stationary); taken as measurements_csv
    measurements_file: str | None = None
    #: the tracker readings of a recording whose measurements_file holds joint states only (a
    #: joint-state CSV t_s,q_<joint>_rad,..., or a bag without a tracker topic): a ROS 2 bag of one
    #: tracker topic, stamped on the recording's clock
    tracker_file: Annotated[str | None, FileInput] = None
    #: a bag's stationary windows: every joint slower than this, for at least stationary_min_s,
    #: the first stationary_settle_s skipped, at least stationary_min_readings tracker readings
    stationary_speed_rad_s: float = 2e-3
    stationary_min_s: float = 0.5
    stationary_settle_s: float = 0.1
    stationary_min_readings: int = 1
    #: a recording's joints renamed to the model's: {name in the recording: name in the model}
    joint_names: dict[str, str] = field(default_factory=dict)
    #: held-out poses: a CSV of poses as measurements_csv, or a recording of both topics in one bag
    validation_csv: Annotated[str | None, FileInput] = None
    figures: bool = True
    #: auto | all | geometric | joint_axes | joint_offsets | joint_offsets+compliance | [names]
    #: (pipeline.calibration.subsets); auto: chosen by cross-validation for a measurement file
    #: (pipeline.calibration.model_selection), all in simulation
    parameters: str | list[str] = "auto"
    #: robust loss before the outlier test: huber | cauchy | linear (pipeline.calibration.robust)
    robust_loss: Loss = "huber"
    #: per-reading confidence of the chi-square outlier test on whitened residuals
    outlier_confidence: float = 0.999
    #: at most this fraction of the readings is rejected (more failing the test: model inadequate)
    max_outlier_fraction: float = 0.1
    #: quality gate: chi²/dof of the final fit must not exceed this (1 = the noise model: tracker
    #: noise, and for the elastostatic model the gravity-model prior below). A rigid model of an
    #: elastic arm gives hundreds; the elastostatic model ~1 (its gravity-model uncertainty is in
    #: the covariance, pipeline.calibration.gravity_uncertainty)
    max_chi2_per_dof: float = 10.0
    #: quality gate: held-out (or cross-validated) RMS error over its covariance prediction must not
    #: exceed max_actual_over_predicted (optimistic); below its inverse (pessimistic) is a warning.
    #: On held-out poses a one-sided test (pipeline.calibration.validate): "the true ratio is at most
    #: max_actual_over_predicted" fails only when the held-out sum of squared errors passes its
    #: actual_over_predicted_confidence quantile under that hypothesis (few poses: a wider bound on
    #: the sample ratio; many poses: close to max_actual_over_predicted); the pessimistic warning is
    #: the mirror test at 1 - actual_over_predicted_confidence
    max_actual_over_predicted: float = 1.5
    #: level of that test (a probability, in (0.5, 1)): the gate fails when the held-out sum of squared
    #: errors lies beyond this quantile of its distribution with the true ratio at max_actual_over_predicted
    actual_over_predicted_confidence: float = 0.99
    #: quality gate (gross inadequacy): held-out (or cross-validated) RMS error after calibration
    #: over the nominal model's must not exceed this
    max_error_after_over_before: float = 0.5
    #: known payload mounted on the flange for some measurements: mass (kg), COM in the flange frame (m)
    payload_mass_kg: float | None = None
    payload_com_m: list[float] | None = None
    #: fraction of the selected configurations measured a second time with the payload mounted
    payload_fraction: float = 0.0
    #: k-fold cross-validation on a measurement file (0: none; e.g. 5), pipeline.calibration.crossval;
    #: parameters auto uses this many folds (0: 5)
    cross_validation_folds: int = 0
    #: 1-sigma of a measurement file's positions (m); None: the tracker noise model of robot.yaml
    position_sigma_m: float | None = None
    #: 6-D readings (CSV rx, ry, rz): fit the orientation too, with this 1-sigma per axis (rad)
    use_orientation: bool = True
    orientation_sigma_rad: float = 1.0e-3
    #: robot folder whose inertias give the gravity torques of the elastostatic model (second pass
    #: after identification: ``<runs>/<name>/identification/robot`` of a previous run); None: this
    #: run's model (nominal)
    gravity_model: Annotated[str | None, FileInput] = None
    #: prior uncertainty of the gravity model's inertial parameters in the elastostatic measurement
    #: covariance (pipeline.calibration.gravity_uncertainty): relative 1-sigma of each link mass and
    #: 1-sigma of each centre of mass (m); typical data-sheet/CAD values ("inertial parameters
    #: 10-20 %"); 0 and 0: no gravity-model term
    gravity_model_relative_sigma: float = 0.15
    gravity_model_com_sigma_m: float = 0.02
    #: both sigmas are multiplied by this with an identified gravity model (calibration.gravity_model)
    gravity_model_identified_scale: float = 0.1
    #: second calibration pass by the runner (pipeline.run.second_pass): a first pass of calibration and
    #: identification under ``<run>/first_pass/``, then this run with the identified inertias as
    #: gravity_model. auto: when the gravity model's share of the first pass's predicted error is
    #: >= 0.25 (arms with a nominal mass model that gravity twists), always, never; only without a
    #: gravity_model
    second_pass: SecondPassMode = "auto"

    # -- task-space criterion and design table (pipeline.calibration.task_space, design_table) --
    #: iso_cube (control.iso) | box (working_box_m) | csv (working_csv: columns q1..qn, rad)
    working_region: str = "iso_cube"
    working_box_m: list[list[float]] | None = None
    working_csv: Annotated[str | None, FileInput] = None
    #: working configurations sampled in the region (W of the V criterion)
    n_region_configurations: int = 300
    #: what V weights at the working configurations: tcp+reflector (the TCP, the task's point, and the
    #: reflector in the tracker frame, what held-out readings verify; docs/calibration_design.md),
    #: tcp, or reflector
    design_figure: str = "tcp+reflector"
    #: compare the design with baselines of the same size in the report (predicted TCP RMS; in
    #: simulation also measured on design_table_heldout visible poses of the working region)
    design_table: bool = True
    design_table_heldout: int = 300
    #: the design table's certified lower bound of the held-out prediction over the candidate pool
    #: (pipeline.calibration.design_bound; a few seconds for 20000 candidates)
    design_table_bound: bool = True
    #: the design table measures and calibrates every design this many more times (fresh tracker noise,
    #: the plain weighted least-squares fit) and gives the RMS over the repeats beside the single
    #: calibration: one calibration is one draw of the estimation error (0: the single draw only; 8 add
    #: about 10 s to the RX130L stage)
    design_table_repeats: int = 8

    def gravity_prior(self) -> GravityPrior:
        """Prior uncertainty of the gravity model (scaled down for an identified one)."""
        f = self.gravity_model_identified_scale if self.gravity_model is not None else 1.0
        return GravityPrior(f * float(self.gravity_model_relative_sigma), f * float(self.gravity_model_com_sigma_m))

    def payload(self) -> Payload | None:
        """The known payload (None when no mass is given)."""
        if self.payload_mass_kg is None:
            return None
        com = tuple(float(v) for v in (self.payload_com_m or (0.0, 0.0, 0.0)))
        return Payload(float(self.payload_mass_kg), com)

    def grid_points_per_axis(self, nq: int) -> int:
        """``grid_per_axis``, or when None the paper's 13 values per axis for 6 axes (paper 004 §3:
        the 13⁶ grid) and, for ``nq`` axes, the most values per axis whose grid is no larger."""
        if self.grid_per_axis is not None:
            return int(self.grid_per_axis)
        return max(2, math.floor(GRID_VALUES_PAPER ** (6 / nq) + 1e-9))

    def __post_init__(self) -> None:
        # measurements_file is measurements_csv under its general name (a CSV or a bag)
        if self.measurements_file and not self.measurements_csv:
            self.measurements_csv = self.measurements_file

    def validate(self, source: str = "config") -> None:
        """Robot-independent checks of every field (robot-dependent ones: :func:`check`)."""
        def bad(key: str, problem: str) -> ConfigError:
            return ConfigError(source, f"calibration.{key}", problem)

        self.__post_init__()
        if self.measurements_file and self.measurements_csv != self.measurements_file:
            raise bad("measurements_file", f"{self.measurements_file!r} and measurements_csv "
                      f"{self.measurements_csv!r} name two files; give one of them")
        if self.tracker_file and not self.measurements_csv:
            raise bad("tracker_file", "names the tracker readings of a recording: set measurements_file "
                      "(its joint states) too")
        for key in ("stationary_speed_rad_s", "stationary_min_s"):
            if not (math.isfinite(getattr(self, key)) and getattr(self, key) > 0):
                raise bad(key, f"must be > 0, got {getattr(self, key)!r}")
        if not (math.isfinite(self.stationary_settle_s) and self.stationary_settle_s >= 0):
            raise bad("stationary_settle_s", f"must be >= 0, got {self.stationary_settle_s!r}")
        if self.stationary_min_readings < 1:
            raise bad("stationary_min_readings", f"must be >= 1, got {self.stationary_min_readings!r}")
        check_choices(self, "calibration", source)
        if self.index_name not in ix.INDEX_NAMES:
            raise bad("index_name", f"must be one of {ix.INDEX_NAMES}, got {self.index_name!r}")
        if isinstance(self.design_restarts, bool) or not isinstance(self.design_restarts, int) \
                or not 0 <= self.design_restarts <= 100:
            raise bad("design_restarts", f"must be an integer in [0, 100], got {self.design_restarts!r}")
        for key in ("n_random_candidates", "n_configurations", "n_heldout",
                    "identifiability_samples", "max_lm_iterations", "n_working_configurations",
                    "gradient_max_iterations"):
            if getattr(self, key) < 1:
                raise bad(key, f"must be >= 1, got {getattr(self, key)}")
        if self.grid_per_axis is not None and self.grid_per_axis < 2:
            raise bad("grid_per_axis", f"needs at least 2 values per axis, got {self.grid_per_axis}")
        if self.identifiability_samples > 100_000:
            raise bad("identifiability_samples",
                      f"at most 100000 (the default 200 suffice), got {self.identifiability_samples}")
        if self.n_random_candidates > MAX_CANDIDATES:
            raise bad("n_random_candidates", f"at most {MAX_CANDIDATES} (memory of the candidate Jacobians), "
                      f"got {self.n_random_candidates}")
        if (self.candidates == "random" and not self.measurements_csv
                and self.n_random_candidates < self.n_configurations):
            raise bad("n_random_candidates", f"{self.n_random_candidates} feasible random candidates cannot "
                      f"give n_configurations = {self.n_configurations} distinct configurations; give at least "
                      f"{self.n_configurations} (many more for a good selection; quick profile 1500)")
        if self.n_initial is not None and not 1 <= self.n_initial <= self.n_configurations:
            raise bad("n_initial", f"must be in [1, n_configurations = {self.n_configurations}] or null "
                      f"(2/3 of n_configurations), got {self.n_initial}")
        if self.n_pilot < 0:
            raise bad("n_pilot", f"must be >= 0 (0: no pilot measurements), got {self.n_pilot}")
        if self.selection_method == "gradient":
            if 0 < self.n_pilot < 3:
                raise bad("n_pilot", f"must be 0 (nominal tracker pose) or >= 3 (registering the tracker "
                          f"pose needs 3 points), got {self.n_pilot}")
            if self.n_pilot >= self.n_configurations:
                raise bad("n_pilot", f"the pilot measurements count towards n_configurations = "
                          f"{self.n_configurations}: must be smaller, got {self.n_pilot}")
        check_parameters(self.parameters, source)
        if not (math.isfinite(self.outlier_confidence) and 0.5 < self.outlier_confidence < 1):
            raise bad("outlier_confidence", f"must be in (0.5, 1), got {self.outlier_confidence}")
        if not (math.isfinite(self.max_outlier_fraction) and 0 <= self.max_outlier_fraction < 0.5):
            raise bad("max_outlier_fraction", f"must be in [0, 0.5), got {self.max_outlier_fraction}")
        if not (math.isfinite(self.max_chi2_per_dof) and self.max_chi2_per_dof > 1):
            raise bad("max_chi2_per_dof", f"must be > 1 (chi²/dof is 1 for a right model), got {self.max_chi2_per_dof}")
        if not (math.isfinite(self.max_actual_over_predicted) and self.max_actual_over_predicted > 1):
            raise bad("max_actual_over_predicted", f"must be > 1, got {self.max_actual_over_predicted}")
        level = self.actual_over_predicted_confidence
        if not (math.isfinite(level) and 0.5 < level < 1):
            raise bad("actual_over_predicted_confidence", f"must be in (0.5, 1) (the test's level; 0.99), got {level}")
        if not (math.isfinite(self.max_error_after_over_before) and 0 < self.max_error_after_over_before <= 1):
            raise bad("max_error_after_over_before", f"must be in (0, 1], got {self.max_error_after_over_before}")
        self._validate_payload(bad)
        for key, hi in (("gravity_model_relative_sigma", 1.0), ("gravity_model_com_sigma_m", 0.5),
                        ("gravity_model_identified_scale", 1.0)):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v) and 0 <= v <= hi):
                raise bad(key, f"must be in [0, {hi}], got {v!r}")
        if self.cross_validation_folds != 0 and not 2 <= self.cross_validation_folds <= 50:
            raise bad("cross_validation_folds", f"must be 0 (none) or in [2, 50], got {self.cross_validation_folds}")
        if self.position_sigma_m is not None and not (math.isfinite(self.position_sigma_m)
                                                      and 0 < self.position_sigma_m < 0.01):
            raise bad("position_sigma_m", f"must be in (0, 0.01) m or null, got {self.position_sigma_m}")
        if not (math.isfinite(self.orientation_sigma_rad) and 0 < self.orientation_sigma_rad < 0.1):
            raise bad("orientation_sigma_rad", f"must be in (0, 0.1) rad, got {self.orientation_sigma_rad}")
        tol = self.identifiability_rel_tol
        if not (math.isfinite(tol) and 0 < tol < 1):
            raise bad("identifiability_rel_tol", f"must be in (0, 1) (relative singular value), got {tol}")
        for key in ("margin_collision_m", "margin_beam_m"):
            v = getattr(self, key)
            if not (math.isfinite(v) and 0 <= v < 1):
                raise bad(key, f"must be in [0, 1) m (a clearance in metres), got {v}")
        v = self.margin_incidence_deg
        if not (math.isfinite(v) and 0 <= v < 90):
            raise bad("margin_incidence_deg", f"must be in [0, 90) degrees, got {v}")
        check_task_fields(self, source)
        if self.selection_method == "gradient" and self.index_name not in GRADIENT_INDICES:
            raise bad("selection_method", f"gradient optimises an A-type index (calibration.index_name one of "
                      f"{GRADIENT_INDICES}), but index_name is {self.index_name!r}")

    def _validate_payload(self, bad) -> None:  # noqa: ANN001 - the local error factory of validate
        mass = self.payload_mass_kg
        if mass is None:
            if self.payload_com_m is not None or self.payload_fraction > 0:
                raise bad("payload_mass_kg", "a payload (payload_com_m or payload_fraction > 0) needs its mass in kg")
            return
        if isinstance(mass, bool) or not isinstance(mass, int | float) or not math.isfinite(mass) or mass <= 0:
            raise bad("payload_mass_kg", f"must be a positive mass in kg, got {mass!r}")
        com = self.payload_com_m
        finite = isinstance(com, list) and all(isinstance(v, int | float) and math.isfinite(v) and abs(v) < 2
                                               for v in com)
        if com is not None and (not finite or len(com) != 3):
            raise bad("payload_com_m", f"must be 3 numbers in m (flange frame, |v| < 2), got {com!r}")
        if not (math.isfinite(self.payload_fraction) and 0 <= self.payload_fraction <= 1):
            raise bad("payload_fraction", f"must be in [0, 1], got {self.payload_fraction}")
        if self.payload_fraction == 0 and not self.measurements_csv:
            raise bad("payload_fraction", "a payload is given but no configuration is measured with it: "
                      "set payload_fraction in (0, 1]")


def check_robot_fields(cfg: Config, robot: RobotModel, n_model_params: int) -> None:
    """Fields that need the robot: enough identifiability samples for the ``n_model_params``
    parameters (3 equations per configuration), a working region the arm can follow, a margin
    below the tracker's incidence limit, a grid of at most :data:`MAX_CANDIDATES`."""
    need_samples = -(-n_model_params // 3)
    if cfg.identifiability_samples < need_samples:
        raise ConfigError(None, "calibration.identifiability_samples",
                          f"{cfg.identifiability_samples} random configurations give {3 * cfg.identifiability_samples} "
                          f"equations for the {n_model_params} model parameters of {robot.name}; need at least "
                          f"{need_samples} (default 200)")
    if cfg.working_region == "iso_cube" and robot.nq < POSE_AXES:
        raise ConfigError(None, "calibration.working_region", f"iso_cube: the ISO 9283 path holds a 6-D tool pose, "
                          f"which the {robot.nq} axes of {robot.name} cannot follow; use box (working_box_m) or csv")
    max_inc = math.degrees(robot.tracker.max_incidence_rad)
    if cfg.margin_incidence_deg >= max_inc:
        raise ConfigError(None, "calibration.margin_incidence_deg",
                          f"{cfg.margin_incidence_deg} deg leaves no visible pose: the tracker's maximum incidence "
                          f"angle of {robot.name} is {max_inc:g} deg; the margin must be smaller")
    if not cfg.measurements_csv and cfg.candidates == "grid":
        per_axis = cfg.grid_points_per_axis(robot.nq)
        n_grid = per_axis ** robot.nq
        if n_grid > MAX_CANDIDATES:
            raise ConfigError(None, "calibration.grid_per_axis",
                              f"{per_axis}^{robot.nq} = {n_grid:.3g} grid configurations, at most "
                              f"{MAX_CANDIDATES:.3g} (time and memory); lower grid_per_axis or use candidates: random")


def check_design_size(cfg: Config, robot: RobotModel, p: int, n_min: int) -> None:
    """Design fields (used only without a measurement file) against the ``p`` identifiable
    parameters: at least ``n_min`` configurations measured, designed after the pilot, and in the
    start subset."""
    if cfg.measurements_csv:
        return
    why = f"3 tracker coordinates per configuration for the {p} identifiable parameters of {robot.name}"
    if cfg.n_configurations < n_min:
        raise ConfigError(None, "calibration.n_configurations",
                          f"need at least {n_min} ({why}; more for redundancy and for poses the "
                          f"tracker cannot see), got {cfg.n_configurations}")
    if cfg.selection_method == "gradient" and cfg.n_configurations - cfg.n_pilot < n_min:
        raise ConfigError(None, "calibration.n_pilot",
                          f"n_configurations - n_pilot = {cfg.n_configurations} - {cfg.n_pilot} designed "
                          f"configurations, need at least {n_min} ({why}): lower n_pilot or raise "
                          "n_configurations")
    if (cfg.n_initial is not None and cfg.selection_method in ("remove_and_replace", "gradient")
            and cfg.n_initial < n_min):
        raise ConfigError(None, "calibration.n_initial",
                          f"the start subset must be regular: need at least {n_min} ({why}) or null "
                          f"(2/3 of n_configurations), got {cfg.n_initial}")
