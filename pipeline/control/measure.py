"""What the control stage measures: the cascade closed around the hidden robot's plant (simulated at
400 µs, :func:`pipeline.control.simulate.simulate_joint_trajectory`), per feedforward variant.

Paper 004 §2.3.3 (DESIGN.md "Control"): every variant runs the same reference with the same
encoder noise (common random numbers: one seed drawn from the stage's generator); the TCP is
measured by an ideal tracker in the base frame. Besides the variants: the same control with the
reference from the nominal kinematics (the calibration's effect on absolute accuracy) and the
speed of the compiled loop against the plain Python loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from pipeline.control.config import ControlConfig
from pipeline.control.design import IsoReference, ServoDesign, slowed_reference
from pipeline.control.estimate import ControlModels, with_dynamics_of
from pipeline.control.simulate import ClosedLoopResult, check_saturation, first_saturation, simulate_joint_trajectory
from pipeline.control.validate import registered_error, run_metrics
from pipeline.core.errors import PipelineError
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import PATH_TORQUE_SHARE, cartesian_reference
from pipeline.stage_api import RealRobot, StageContext

#: slowings of a derived ISO path whose closed-loop commands exceed the torque limits
MAX_SLOWINGS = 3


@dataclass
class ServoRuns:
    """The closed-loop runs by name, their metrics, the variant the summary reports (``main``), the
    real robot's TCP at the reference joints and the encoder-noise seed every run shares."""

    runs: dict[str, ClosedLoopResult]
    metrics: dict[str, dict]
    main: str
    tcp_at_ref: np.ndarray
    noise_seed: int


def measured_tcp(res: ClosedLoopResult) -> np.ndarray:
    """The run's TCP as the ideal tracker measured it (every run of the stage names its TCP frame)."""
    if res.tcp_position_m is None:
        raise PipelineError(None, "control", "the closed loop returned no TCP measurement")
    return res.tcp_position_m


def run_variant(real: RealRobot, model: RobotModel, iso: IsoReference, q_d: np.ndarray, v_d: np.ndarray,
                a_d: np.ndarray, cfg: ControlConfig, variant: str, servo: ServoDesign,
                noise_seed: int) -> ClosedLoopResult:
    """One closed-loop run of ``(q_d, v_d, a_d)`` on the reference's time grid with ``model``'s
    ``variant`` feedforward."""
    return simulate_joint_trajectory(real, model, iso.ref.t_s, q_d, v_d, a_d, cfg, feedforward=variant,
                                     rng=np.random.default_rng(noise_seed), gains=servo.gains, tcp_frame=iso.frame)


def variant_runs(ctx: StageContext, models: ControlModels, iso: IsoReference, servo: ServoDesign,
                 config: ControlConfig | None = None) -> ServoRuns:
    """Every feedforward variant of ``control.variants`` (and, with identified dynamics and
    ``compare_nominal_feedforward``, full_friction from the nominal dynamics) on the ISO reference;
    ``config`` instead of the stage's (``ctx.config``) when given."""
    cfg: ControlConfig = config or ctx.config
    ref, robot = iso.ref, models.robot
    assert ctx.real is not None          # the stage checked it before any step
    tcp_at_ref = ctx.real.plant.measure_tcp(ref.q_d, iso.frame)
    noise_seed = int(ctx.rng.integers(2**32))  # common random numbers across the variants
    runs, metrics = {}, {}
    jobs: list[tuple[str, RobotModel]] = [(v, robot) for v in cfg.variants]
    if cfg.compare_nominal_feedforward and models.identified:
        jobs.append(("full_friction_nominal", with_dynamics_of(robot, models.nominal)))
    for name, model in ctx.progress.track(jobs, "closed loop on the ISO path"):
        variant = "full_friction" if name == "full_friction_nominal" else name
        res = run_variant(ctx.real, model, iso, ref.q_d, ref.v_d, ref.a_d, cfg, variant, servo, noise_seed)
        runs[name] = res
        metrics[name] = run_metrics(res.lag_error_rad, measured_tcp(res), ref.tcp_d_m, tcp_at_ref)
        metrics[name]["max_torque_ratio"] = res.max_torque_ratio.tolist()
        metrics[name]["realtime_factor"] = res.realtime_factor
        metrics[name]["realtime_factor_cpu"] = res.realtime_factor_cpu
        metrics[name]["saturation"] = first_saturation(res, cfg.saturation_ratio)
    # the variant the summary reports: full feedforward with friction, else the user's last variant
    # (never the nominal-model comparison run)
    main = "full_friction" if "full_friction" in cfg.variants else cfg.variants[-1]
    return ServoRuns(runs, metrics, main, tcp_at_ref, noise_seed)


def runs_within_torque(ctx: StageContext, models: ControlModels, iso: IsoReference, servo: ServoDesign
                       ) -> tuple[IsoReference, ServoRuns]:
    """:func:`variant_runs`, and the reference they ran. A derived path (:class:`IsoReference`) whose
    closed-loop commands still exceed the torque limits (the servo's corrections and the hidden robot's
    deviations on top of the model's torque) is slowed by ``s = sqrt(PATH_TORQUE_SHARE / peak ratio)``
    and run again, at most ``MAX_SLOWINGS`` times, as a commissioning engineer lowers the override; the
    runs that are kept are then checked by ``control.on_saturation`` (an error, or clipped and reported)."""
    cfg: ControlConfig = ctx.config
    clipped = replace(cfg, on_saturation="clip")        # every variant runs; the check comes after
    for slowing in range(MAX_SLOWINGS + 1):
        measured = variant_runs(ctx, models, iso, servo, clipped)
        peak = max((m["saturation"]["max_ratio"] for m in measured.metrics.values() if m["saturation"]),
                   default=0.0)
        if peak <= cfg.saturation_ratio or not iso.derived_cube or slowing == MAX_SLOWINGS:
            break
        iso = slowed_reference(models.robot, cfg, iso, math.sqrt(PATH_TORQUE_SHARE / peak))
    for res in measured.runs.values():
        check_saturation(res, cfg)
    return iso, measured


def kinematics_comparison(ctx: StageContext, models: ControlModels, iso: IsoReference, servo: ServoDesign,
                          measured: ServoRuns) -> tuple[float, dict[str, float]]:
    """The main variant with the reference from the nominal kinematics (after a calibration; else the
    main run itself): its TCP RMS error, and the registered RMS errors of both kinematics."""
    cfg: ControlConfig = ctx.config
    ref, main = iso.ref, measured.main
    assert ctx.real is not None          # the stage checked it before any step
    if models.calibrated:
        nom_kin = with_dynamics_of(models.nominal, models.robot)
        q_start_n = start_configuration(nom_kin, iso.path.poses(np.array([0.0]))[0],
                                        np.vstack([iso.q_start, iso.seeds]), iso.frame)
        ref_n = cartesian_reference(nom_kin, iso.path, cfg.sample_time_s, iso.iso.speed_m_s,
                                    iso.iso.acceleration_m_s2, iso.iso.jerk_m_s3, q_start_n, iso.frame,
                                    cfg.ik_tolerance_m)
        res_n = run_variant(ctx.real, models.robot, iso, ref_n.q_d, ref_n.v_d, ref_n.a_d, cfg, main, servo,
                            measured.noise_seed)
        tcp_n = measured_tcp(res_n)
        n = min(len(tcp_n), len(ref.tcp_d_m))
        rms_nominal_kin = float(np.sqrt(np.mean(np.sum((tcp_n[:n] - ref.tcp_d_m[:n]) ** 2, 1))))
        reg_nominal_kin = registered_error(tcp_n[:n], ref.tcp_d_m[:n])
    else:
        rms_nominal_kin = measured.metrics[main]["tcp_error_rms_m"]
        reg_nominal_kin = registered_error(measured_tcp(measured.runs[main]), ref.tcp_d_m)
    reg_main = registered_error(measured_tcp(measured.runs[main]), ref.tcp_d_m)
    registered = {"tcp_error_rms_registered_nominal_kinematics_m": float(np.sqrt(np.mean(reg_nominal_kin**2))),
                  "tcp_error_rms_registered_calibrated_kinematics_m": float(np.sqrt(np.mean(reg_main**2)))}
    return rms_nominal_kin, registered


def loop_speed(ctx: StageContext, iso: IsoReference, servo: ServoDesign, measured: ServoRuns) -> dict[str, float]:
    """Real-time factors of the compiled loop (median over the runs) and, with
    ``benchmark_python_seconds`` > 0, of the plain Python loop on the first seconds of the path."""
    cfg: ControlConfig = ctx.config
    ref, metrics = iso.ref, measured.metrics
    rtf = float(np.median([m["realtime_factor"] for m in metrics.values()]))
    speed = {"realtime_factor": rtf,
             "realtime_factor_cpu": float(np.median([m["realtime_factor_cpu"] for m in metrics.values()]))}
    if cfg.benchmark_python_seconds > 0:
        k = min(len(ref.t_s), max(2, int(cfg.benchmark_python_seconds / cfg.sample_time_s)))
        py_cfg = ControlConfig(**{**cfg.__dict__, "engine": "python", "settle_time_s": 0.0,
                                  "on_saturation": "clip"})
        res_py = simulate_joint_trajectory(ctx.real, ctx.robot, ref.t_s[:k], ref.q_d[:k], ref.v_d[:k], ref.a_d[:k],
                                           py_cfg, feedforward=measured.main,
                                           rng=np.random.default_rng(measured.noise_seed), gains=servo.gains,
                                           tcp_frame=iso.frame)
        speed["python_loop_realtime_factor"] = res_py.realtime_factor
        speed["speedup_vs_python_loop"] = rtf / res_py.realtime_factor
    return speed
