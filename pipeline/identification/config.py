"""Configuration of stage ``identification`` (section ``identification:`` of the run YAML).

Robot-independent range checks in :meth:`Config.validate` (called at load time); the ones that
need the robot or a data file in :func:`pipeline.identification.stage.check`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal, get_args

from pipeline.core.errors import ConfigError, Source
from pipeline.core.typed_config import FileInput, check_choices
from pipeline.identification.base_set import STRUCTURAL_BASE_TOLERANCE

#: processed samples dropped at each end of a data_file record (filter transients)
DATA_BORDER_SAMPLES = 20
#: longest plausible sample interval of a torque/encoder record (20 Hz); a longer one in a data
#: file means its t column is not in seconds
MAX_SAMPLE_TIME_S = 0.05
#: friction models of the fit (``friction_model``, :mod:`.friction`)
FrictionModel = Literal["viscous_coulomb", "stribeck"]
FRICTION_MODELS: tuple[FrictionModel, ...] = get_args(FrictionModel)
#: sample time of the Stäubli TX40 record (5 kHz, :mod:`.tx40`)
TX40_SAMPLE_TIME_S = 2e-4
TX40_NYQUIST_HZ = 0.5 / TX40_SAMPLE_TIME_S


@dataclass
class Tx40Config:
    """Fit of the Stäubli TX40 record (:mod:`.tx40`)."""

    data_dir: str = ""  # empty: data/staubli_tx40 of the repository
    cutoff_hz: float = 100.0
    decimation: int = 10
    border_samples: int = 5
    train_fraction: float = 0.7
    regularization: float = 1e-3
    max_iter: int = 1500
    max_samples: int = 0  # >0: use only the first max_samples raw samples (quick profile)
    # seed of the random states that select the structural base parameters (pivoted QR): fixed
    # here, so the real-data result does not change with the simulation's seed
    base_seed: int = 0


@dataclass
class ExcitationConfig:
    """Fourier excitation and its optimisation (``design.optimize_excitation``)."""

    harmonics: int = 5
    base_frequency_hz: float = 0.1
    n_samples: int = 100  # samples of one period in the NLP (criterion and constraints)
    n_starts: int = 3  # IPOPT runs from the best random feasible trajectories
    n_random: int = 20  # random feasible trajectories for the baseline median
    max_iter: int = 150  # IPOPT stops earlier when the objective stalls (objective_change_tol)
    criterion: Literal["cond", "logdet"] = "cond"
    # >0: IPOPT minimises a smooth surrogate of log cond, soft max - soft min of log(eigenvalues)
    # of W^T W (log-sum-exp with this width); the reported condition number is the exact one
    cond_softness: float = 0.2
    position_margin: float = 0.95
    velocity_margin: float = 0.95
    acceleration_margin: float = 0.95
    torque_margin: float = 0.8  # of the torque limit, for the nominal model (truth differs)
    floor_clearance_m: float = 0.05
    self_clearance_m: float = 0.02
    # bounds of the TCP speed and acceleration along the excitation (None: none; paper 004 §4.3
    # reports up to 5 m/s and 12 m/s^2 on the RX130L); NLP constraints and fine-grid check
    max_tcp_speed_m_s: float | None = None
    max_tcp_acceleration_m_s2: float | None = None
    n_check: int = 400  # fine grid of the final feasibility check
    # IPOPT "acceptable" stop: feasible and the objective changing by less than this (relative)
    objective_change_tol: float = 1e-2


@dataclass
class Config:
    """Settings of the ``identification`` stage."""

    excitation: ExcitationConfig = field(default_factory=ExcitationConfig)
    periods: int = 4
    sample_time_s: float = 4e-4  # torque/encoder sampling (control loop)
    state_cutoff_factor: float = 4.0  # position low-pass at this x the highest harmonic frequency
    decimation: int = 25  # block means of this many samples (parallel decimation)
    # relative |R_kk| of the pivoted QR on the NOMINAL model below which a direction is not
    # identifiable (structural base set, :mod:`.base_set`)
    base_tolerance: float = STRUCTURAL_BASE_TOLERANCE
    base_samples: int = 300
    regularization: float = 1e-3  # pull of the physical fit towards the nominal model
    physical_max_iter: int = 1000
    # stribeck: viscous + Coulomb + a Stribeck term per joint (IPOPT), handed on in the identified
    # model, with the viscous_coulomb fit's validation errors reported beside it (friction.py);
    # viscous_coulomb: the linear friction model only
    friction_model: FrictionModel = "stribeck"
    validation: Literal["iso9283", "fourier"] = "iso9283"
    validation_sample_time_s: float = 4e-3
    #: CSV record or ROS 2 bag (folder, .db3, .mcap) instead of the simulated experiment
    data_file: Annotated[str, FileInput] = ""
    data_side: Literal["joint", "motor"] = "joint"  # columns of data_file
    # a data_file's efforts: "auto" = read against the nominal model's torques, converted (and stated) when
    # they are not joint torques in N·m (motor currents, motor-side torques); a list = joint-side N·m per
    # logged unit per joint (k_t x gear ratio for currents in A; with data_side: motor, applied after the gear
    # matrix, so k_t alone); "none" = taken as joint torques unchecked (effort_unit.read_effort_unit)
    effort_scale: Literal["auto", "none"] | list[float] = "auto"
    # position low-pass and decimation of a (non-periodic) data_file; null: from its sample rate,
    # min(20 Hz, rate / 4) and rate / (5 x cut-off) (signals.record_filter_settings)
    data_cutoff_hz: float | None = None
    data_decimation: int | None = None
    # a data_file's Coulomb smoothing width tanh(v / w): "auto" = chosen per joint on the training part
    # (coulomb_width.choose_widths), "robot" = robot.yaml's actuation.coulomb_smoothing_rad_s
    coulomb_width: Literal["auto", "robot"] = "auto"
    # a joint whose torques show no rotor inertia (the physically consistent fit puts it on its bound;
    # handed_on.unseen_rotor_inertia_joints): "stated" = the robot handed on keeps robot.yaml's
    # actuation.rotor_inertia_kgm2 there (a warning names it), "fitted" = the fit's bound value
    unseen_rotor_inertia: Literal["stated", "fitted"] = "stated"
    # a data_file's joints at rest while others move (held by their static friction): their rows left out of
    # the fits, scored in the validation (dwell.py); true: fitted like every other row
    fit_dwells: bool = False
    # a data_file's joints renamed to the model's: {name in the record: name in the model} (bags)
    joint_names: dict[str, str] = field(default_factory=dict)
    # actuator columns: "gear" = motor-side rotor/friction through the gear matrix (coupled axes,
    # e.g. TX40 5/6), "none" = diagonal joint-side (RobotModel, SymbolicRobot and the hidden robot),
    # "auto" = gear for a data_file (a real drive train; none with robot.yaml actuation.torque_side: link),
    # none for the simulated hidden robot
    actuator_coupling: Literal["auto", "gear", "none"] = "auto"
    # quality gates (pipeline.quality): data must excite the model (hard error) ...
    min_joint_motion_rad: float = 0.05  # peak to peak, every joint
    max_cond_base_regressor_data: float = 1e6
    # ... and the result must vouch for itself (QualityGateError unless --accept-poor)
    max_cond_data_over_design: float = 2.0  # cond of the fitted base regressor / design criterion
    max_validation_rms_over_noise: float = 2.0  # per joint, validation RMS / noise sigma
    max_predicted_torque_over_limit: float = 1.5  # max |tau| predicted on the validation path / limit
    # the Stäubli TX40 record: None = only when the robot is the TX40 (or tx40.data_dir is set)
    run_tx40: bool | None = None
    tx40: Tx40Config = field(default_factory=Tx40Config)
    score_against_truth: bool = True  # simulated runs: z-scores of the final base estimate vs the truth
    replay_rate_hz: float = 50.0
    # data_file: validation fits on this first fraction of the record, scores on the rest
    data_train_fraction: float = 0.7
    # joints whose torques the fit uses (robot joint names or 1-based indices); empty: every joint
    # whose logged torque column carries a signal (joints.unmeasured_torque_columns)
    joints: list[str | int] = field(default_factory=list)

    def validate(self, source: Source = None) -> None:
        """Range checks of values of the right type (called by ``pipeline.core.config`` at load time
        with the file or ``--set`` that set them, and again by :func:`run`); the robot-dependent
        ones are in :func:`check`."""
        ex = self.excitation
        tx = self.tx40
        p = "identification."
        check_choices(self, "identification", source)
        check_choices(ex, "identification.excitation", source)

        def fin(x: float) -> bool:
            return math.isfinite(x)

        checks = [
            ("excitation.harmonics", ex.harmonics >= 1, "must be >= 1"),
            ("excitation.base_frequency_hz", fin(ex.base_frequency_hz) and ex.base_frequency_hz > 0, "must be > 0"),
            ("excitation.n_samples", ex.n_samples >= 10, "must be >= 10"),
            ("excitation.n_samples", ex.n_samples > 2 * ex.harmonics,
             f"must be > 2 x excitation.harmonics = {2 * ex.harmonics} (sampling of the highest harmonic)"),
            ("excitation.n_starts", ex.n_starts >= 1, "must be >= 1"),
            ("excitation.n_random", ex.n_random >= 1, "must be >= 1"),
            ("excitation.max_iter", ex.max_iter >= 0, "must be >= 0"),
            ("excitation.n_check", ex.n_check >= 2, "must be >= 2"),
            ("excitation.objective_change_tol", fin(ex.objective_change_tol) and ex.objective_change_tol > 0,
             "must be > 0"),
            ("min_joint_motion_rad", fin(self.min_joint_motion_rad) and self.min_joint_motion_rad >= 0, "must be >= 0"),
            ("max_cond_base_regressor_data", self.max_cond_base_regressor_data > 1, "must be > 1"),
            ("max_cond_data_over_design", self.max_cond_data_over_design >= 1, "must be >= 1"),
            ("max_validation_rms_over_noise", self.max_validation_rms_over_noise > 0, "must be > 0"),
            ("max_predicted_torque_over_limit", self.max_predicted_torque_over_limit > 0, "must be > 0"),
            ("excitation.cond_softness", fin(ex.cond_softness) and ex.cond_softness >= 0, "must be >= 0"),
            ("excitation.floor_clearance_m", fin(ex.floor_clearance_m) and 0 <= ex.floor_clearance_m < 1,
             "must be in [0, 1) m (a clearance in metres)"),
            ("excitation.self_clearance_m", fin(ex.self_clearance_m) and 0 <= ex.self_clearance_m < 1,
             "must be in [0, 1) m (a clearance in metres)"),
            ("periods", self.periods >= 1, "must be >= 1"),
            ("sample_time_s", fin(self.sample_time_s) and 0 < self.sample_time_s <= MAX_SAMPLE_TIME_S,
             f"must be in (0, {MAX_SAMPLE_TIME_S}] s (torque/encoder sampling)"),
            ("state_cutoff_factor", fin(self.state_cutoff_factor) and self.state_cutoff_factor > 1, "must be > 1"),
            ("decimation", self.decimation >= 1, "must be >= 1"),
            ("base_tolerance", fin(self.base_tolerance) and 0 < self.base_tolerance < 1, "must be in (0, 1)"),
            ("base_samples", self.base_samples >= 1, "must be >= 1"),
            ("regularization", fin(self.regularization) and self.regularization >= 0, "must be >= 0"),
            ("physical_max_iter", self.physical_max_iter >= 1, "must be >= 1"),
            ("validation_sample_time_s", fin(self.validation_sample_time_s)
             and 0 < self.validation_sample_time_s <= MAX_SAMPLE_TIME_S, f"must be in (0, {MAX_SAMPLE_TIME_S}] s"),
            ("data_cutoff_hz", self.data_cutoff_hz is None or (fin(self.data_cutoff_hz) and self.data_cutoff_hz > 0),
             "must be > 0 or null (from the record's rate)"),
            ("data_decimation", self.data_decimation is None or self.data_decimation >= 1,
             "must be >= 1 or null (from the record's rate)"),
            ("replay_rate_hz", fin(self.replay_rate_hz) and self.replay_rate_hz > 0, "must be > 0"),
            ("data_train_fraction", 0 < self.data_train_fraction < 1, "must be in (0, 1)"),
            ("tx40.train_fraction", 0 < tx.train_fraction < 1, "must be in (0, 1)"),
            ("tx40.cutoff_hz", fin(tx.cutoff_hz) and 0 < tx.cutoff_hz < TX40_NYQUIST_HZ,
             f"must be in (0, {TX40_NYQUIST_HZ:g}) Hz (Nyquist frequency of the {1 / TX40_SAMPLE_TIME_S:g} Hz "
             "TX40 record)"),
            ("tx40.decimation", tx.decimation >= 1, "must be >= 1"),
            ("tx40.border_samples", tx.border_samples >= 0, "must be >= 0"),
            ("tx40.regularization", fin(tx.regularization) and tx.regularization >= 0, "must be >= 0"),
            ("tx40.max_iter", tx.max_iter >= 1, "must be >= 1 (IPOPT iterations of the physical fit)"),
            ("tx40.max_samples", tx.max_samples >= 0, "must be >= 0 (0: the whole record)"),
        ]
        for fld, ok, problem in checks:
            if not ok:
                value = self
                for part in fld.split("."):
                    value = getattr(value, part)
                raise ConfigError(source, p + fld, f"{problem}, got {value!r}")
        if isinstance(self.effort_scale, list) and not all(
                isinstance(k, int | float) and fin(k) and k > 0 for k in self.effort_scale):
            raise ConfigError(source, p + "effort_scale",
                              "must be auto, none or a list of numbers > 0 (joint-side N·m per logged effort unit, "
                              f"per joint), got {self.effort_scale!r}")
        for name in ("max_tcp_speed_m_s", "max_tcp_acceleration_m_s2"):
            v = getattr(ex, name)
            if v is not None and not (isinstance(v, int | float) and fin(v) and v > 0):
                raise ConfigError(source, f"{p}excitation.{name}",
                                  f"must be a number > 0 or null (no bound), got {v!r}")
        for name in ("position_margin", "velocity_margin", "acceleration_margin", "torque_margin"):
            v = getattr(ex, name)
            if not 0 < v <= 1:
                raise ConfigError(source, f"{p}excitation.{name}", f"must be in (0, 1], got {v}")
        if not self.data_file:  # the simulated experiment samples whole periods
            per = 1.0 / ex.base_frequency_hz
            n = per / self.sample_time_s
            if abs(n - round(n)) > 1e-6:
                raise ConfigError(source, p + "sample_time_s",
                                  f"{self.sample_time_s} s does not divide the period {per} s")
            cutoff = self.state_cutoff_factor * ex.harmonics * ex.base_frequency_hz
            nyquist = 0.5 / self.sample_time_s
            if not cutoff < nyquist:
                raise ConfigError(source, p + "state_cutoff_factor",
                                  f"the position low-pass at {self.state_cutoff_factor:g} x the highest harmonic "
                                  f"({ex.harmonics} x {ex.base_frequency_hz:g} Hz) = {cutoff:g} Hz is not below the "
                                  f"Nyquist frequency {nyquist:g} Hz of sample_time_s = {self.sample_time_s:g} s")
