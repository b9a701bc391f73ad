"""Verification of planned trajectories: execution in stage 3's servo simulation on the real robot
(:func:`simulate_on_real`) and the stage's quality gates (:func:`quality_gates`: limits on the fine
grid and in the servo simulation, IPOPT statuses). Figures: :mod:`pipeline.trajectory.report`."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from pipeline.control.config import ControlConfig
from pipeline.control.simulate import simulate_joint_trajectory
from pipeline.core.solver_status import SUCCESS_STATUSES
from pipeline.quality import QualityGates
from pipeline.robot.model import RobotModel
from pipeline.trajectory.config import TrajectoryConfig
from pipeline.trajectory.solve import CPPlan, PTPPlan
from pipeline.trajectory.trajectories import JointTrajectory


@dataclass(frozen=True)
class ServoRun:
    """One plan's run in the servo simulation of the real robot (:func:`simulate_on_real`).

    Torque ratios are ``|tau| / tau_max`` with the full limits (no reserve); the ``*_per_joint``
    arrays have one entry per joint. The TCP errors are ``None`` when the simulation has no TCP
    (``tcp_tracking_*`` also when the plant has no tracker). ``diverged_at_s`` is the time of the
    first sample of a run that diverged (:func:`first_divergence_s`; its ratios are then no
    measurement), else ``None``."""

    duration_s: float
    max_torque_ratio: float
    max_torque_ratio_per_joint: np.ndarray
    max_feedforward_ratio: float
    max_averaged_torque_ratio: float
    max_averaged_torque_ratio_per_joint: np.ndarray
    average_window_s: float
    feedback_std_ratio_per_joint: np.ndarray
    feedback_max_ratio_per_joint: np.ndarray
    lag_error_max_rad: float
    realtime_factor: float
    tcp_error_max_m: float | None = None
    tcp_error_rms_m: float | None = None
    tcp_tracking_error_max_m: float | None = None
    tcp_tracking_error_rms_m: float | None = None
    diverged_at_s: float | None = None

    @property
    def diverged(self) -> bool:
        """Whether the simulation diverged (:func:`first_divergence_s`; its ratios measure nothing)."""
        return self.diverged_at_s is not None

    def to_summary(self) -> dict[str, Any]:
        """The run as a summary entry: arrays as lists, TCP errors only when measured."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            out[f.name] = value.tolist() if isinstance(value, np.ndarray) else value
        return out


def first_divergence_s(t_s: np.ndarray, q: np.ndarray, v: np.ndarray, tau: np.ndarray, q_d: np.ndarray,
                       span_rad: np.ndarray) -> float | None:
    """Time from the start (s) of the first sample of a servo run that has diverged, else None: its
    joint readings, velocity estimates or commands are not finite, or the following error
    ``|q - q_d|`` of a joint exceeds ``span_rad`` (the joint's range, at most one turn). A servo
    that still tracks cannot be that far off, so a run growing without bound is caught while its
    numbers are still finite, before its ratios turn into huge finite figures."""
    q, v, tau, q_d = (np.asarray(a, float) for a in (q, v, tau, q_d))
    finite = np.all(np.isfinite(np.hstack([q, v, tau])), axis=1)
    with np.errstate(invalid="ignore"):
        runaway = np.any(np.abs(q - q_d) > np.asarray(span_rad, float), axis=1)
    bad = ~finite | runaway
    return float(t_s[int(np.argmax(bad))] - t_s[0]) if bad.any() else None


def simulate_on_real(real: Any, robot: RobotModel, traj: JointTrajectory,  # Any: the simulated hidden robot
                     control_config: ControlConfig | None = None,
                     rng: np.random.Generator | None = None, average_window_s: float = 4e-3) -> ServoRun:
    """Run ``traj`` through ``pipeline.control.simulate.simulate_joint_trajectory`` (cascade with
    full-friction feedforward from ``robot``) and report duration, max torque ratio and the TCP
    error of the (ideal-tracker) measured TCP against the planned TCP ``fk(q_d)``.

    Torque ratios are ``|tau| / tau_max`` with the FULL limits of ``robot`` (no reserve):
    ``max_torque_ratio`` of the raw command (per servo sample), ``max_feedforward_ratio`` of the
    feedforward alone, ``max_averaged_torque_ratio`` of the command averaged over
    ``average_window_s``, and the feedback share ``(tau_cmd - tau_ff) / tau_max`` per joint
    (standard deviation and maximum). A run whose encoder readings, velocity estimates or commands
    turn non-finite, or whose following error exceeds a joint's range, has diverged:
    ``diverged_at_s`` names the first such sample (:func:`first_divergence_s`)."""
    cfg = control_config or ControlConfig(on_saturation="clip", benchmark_python_seconds=0.0)
    if getattr(cfg, "on_saturation", "clip") != "clip":
        cfg = ControlConfig(**{**cfg.__dict__, "on_saturation": "clip"})
    res = simulate_joint_trajectory(real, robot, traj.t_s, traj.q, traj.v, traj.a, cfg,
                                    feedforward="full_friction", rng=rng)
    # split the command into the feedforward (the plan's torques on the model) and the feedback:
    # the feedback is mostly zero-mean noise (encoder noise through the velocity loop), so the
    # command is also reported averaged over ``average_window_s`` (what a drive's current loop and
    # thermal limit see) next to its raw per-sample maximum
    limit = np.asarray(robot.limits.effort_Nm, float)
    feedback = (np.asarray(res.tau_cmd) - np.asarray(res.tau_ff)) / limit
    dt = float(res.t_s[1] - res.t_s[0]) if len(res.t_s) > 1 else 1.0
    width = min(max(1, int(round(average_window_s / dt))), len(res.t_s))
    kernel = np.ones(width) / width
    averaged = np.stack([np.convolve(np.asarray(res.tau_cmd)[:, j], kernel, mode="valid")
                         for j in range(limit.size)], axis=1) / limit
    span = np.minimum(np.asarray(robot.limits.upper_rad, float) - np.asarray(robot.limits.lower_rad, float),
                      2.0 * np.pi)
    diverged_at_s = first_divergence_s(res.t_s, res.q, res.v, res.tau_cmd, res.q_d, span)
    tcp: dict[str, float] = {}
    if res.tcp_position_m is not None:
        # against the planned TCP of the model (includes the residual kinematic error) ...
        desired = robot.positions(res.q_d, robot.frame_tcp)
        e = np.linalg.norm(res.tcp_position_m - desired, axis=1)
        tcp["tcp_error_max_m"] = float(e.max())
        tcp["tcp_error_rms_m"] = float(np.sqrt(np.mean(e**2)))
        # ... and against the tracker reading of the robot standing at q_d (dynamic tracking error)
        if hasattr(real.plant, "measure_tcp"):
            e = np.linalg.norm(res.tcp_position_m - real.plant.measure_tcp(res.q_d), axis=1)
            tcp["tcp_tracking_error_max_m"] = float(e.max())
            tcp["tcp_tracking_error_rms_m"] = float(np.sqrt(np.mean(e**2)))
    return ServoRun(duration_s=float(res.t_s[-1] - res.t_s[0]),
                    max_torque_ratio=float(np.max(res.max_torque_ratio)),
                    max_torque_ratio_per_joint=np.asarray(res.max_torque_ratio, float),
                    max_feedforward_ratio=float(np.max(np.abs(res.tau_ff) / limit)),
                    max_averaged_torque_ratio=float(np.max(np.abs(averaged))),
                    max_averaged_torque_ratio_per_joint=np.abs(averaged).max(axis=0),
                    average_window_s=width * dt,
                    feedback_std_ratio_per_joint=feedback.std(axis=0),
                    feedback_max_ratio_per_joint=np.abs(feedback).max(axis=0),
                    lag_error_max_rad=float(np.max(np.abs(res.lag_error_rad))),
                    realtime_factor=float(res.realtime_factor), diverged_at_s=diverged_at_s, **tcp)


def quality_gates(cfg: TrajectoryConfig, cp: CPPlan, ptp: PTPPlan, sims: dict[str, ServoRun],
                  accept_poor: bool = False, elastic_plant: bool = False) -> QualityGates:
    """The stage's gates: every plan within its limits on the fine grid (torque excess, speed and,
    with ``acceleration_limits``, acceleration ratios <= 1 + ``violation_tolerance``), every IPOPT
    solve of a stored plan ``Solve_Succeeded`` (or acceptable), and in the servo simulation the
    command averaged over 4 ms within ``max_sim_averaged_torque_ratio`` x the full torque limits.
    On an elastic plant the time-optimal (rigid-model) PtP is reported, not vouched for: its torque
    steps ring the joints (paper 004 §5: hence jerk-limited plans); the smooth PtP is the one gated.
    A servo run that diverged fails a gate of its own (``<name>_sim_diverged``, naming the plan and the
    time) whether its plan is vouched for or reported: its numbers are no measurement."""
    gates = QualityGates("trajectory", accept_poor=accept_poor)
    tol = cfg.violation_tolerance
    plans = {**cp.checks, **ptp.checks}
    for name in ("cp", "cp_smooth", "ptp", "ptp_energy_at_ruckig_duration", "ptp_smooth"):
        if name not in plans:
            continue
        chk = plans[name]
        gates.check(f"{name}_fine_violation", chk.violation, "<=", tol, "torque excess on the fine grid")
        gates.check(f"{name}_fine_max_velocity_ratio", chk.max_velocity_ratio, "<=", 1.0 + tol)
        if cfg.acceleration_limits:
            gates.check(f"{name}_fine_max_acceleration_ratio", chk.max_acceleration_ratio, "<=", 1.0 + tol)
    statuses = {"ptp_solver_status": ptp.result.info.get("solver_status"),
                "ptp_energy_at_ruckig_duration_solver_status": ptp.at_ruckig_duration_status()}
    if ptp.at_ruckig_duration is None:          # a comparison that does not exist is not a failed solve
        statuses.pop("ptp_energy_at_ruckig_duration_solver_status")
    if cp.optimal.info.get("method") == "nlp":          # the reachability solver has no IPOPT status
        statuses["cp_solver_status"] = cp.optimal.info.get("solver_status")
    if cp.smooth is not None:
        statuses["cp_smooth_solver_status"] = cp.smooth.info.get("solver_status")
    for name, status in statuses.items():
        gates.require(name, status in SUCCESS_STATUSES, f"IPOPT returned {status}")
    # the executed CP is vouched for instead of the time-optimal and smooth ones (reported) when it may
    # differ from them: under torque limits alone always, under acceleration limits once the
    # time-optimal plan fails the servo gate and a remedy (:mod:`.executable`) is executed
    remedy_executed = "cp" in sims and not sims["cp"].max_averaged_torque_ratio <= cfg.max_sim_averaged_torque_ratio
    torque_limited_cp = elastic_plant and "cp_executed" in sims and (not cfg.acceleration_limits or remedy_executed)
    if torque_limited_cp:
        chk = cp.checks["cp_executed"]
        gates.check("cp_executed_fine_violation", chk.violation, "<=", tol, "torque excess on the fine grid")
        gates.check("cp_executed_fine_max_velocity_ratio", chk.max_velocity_ratio, "<=", 1.0 + tol)
        if cfg.acceleration_limits:
            gates.check("cp_executed_fine_max_acceleration_ratio", chk.max_acceleration_ratio, "<=", 1.0 + tol)
    for name, s in sims.items():
        if s.diverged:
            gates.require(f"{name}_sim_diverged", False, f"the servo simulation of plan {name} diverged at "
                          f"t = {s.diverged_at_s:.4f} s of {s.duration_s:.4f} s (a non-finite state, or a joint "
                          "further off its reference than its whole range): no torque ratio to judge")
            continue
        if name in ("ptp_ruckig", "ptp_energy_at_ruckig_duration"):
            continue                 # the baseline is reported, not vouched for
        if torque_limited_cp and name in ("cp", "cp_smooth"):
            continue                 # reported (summary cp_sim_*); the executed CP is the one vouched for
        if elastic_plant and name == "ptp" and "ptp_smooth" in sims:
            continue                 # reported (summary ptp_sim_*); the smooth plan is the executable one
        gates.check(f"{name}_sim_max_averaged_torque_ratio", s.max_averaged_torque_ratio, "<=",
                    cfg.max_sim_averaged_torque_ratio, "servo simulation, 4 ms mean over the full limits")
    return gates
