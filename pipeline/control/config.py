"""Configuration of stage 3 (control). Units in the names.

Range and length checks that do not need the robot are in ``validate(source)`` (called by
:func:`pipeline.core.config.load_config` with the file or ``--set`` the section came from, and by
``__post_init__`` for configs built in Python); the joint-vector lengths (``nq``) are checked by
``pipeline.control.stage.check``. Field checks: :mod:`pipeline.core.config_checks`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

from pipeline.core.config_checks import check_count, check_number, check_unique, check_vector
from pipeline.core.errors import ConfigError, Source
from pipeline.core.typed_config import check_choices
from pipeline.robot.iso9283 import IsoPathConfig

FeedforwardVariant = Literal["none", "gravity", "full", "full_friction", "elastic_static", "elastic_flat"]
Engine = Literal["compiled", "python"]
PathFrame = Literal["reflector", "tcp"]
OnSaturation = Literal["error", "clip"]
FEEDFORWARD_VARIANTS: tuple[FeedforwardVariant, ...] = get_args(FeedforwardVariant)
ENGINES: tuple[Engine, ...] = get_args(Engine)
PATH_FRAMES: tuple[PathFrame, ...] = get_args(PathFrame)
ON_SATURATION: tuple[OnSaturation, ...] = get_args(OnSaturation)


@dataclass
class ControlConfig:
    sample_time_s: float = 4e-4                 # position loop (paper 004: 400 us)
    velocity_samples_per_position_sample: int = 2   # velocity loop 200 us
    setpoint_delay_samples: int = 2             # set points reach the drives late
    measurement_delay_samples: int = 1          # measurements return late
    advance_feedforward: bool = True            # send set points early by the known delay
    position_bandwidth_hz: float = 5.0
    velocity_bandwidth_hz: float = 30.0
    pi_zero_ratio: float = 4.0
    #: Kv >= this x the steepest fall of the model's identified Stribeck friction (minus its viscous
    #: friction): no stick-slip at low speed (pipeline.control.design); 0 = the bandwidth design only
    stick_slip_margin: float = 1.5
    #: encoder-velocity low-pass; at 400 Hz the 2 µrad encoder noise differentiated at 200 µs put ~4.5 % of
    #: axis 2's torque limit of feedback noise on the command (150 Hz: half, 64 deg velocity-loop margin)
    velocity_filter_hz: float = 150.0
    compensate_velocity_estimate_delay: bool = True   # delay v_ff like the velocity estimate
    #: Coulomb switching width (rad/s) of the friction feedforward on an arm whose dry friction sticks
    #: (``RealRobot.dry_friction_sticks``): its friction changes sign with its velocity, not smoothly, and
    #: the feedforward's reference velocity is exact, so ``tanh(v_d / w)`` switches this narrowly (the
    #: model's own width, the identification's smoothing of measured speeds, where it is narrower); an
    #: arm with smooth Coulomb friction gets the model's law (pipeline.control.simulate)
    sticking_friction_width_rad_s: float = 1e-3
    settle_time_s: float = 0.3                  # hold the start pose before the path (integrators settle)
    engine: Engine = "compiled"
    chunk_samples: int = 250
    on_saturation: OnSaturation = "error"
    saturation_ratio: float = 1.0               # |tau_cmd| / tau_max above this is saturation
    variants: list[FeedforwardVariant] = field(default_factory=lambda: list(FEEDFORWARD_VARIANTS))
    compare_nominal_feedforward: bool = True    # also run full_friction from the nominal model
    ik_tolerance_m: float = 1e-9
    #: cold-start seeds (deg) for the IK of the first path point, tried in order; None = derived from
    #: the robot (pipeline.robot.defaults.ik_seeds_rad)
    ik_seeds_deg: list[list[float]] | None = None
    #: the point that follows the ISO path and whose error is scored: the laser tracker's reflector,
    #: as paper 004 measures the path with the tracker ("reflector"), or the tool centre point ("tcp";
    #: its offset from the reflector is not observable by the calibration, so its absolute error
    #: keeps the tool's unidentified part)
    path_frame: PathFrame = "reflector"
    iso: IsoPathConfig = field(default_factory=IsoPathConfig)
    benchmark_python_seconds: float = 0.5       # >0: time the plain-Python loop for this simulated time

    def __post_init__(self) -> None:
        if isinstance(self.iso, dict):
            self.iso = IsoPathConfig(**self.iso)
        self.validate(None)

    def validate(self, source: Source = None) -> None:
        """Robot-independent checks; ConfigError naming ``control.<field>`` (``nq``: stage ``check``)."""
        s = source
        check_number(s, "control.sample_time_s", self.sample_time_s, gt=0, unit="s")
        check_count(s, "control.velocity_samples_per_position_sample", self.velocity_samples_per_position_sample, 1)
        check_count(s, "control.setpoint_delay_samples", self.setpoint_delay_samples, 0)
        check_count(s, "control.measurement_delay_samples", self.measurement_delay_samples, 0)
        nyquist_hz = self.velocity_samples_per_position_sample / (2 * self.sample_time_s)
        tv_us = 1e6 * self.sample_time_s / self.velocity_samples_per_position_sample
        why = f" (the velocity loop samples every {tv_us:g} µs: Nyquist frequency {nyquist_hz:g} Hz)"
        check_number(s, "control.velocity_bandwidth_hz", self.velocity_bandwidth_hz, gt=0, lt=nyquist_hz, unit="Hz",
                     why=why)
        check_number(s, "control.velocity_filter_hz", self.velocity_filter_hz, gt=0, lt=nyquist_hz, unit="Hz", why=why)
        check_number(s, "control.position_bandwidth_hz", self.position_bandwidth_hz, gt=0,
                     lt=self.velocity_bandwidth_hz, unit="Hz",
                     why=" (the position loop of the cascade must be slower than control.velocity_bandwidth_hz)")
        check_number(s, "control.pi_zero_ratio", self.pi_zero_ratio, gt=0,
                     why=" (PI zero at velocity bandwidth / pi_zero_ratio)")
        check_number(s, "control.stick_slip_margin", self.stick_slip_margin, ge=0,
                     why=" (Kv >= margin x the identified Stribeck slope; 0 turns the floor off)")
        check_number(s, "control.sticking_friction_width_rad_s", self.sticking_friction_width_rad_s, gt=0,
                     unit="rad/s", why=" (the friction feedforward's sign switching on an arm whose friction sticks)")
        check_number(s, "control.settle_time_s", self.settle_time_s, ge=0, unit="s")
        check_choices(self, "control", s)
        check_count(s, "control.chunk_samples", self.chunk_samples, 1)
        check_number(s, "control.saturation_ratio", self.saturation_ratio, gt=0,
                     why=" (|tau_cmd| / tau_max above this counts as saturation)")
        if not isinstance(self.variants, (list, tuple)) or not self.variants:
            raise ConfigError(s, "control.variants", f"expected a non-empty list of feedforward variants "
                              f"({', '.join(FEEDFORWARD_VARIANTS)}), got {self.variants!r}")
        check_unique(s, "control.variants", self.variants)
        check_number(s, "control.ik_tolerance_m", self.ik_tolerance_m, gt=0, le=1e-4, unit="m",
                     why=" (the IK error of the reference must stay far below the sub-mm errors being measured)")
        if self.ik_seeds_deg is None:
            pass
        elif not isinstance(self.ik_seeds_deg, (list, tuple)) or not self.ik_seeds_deg:
            raise ConfigError(s, "control.ik_seeds_deg",
                              f"expected a non-empty list of joint vectors (deg), got {self.ik_seeds_deg!r}")
        for i, seed in enumerate(self.ik_seeds_deg or []):
            check_vector(s, f"control.ik_seeds_deg[{i}]", seed, unit="deg", nonempty=True)
        if isinstance(self.iso, IsoPathConfig):
            self.iso.validate(s)
        else:
            raise ConfigError(s, "control.iso", f"expected a mapping of ISO path settings, got {self.iso!r}")
        check_number(s, "control.benchmark_python_seconds", self.benchmark_python_seconds, ge=0, unit="s",
                     why=" (0 skips the plain-Python benchmark)")

