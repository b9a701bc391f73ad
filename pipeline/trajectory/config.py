"""Configuration of stage ``trajectory`` (section ``trajectory:`` of the run YAML)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

from pipeline.core.config_checks import check_count, check_number, check_vector
from pipeline.core.errors import ConfigError, Source
from pipeline.core.typed_config import check_choices
from pipeline.robot.iso9283 import IsoPlane

CpSegment = Literal["line", "circle_large", "circle_small", "spline"]   # smooth pieces of the ISO path, or a spline
PtpEnergy = Literal["torque", "normalised", "electrical"]
CpMethod = Literal["reachability", "nlp"]
CP_SEGMENTS: tuple[CpSegment, ...] = get_args(CpSegment)
PTP_ENERGIES: tuple[PtpEnergy, ...] = get_args(PtpEnergy)
CP_METHODS: tuple[CpMethod, ...] = get_args(CpMethod)
MIN_GRID = 6                                                        # smallest grid / interval count
MAX_CHECK_DT_S = 5e-4                                               # torques are checked at least this often


@dataclass
class TrajectoryConfig:
    # share of each torque limit left to the feedback controller (model errors); the planners and
    # the fine-grid checks use (1 - torque_reserve) * limit, the servo simulation the full limit
    torque_reserve: float = 0.1
    # honour robot.limits.acceleration_rad_s2 in every planner and baseline (CP, toppra, PtP, ruckig);
    # false: torque and speed limits only (the time-optimal studies of paper 004 section 5)
    acceleration_limits: bool = True
    # --- continuous path (CP): one smooth piece of the EN ISO 9283 path (DESIGN.md) ---------
    cp_segment: CpSegment = "circle_large"
    # spline: a cubic spline through these TCP points (base frame, metres; >= 3), the tool
    # orientation as on the ISO path (z axis down); the ISO fields below are then unused
    cp_points_m: list[list[float]] = field(default_factory=list)
    # ISO cube edge L and centre; None = derived from the robot (pipeline.robot.defaults.iso_cube)
    cp_edge_m: float | None = None
    cp_centre_m: list[float] | None = None
    cp_plane: IsoPlane = "diagonal_x"
    cp_ik_points: int = 200                   # IK samples of the Cartesian path
    cp_ik_seed_deg: list[float] | None = None  # None = the robot's ready pose (pipeline.robot.defaults)
    cp_max_ik_step_deg: float = 15.0          # larger jumps between IK samples = branch change
    cp_n_grid: int = 400                      # path grid (toppra uses the same grid)
    # reachability: TOPP-RA with the full friction model (pipeline/trajectory/reachability.py, fast);
    # nlp: the convex problem + IPOPT refinement (pipeline/trajectory/cp.py, the reference)
    cp_method: CpMethod = "reachability"
    cp_torque_margin: float = 0.0             # relative tightening of torque limits in the refinement
    cp_smooth: bool = True
    cp_smooth_intervals: int = 120
    cp_smooth_jerk_rise_time_s: float = 0.05  # jerk limit = peak acceleration / rise time
    cp_smooth_torque_margin: float = 0.004
    # --- point to point (PtP), seed 004 eq. 40 ----------------------------------------------
    # None = a large collision-free move derived from the robot (pipeline.robot.defaults.ptp_move_rad)
    ptp_start_deg: list[float] | None = None
    ptp_goal_deg: list[float] | None = None
    ptp_n_intervals: int = 50
    ptp_k1: float = 1.0
    ptp_k2: float = 0.01
    ptp_energy: PtpEnergy = "normalised"
    ptp_pareto_k2: list[float] = field(default_factory=lambda: [0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0])
    ptp_jit: bool = True
    ptp_jit_flags: list[str] = field(default_factory=lambda: ["-O1"])   # gcc optimisation of the NLP code
    # Coulomb-width continuation of the time-optimal solve, then the model's width: [1.0, 0.1] needs
    # fewer IPOPT iterations than [0.1] (measured at IPOPT tol 1e-6 on the RX130L's robot.yaml PtP move
    # (-45, 20, 30, 0, 40, 0) -> (45, 60, -20, 30, 50, 60) deg: 88 vs 123; 9 random
    # moves on the nominal and the identified RX130L: 3-10 % fewer iterations in all)
    ptp_coulomb_widths_rad_s: list[float] = field(default_factory=lambda: [1.0, 0.1])
    # continuation of the fixed-duration energy solve (at ruckig's duration): on that RX130L move it
    # lands in a slightly better local optimum than [0.1] and needs fewer iterations (nominal RX130L
    # ratio 0.7017 vs 0.7021 in 1.5 s vs 2.9 s; identified 0.735 vs 0.741 in 1.9 s vs 2.9 s); [0.3]
    # alone is worse (0.761 identified). Multi-starts (time-optimal stretched, ruckig resampled, via a
    # low-gravity pose, Pareto point) reach 0.70-0.78, none better by more than 0.005.
    ptp_fixed_coulomb_widths_rad_s: list[float] = field(default_factory=lambda: [1.0, 0.3, 0.1])
    # motor data of ptp_energy: electrical (no robot-independent default: give them for that energy)
    motor_resistance_ohm: list[float] | None = None
    torque_constant_Nm_A: list[float] | None = None
    # --- baselines and verification ----------------------------------------------------------
    ruckig_check_dt_s: float = 5e-4
    ruckig_jerk_ratios_1_s: list[float] = field(default_factory=lambda: [10.0, 25.0, 60.0])
    ruckig_joint_rounds: int = 6
    # then Nelder-Mead on all acceleration factors (coupled joints), this many ruckig evaluations
    ruckig_refine_evaluations: int = 800
    fine_dt_s: float = 2e-4                   # fine-grid torque re-check
    violation_tolerance: float = 0.005        # accepted fine-grid torque violation (0.5 %)
    max_tightening_rounds: int = 3            # re-solves with tightened limits when the fine grid exceeds it
    # quality gate on the servo simulation: the command averaged over 4 ms (feedback noise removed)
    # must stay within this multiple of the full torque limits
    max_sim_averaged_torque_ratio: float = 1.0
    simulate: bool = True                     # run the trajectories in stage 3's servo simulation

    def validate(self, source: Source = None) -> None:
        """Robot-independent checks (ConfigError naming ``trajectory.<field>``); the joint-vector
        lengths (``nq``) and joint limits are checked by ``pipeline.trajectory.stage.check``."""
        s = source

        def name(f: str) -> str:
            return f"trajectory.{f}"

        check_number(s, name("torque_reserve"), self.torque_reserve, ge=0, lt=1,
                     why=" (share of each torque limit kept for the feedback controller)")
        # --- CP
        check_choices(self, "trajectory", s)
        if not isinstance(self.cp_points_m, (list, tuple)):
            raise ConfigError(s, name("cp_points_m"),
                              f"expected a list of [x, y, z] points (m), got {self.cp_points_m!r}")
        for i, p in enumerate(self.cp_points_m):
            check_vector(s, name(f"cp_points_m[{i}]"), p, 3, "m")
        if self.cp_segment == "spline":
            if len(self.cp_points_m) < 3:
                raise ConfigError(s, name("cp_points_m"), "cp_segment spline needs at least 3 points (m), "
                                  f"got {len(self.cp_points_m)}")
            for i in range(1, len(self.cp_points_m)):
                a, b = self.cp_points_m[i - 1], self.cp_points_m[i]
                if sum((x - y) ** 2 for x, y in zip(a, b, strict=True)) ** 0.5 < 1e-6:
                    raise ConfigError(s, name(f"cp_points_m[{i}]"), f"coincides with point {i - 1} ({list(a)!r})")
        if self.cp_edge_m is not None:
            check_number(s, name("cp_edge_m"), self.cp_edge_m, gt=0, unit="m")
        if self.cp_centre_m is not None:
            check_vector(s, name("cp_centre_m"), self.cp_centre_m, 3, "m")
        check_count(s, name("cp_ik_points"), self.cp_ik_points, MIN_GRID)
        if self.cp_ik_seed_deg is not None:
            check_vector(s, name("cp_ik_seed_deg"), self.cp_ik_seed_deg, unit="deg", nonempty=True)
        check_number(s, name("cp_max_ik_step_deg"), self.cp_max_ik_step_deg, gt=0, unit="deg")
        check_count(s, name("cp_n_grid"), self.cp_n_grid, MIN_GRID)
        check_number(s, name("cp_torque_margin"), self.cp_torque_margin, ge=0, lt=1,
                     why=" (relative tightening of the torque limits)")
        check_count(s, name("cp_smooth_intervals"), self.cp_smooth_intervals, MIN_GRID)
        check_number(s, name("cp_smooth_jerk_rise_time_s"), self.cp_smooth_jerk_rise_time_s, gt=0, unit="s")
        check_number(s, name("cp_smooth_torque_margin"), self.cp_smooth_torque_margin, ge=0, lt=1,
                     why=" (relative tightening of the torque limits)")
        # --- PtP
        if (self.ptp_start_deg is None) != (self.ptp_goal_deg is None):
            given, missing = ("ptp_start_deg", "ptp_goal_deg")[::1 if self.ptp_goal_deg is None else -1]
            raise ConfigError(s, name(missing), f"trajectory.{given} is set: set {missing} too (or neither, "
                              "for a move derived from the robot)")
        for field_name in ("ptp_start_deg", "ptp_goal_deg"):
            if getattr(self, field_name) is not None:
                check_vector(s, name(field_name), getattr(self, field_name), unit="deg", nonempty=True)
        if self.ptp_start_deg is not None and len(self.ptp_start_deg) == len(self.ptp_goal_deg) and \
                max(abs(a - b) for a, b in zip(self.ptp_start_deg, self.ptp_goal_deg, strict=True)) < 1e-6:
            raise ConfigError(s, name("ptp_goal_deg"), f"equals trajectory.ptp_start_deg {list(self.ptp_start_deg)!r}: "
                              "a point-to-point move needs two different poses")
        check_count(s, name("ptp_n_intervals"), self.ptp_n_intervals, MIN_GRID)
        check_number(s, name("ptp_k1"), self.ptp_k1, ge=0, why=" (weight of the duration)")
        check_number(s, name("ptp_k2"), self.ptp_k2, gt=0, why=" (weight of the energy)")
        check_vector(s, name("ptp_pareto_k2"), self.ptp_pareto_k2, gt=0)    # empty: no Pareto sweep
        if not isinstance(self.ptp_jit_flags, (list, tuple)):
            raise ConfigError(s, name("ptp_jit_flags"),
                              f"expected a list of compiler flags, got {self.ptp_jit_flags!r}")
        for i, flag in enumerate(self.ptp_jit_flags):
            if not isinstance(flag, str) or not flag.startswith("-") or any(c.isspace() for c in flag):
                raise ConfigError(s, name(f"ptp_jit_flags[{i}]"),
                                  f"expected one compiler flag such as '-O1', got {flag!r}")
        # continuations: widths wider than the model's are solved first; empty = the model's only
        check_vector(s, name("ptp_coulomb_widths_rad_s"), self.ptp_coulomb_widths_rad_s, unit="rad/s", gt=0)
        check_vector(s, name("ptp_fixed_coulomb_widths_rad_s"), self.ptp_fixed_coulomb_widths_rad_s,
                     unit="rad/s", gt=0)
        for field_name, unit in (("motor_resistance_ohm", "ohm"), ("torque_constant_Nm_A", "N m/A")):
            if getattr(self, field_name) is not None:
                check_vector(s, name(field_name), getattr(self, field_name), unit=unit, gt=0, nonempty=True)
            elif self.ptp_energy == "electrical":
                raise ConfigError(s, name(field_name), "ptp_energy: electrical needs the motors' data (per joint)")
        # --- baselines and verification
        check_number(s, name("ruckig_check_dt_s"), self.ruckig_check_dt_s, gt=0, le=MAX_CHECK_DT_S, unit="s",
                     why=" (torques must be checked at least every 0.5 ms)")
        check_vector(s, name("ruckig_jerk_ratios_1_s"), self.ruckig_jerk_ratios_1_s, unit="1/s", gt=0,
                     nonempty=True)
        check_count(s, name("ruckig_joint_rounds"), self.ruckig_joint_rounds, 0)
        check_count(s, name("ruckig_refine_evaluations"), self.ruckig_refine_evaluations, 0)
        check_number(s, name("fine_dt_s"), self.fine_dt_s, gt=0, le=MAX_CHECK_DT_S, unit="s",
                     why=" (torques must be checked at least every 0.5 ms)")
        check_number(s, name("violation_tolerance"), self.violation_tolerance, ge=0, lt=1,
                     why=" (accepted relative torque excess on the fine grid)")
        check_count(s, name("max_tightening_rounds"), self.max_tightening_rounds, 0)
        check_number(s, name("max_sim_averaged_torque_ratio"), self.max_sim_averaged_torque_ratio, gt=0,
                     why=" (simulated torque over the full limit)")
        if not isinstance(self.acceleration_limits, bool):
            raise ConfigError(s, name("acceleration_limits"),
                              f"expected true or false, got {self.acceleration_limits!r}")

