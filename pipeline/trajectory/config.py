"""Configuration of stage ``trajectory`` (section ``trajectory:`` of the run YAML)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class TrajectoryConfig:
    # share of each torque limit left to the feedback controller (model errors); the planners and
    # the fine-grid checks use (1 - torque_reserve) * limit, the servo simulation the full limit
    torque_reserve: float = 0.1
    # --- continuous path (CP): one smooth piece of the EN ISO 9283 path (DESIGN.md) ---------
    cp_segment: str = "circle_large"          # line | circle_large | circle_small | spline
    # spline: a cubic spline through these TCP points (base frame, metres; >= 3), the tool
    # orientation as on the ISO path (z axis down); the ISO fields below are then unused
    cp_points_m: list[list[float]] = field(default_factory=list)
    cp_edge_m: float = 0.5                    # ISO cube edge L
    cp_centre_m: list[float] = field(default_factory=lambda: [0.9, 0.0, 0.3])
    cp_plane: str = "diagonal_x"
    cp_ik_points: int = 200                   # IK samples of the Cartesian path
    cp_ik_seed_deg: list[float] = field(default_factory=lambda: [0.0, 17.0, 86.0, 0.0, 75.0, 0.0])
    cp_max_ik_step_deg: float = 15.0          # larger jumps between IK samples = branch change
    cp_n_grid: int = 400                      # path grid (toppra uses the same grid)
    cp_torque_margin: float = 0.0             # relative tightening of torque limits in the refinement
    cp_smooth: bool = True
    cp_smooth_intervals: int = 120
    cp_smooth_jerk_rise_time_s: float = 0.05  # jerk limit = peak acceleration / rise time
    cp_smooth_torque_margin: float = 0.004
    # --- point to point (PtP), seed 004 eq. 40 ----------------------------------------------
    ptp_start_deg: list[float] = field(default_factory=lambda: [-45.0, 20.0, 30.0, 0.0, 40.0, 0.0])
    ptp_goal_deg: list[float] = field(default_factory=lambda: [45.0, 60.0, -20.0, 30.0, 50.0, 60.0])
    ptp_n_intervals: int = 50
    ptp_k1: float = 1.0
    ptp_k2: float = 0.01
    ptp_energy: str = "normalised"            # torque | normalised | electrical
    ptp_pareto_k2: list[float] = field(default_factory=lambda: [0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0])
    ptp_jit: bool = True
    ptp_jit_flags: list[str] = field(default_factory=lambda: ["-O1"])   # gcc optimisation of the NLP code
    # Coulomb-width continuation of the time-optimal solve, then the model's width: [1.0, 0.1] needs
    # fewer IPOPT iterations than [0.1] (issue-6 move: 88 vs 123, about 1.0 s vs 1.5 s; 9 random
    # moves on the nominal and the identified RX130L: 3-10 % fewer iterations in all)
    ptp_coulomb_widths_rad_s: list[float] = field(default_factory=lambda: [1.0, 0.1])
    # continuation of the fixed-duration energy solve (at ruckig's duration): on the issue-6 move it
    # lands in a slightly better local optimum than [0.1] and needs fewer iterations (nominal RX130L
    # ratio 0.7017 vs 0.7021 in 1.5 s vs 2.9 s; identified 0.735 vs 0.741 in 1.9 s vs 2.9 s); [0.3]
    # alone is worse (0.761 identified). Multi-starts (time-optimal stretched, ruckig resampled, via a
    # low-gravity pose, Pareto point) reach 0.70-0.78, none better by more than 0.005.
    ptp_fixed_coulomb_widths_rad_s: list[float] = field(default_factory=lambda: [1.0, 0.3, 0.1])
    motor_resistance_ohm: list[float] = field(default_factory=lambda: [0.6, 0.6, 1.2, 2.5, 2.5, 3.0])
    torque_constant_Nm_A: list[float] = field(default_factory=lambda: [0.9, 0.9, 0.6, 0.35, 0.3, 0.3])
    # --- baselines and verification ----------------------------------------------------------
    ruckig_check_dt_s: float = 5e-4
    ruckig_jerk_ratios_1_s: list[float] = field(default_factory=lambda: [10.0, 25.0, 60.0])
    ruckig_joint_rounds: int = 6
    # then Nelder-Mead on all acceleration factors (coupled joints), this many ruckig evaluations
    ruckig_refine_evaluations: int = 800
    fine_dt_s: float = 2e-4                   # fine-grid torque re-check
    violation_tolerance: float = 0.005        # accepted fine-grid torque violation (0.5 %)
    max_tightening_rounds: int = 3            # re-solves with tightened limits when the fine grid exceeds it
    simulate: bool = True                     # run the trajectories in stage 3's servo simulation
