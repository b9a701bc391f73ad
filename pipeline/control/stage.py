"""Stage ``control``: model-based feedforward on the EN ISO 9283 path, simulated at 400 µs.

Paper ``004_abbe750b8bbcc3aa.txt`` §2.3 (DESIGN.md "Control", "EN ISO 9283 test path"):

1. servo design per joint from the reflected inertia (python-control, margins);
2. the ISO path (cube of edge L, diagonal plane, P1..P5) with a ruckig speed profile, IK at every
   sample with the best kinematics available (calibrated after stage 1) -> q_d, v_d, a_d;
3. the cascade closed around the real robot's plant (delays, encoder noise) for each
   feedforward variant (none, gravity, rigid body, rigid body + friction) from the best dynamics
   (identified after stage 2) and, for comparison, from the nominal model;
4. the same with the nominal kinematics (effect of the calibration on absolute TCP accuracy).

Works without the upstream stages (then ctx.robot is the nominal model and the comparisons
collapse to equal numbers; the summary says which models were used).

Summary (per feedforward variant where a dict): ``tcp_error_max_m`` / ``_rms_m`` (measured TCP vs
desired path in the base frame), ``tcp_error_registered_*`` (after a best-fit rigid registration),
``tcp_tracking_error_*`` (vs the real robot at the reference joints), ``lag_error_max_rad`` /
``_rms_rad`` (axes 1-3), ``max_torque_ratio``, ``saturation`` (first time and joint, with
``on_saturation = clip``), ``realtime_factor`` (wall) and ``realtime_factor_cpu``, the speed-up
against the plain Python loop, ``tcp_error_rms_{nominal,calibrated}_kinematics_m`` (and registered),
``servo_stick_slip_joints`` (joints whose ``Kv`` the stick-slip floor raised, :mod:`pipeline.control.design`),
``improvement`` (none / full_friction ratios), ``elastic_improvement`` (with an elastic variant:
max TCP tracking error of none and of rigid full_friction over the best elastic variant's, and the
same for the max path error ``path_error_max_*_over_elastic``), ``joint_stiffness`` (with an elastic
variant: the stiffness the feedforward uses, its source per joint, the gravity-model factor and the
deflection budget, :mod:`pipeline.control.joint_stiffness`).
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.config import resolve_robot_dir
from pipeline.control.config import ControlConfig
from pipeline.control.design import filter_alpha, loop_models, servo_report
from pipeline.control.elastic_feedforward import ELASTIC_VARIANTS
from pipeline.control.joint_stiffness import deflection_budget, feedforward_stiffness, stiffness_markdown
from pipeline.control.simulate import first_saturation, servo_gains, simulate_joint_trajectory
from pipeline.control.validate import (
    bode_figure,
    lag_figure,
    path_figure,
    registered_error,
    run_metrics,
    tcp_figure,
)
from pipeline.errors import ConfigError, InfeasibleError, PipelineError
from pipeline.robot.defaults import ik_seeds_or_derived_rad, iso_or_derived, iso_rotation
from pipeline.robot.handoff import ElastostaticRecord
from pipeline.robot.iso9283 import iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import cartesian_reference
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad
from pipeline.stage_api import StageContext, StageResult

NAME = "control"
DEPENDS: tuple[str, ...] = ("model", "calibration", "identification")
#: provenance (pipeline.stage_plan): what is simulated (this stage reads no recorded file)
SIMULATES = "servo loop on the hidden robot"
Config = ControlConfig


def check(config: ControlConfig, robot: RobotModel) -> None:
    """Validate the section against the robot before anything runs (ConfigError naming the field)."""
    config.validate(None)
    nq = robot.nq
    for i, seed in enumerate(config.ik_seeds_deg or []):
        if len(seed) != nq:
            raise ConfigError(None, f"control.ik_seeds_deg[{i}]", f"expected {nq} joint angles (deg) for robot "
                              f"{robot.name}, got {len(seed)}: {list(seed)!r}")


def _nominal_robot(ctx: StageContext):
    return RobotModel.load(resolve_robot_dir(ctx.run))


def _with_dynamics_of(kinematics_robot, dynamics_robot):
    """Copy of ``kinematics_robot`` whose inertias, armature, friction and joint stiffness are
    ``dynamics_robot``'s."""
    out = kinematics_robot.copy()
    for j in range(1, out.model.njoints):
        out.model.inertias[j] = dynamics_robot.model.inertias[j].copy()
    out.model.armature = np.array(dynamics_robot.model.armature).copy()
    for name in ("viscous_Nms_rad", "coulomb_Nm", "rotor_inertia_kgm2"):
        setattr(out.actuation, name, np.array(getattr(dynamics_robot.actuation, name)).copy())
    for name in ("static_friction_excess_Nm", "stribeck_velocity_rad_s"):    # identified Stribeck term, or None
        value = getattr(dynamics_robot.actuation, name)
        setattr(out.actuation, name, None if value is None else np.array(value).copy())
    out.spec.actuation.joint_stiffness_Nm_rad = nominal_joint_stiffness_Nm_rad(dynamics_robot)
    return out


def _upstream_robot(ctx: StageContext, stage: str):
    out = ctx.upstream.get(stage)
    return None if out is None else out.robot


def iso_reference(robot: RobotModel, cfg: ControlConfig):
    """The EN ISO 9283 path of ``cfg.iso`` (None fields derived from ``robot``) and its joint reference:
    ``(ref, path, frame, ik_seeds, q_start)``; ``ref`` from ruckig + IK at every sample with ``robot``'s
    kinematics. Raises InfeasibleError naming ``control.iso`` when the path leaves the workspace."""
    iso = iso_or_derived(robot, cfg.iso)
    frame = robot.frame_reflector if cfg.path_frame == "reflector" else robot.frame_tcp
    rotation = iso_rotation(robot, iso.plane, iso.tool_orientation)
    path = iso9283_path(robot, iso.edge_m, iso.centre_m, iso.plane, rotation, iso.corner_fraction,
                        iso.large_circle_fraction, iso.small_circle_fraction, tuple(iso.segments))
    seeds = ik_seeds_or_derived_rad(robot, cfg.ik_seeds_deg)
    try:
        q_start = start_configuration(robot, path.poses([0.0])[0], seeds, frame)
        ref = cartesian_reference(robot, path, cfg.sample_time_s, iso.speed_m_s, iso.acceleration_m_s2,
                                  iso.jerk_m_s3, q_start, frame, cfg.ik_tolerance_m)
    except InfeasibleError as exc:
        raise InfeasibleError(exc.file, "control.iso", f"{exc.field}: {exc.problem}; the ISO path (cube centre "
                              f"{iso.centre_m} m, edge {iso.edge_m} m) must lie in this robot's workspace: set "
                              "control.iso.centre_m / edge_m in the run config, or run_defaults in its robot.yaml"
                              ) from None
    return ref, path, frame, seeds, q_start


def run(ctx: StageContext) -> StageResult:
    cfg: ControlConfig = ctx.config
    if ctx.real is None:
        raise PipelineError(None, "control", "the hidden robot (pipeline.sim.truth) is not available")
    robot = ctx.robot
    nominal = _nominal_robot(ctx)
    calibrated = _upstream_robot(ctx, "calibration") is not None
    identified = _upstream_robot(ctx, "identification") is not None
    iso = iso_or_derived(robot, cfg.iso)          # None fields derived from the robot
    dt = cfg.sample_time_s
    t0 = time.perf_counter()
    ref, path, frame, seeds, q_start = iso_reference(robot, cfg)
    t_ref = time.perf_counter() - t0
    # the elastic variants' stiffness: calibrated (re-expressed for the identified inertias) or nominal
    cal_out = ctx.upstream.get("calibration")
    record = None if cal_out is None else ElastostaticRecord.from_arrays(cal_out.arrays, robot.nq)
    stiffness = feedforward_stiffness(robot, record, identified,
                                      nominal_joint_stiffness_Nm_rad(nominal))
    robot.spec.actuation.joint_stiffness_Nm_rad = stiffness.stiffness_Nm_rad

    gains = servo_gains(robot, np.mean(ref.q_d, axis=0), cfg)
    nv = cfg.velocity_samples_per_position_sample
    alpha = filter_alpha(cfg.velocity_filter_hz, dt / nv)
    servo = servo_report(gains, dt, nv, cfg.measurement_delay_samples, alpha)

    plant = ctx.real.plant
    tcp_at_ref = plant.measure_tcp(ref.q_d, frame)
    noise_seed = int(ctx.rng.integers(2**32))  # common random numbers across the variants

    def simulate(model, q_d, v_d, a_d, variant):
        return simulate_joint_trajectory(ctx.real, model, ref.t_s, q_d, v_d, a_d, cfg, feedforward=variant,
                                         rng=np.random.default_rng(noise_seed), gains=gains, tcp_frame=frame)

    runs, metrics = {}, {}
    jobs = [(v, robot) for v in cfg.variants]
    if cfg.compare_nominal_feedforward and identified:
        jobs.append(("full_friction_nominal", _with_dynamics_of(robot, nominal)))
    for name, model in ctx.progress.track(jobs, "closed loop on the ISO path"):
        variant = "full_friction" if name == "full_friction_nominal" else name
        res = simulate(model, ref.q_d, ref.v_d, ref.a_d, variant)
        runs[name] = res
        metrics[name] = run_metrics(res.lag_error_rad, res.tcp_position_m, ref.tcp_d_m, tcp_at_ref)
        metrics[name]["max_torque_ratio"] = res.max_torque_ratio.tolist()
        metrics[name]["realtime_factor"] = res.realtime_factor
        metrics[name]["realtime_factor_cpu"] = res.realtime_factor_cpu
        metrics[name]["saturation"] = first_saturation(res, cfg.saturation_ratio)

    # the variant the summary reports: full feedforward with friction, else the user's last variant
    # (never the nominal-model comparison run)
    main = "full_friction" if "full_friction" in cfg.variants else cfg.variants[-1]
    # kinematics: the same control with the reference from the nominal kinematics
    if calibrated:
        nom_kin = _with_dynamics_of(nominal, robot)
        q_start_n = start_configuration(nom_kin, path.poses([0.0])[0], np.vstack([q_start, seeds]), frame)
        ref_n = cartesian_reference(nom_kin, path, dt, iso.speed_m_s, iso.acceleration_m_s2, iso.jerk_m_s3,
                                    q_start_n, frame, cfg.ik_tolerance_m)
        res_n = simulate(robot, ref_n.q_d, ref_n.v_d, ref_n.a_d, main)
        n = min(len(res_n.tcp_position_m), len(ref.tcp_d_m))
        rms_nominal_kin = float(np.sqrt(np.mean(np.sum((res_n.tcp_position_m[:n] - ref.tcp_d_m[:n]) ** 2, 1))))
        reg_nominal_kin = registered_error(res_n.tcp_position_m[:n], ref.tcp_d_m[:n])
    else:
        rms_nominal_kin = metrics[main]["tcp_error_rms_m"]
        reg_nominal_kin = registered_error(runs[main].tcp_position_m, ref.tcp_d_m)
    reg_main = registered_error(runs[main].tcp_position_m, ref.tcp_d_m)
    registered = {"tcp_error_rms_registered_nominal_kinematics_m": float(np.sqrt(np.mean(reg_nominal_kin**2))),
                  "tcp_error_rms_registered_calibrated_kinematics_m": float(np.sqrt(np.mean(reg_main**2)))}

    # speed: compiled loop vs the plain Python loop on the first seconds of the path
    rtf = float(np.median([m["realtime_factor"] for m in metrics.values()]))
    speed = {"realtime_factor": rtf,
             "realtime_factor_cpu": float(np.median([m["realtime_factor_cpu"] for m in metrics.values()]))}
    if cfg.benchmark_python_seconds > 0:
        k = min(len(ref.t_s), max(2, int(cfg.benchmark_python_seconds / dt)))
        py_cfg = ControlConfig(**{**cfg.__dict__, "engine": "python", "settle_time_s": 0.0,
                                  "on_saturation": "clip"})
        res_py = simulate_joint_trajectory(ctx.real, robot, ref.t_s[:k], ref.q_d[:k], ref.v_d[:k], ref.a_d[:k],
                                           py_cfg, feedforward=main,
                                           rng=np.random.default_rng(noise_seed), gains=gains, tcp_frame=frame)
        speed["python_loop_realtime_factor"] = res_py.realtime_factor
        speed["speedup_vs_python_loop"] = rtf / res_py.realtime_factor

    summary = _summary(cfg, ref, metrics, main, speed, rms_nominal_kin, calibrated, identified, servo, t_ref)
    summary.update(registered)
    stiffness_md = ""
    if any(v in ELASTIC_VARIANTS for v in cfg.variants):
        budget = deflection_budget(robot, ref.q_d, ref.v_d, ref.a_d, stiffness.stiffness_Nm_rad, frame)
        summary["joint_stiffness"] = {"Nm_rad": stiffness.stiffness_Nm_rad.tolist(), "source": stiffness.source,
                                      "gravity_model_factor": stiffness.gravity_factor.tolist(),
                                      "nominal_joints": stiffness.nominal_joints, **budget}
        stiffness_md = "\n\n" + stiffness_markdown(stiffness, budget)
    figures = _figures(ref, runs, path, tcp_at_ref, servo_models=[
        loop_models(gains.inertia_kgm2[i], gains.kp[i], gains.kv[i], gains.ki[i], dt, nv,
                    cfg.measurement_delay_samples, alpha) for i in range(min(3, robot.nq))])
    step = max(1, int(round(0.002 / dt)))  # 2 ms for the viewer replay
    arrays = {
        "trajectory_iso_t": runs[main].t_s[::step], "trajectory_iso_q": runs[main].q[::step],
        "trajectory_iso_desired_t": ref.t_s[::step], "trajectory_iso_desired_q": ref.q_d[::step],
        "iso_tcp_desired_m": ref.tcp_d_m, "iso_path_s_m": ref.s_m, "iso_t_s": ref.t_s,
        "iso_q_d": ref.q_d, "iso_v_d": ref.v_d, "iso_a_d": ref.a_d,
        "servo_kp_1_s": gains.kp, "servo_kv_Nms_rad": gains.kv, "servo_ki_Nm_rad": gains.ki,
    }
    for name, res in runs.items():
        arrays[f"lag_error_{name}_rad"] = res.lag_error_rad
        arrays[f"tcp_{name}_m"] = res.tcp_position_m
        arrays[f"tau_cmd_{name}_Nm"] = res.tau_cmd
    data = {"metrics": metrics, "servo": servo, "iso_points_m": {k: v.tolist() for k, v in path.points.items()},
            "segments": ref.segment_labels, "q_start_rad": q_start.tolist()}
    return StageResult(summary=summary, arrays=arrays, data=data, figures=figures,
                       report_md=_report(summary, metrics, servo) + stiffness_md)


def _summary(cfg, ref, metrics, main, speed, rms_nominal_kin, calibrated, identified, servo, t_ref) -> dict:
    s = {
        "sample_time_s": cfg.sample_time_s,
        "velocity_sample_time_s": cfg.sample_time_s / cfg.velocity_samples_per_position_sample,
        "delay_samples": {"setpoint": cfg.setpoint_delay_samples, "measurement": cfg.measurement_delay_samples},
        "feedforward_advanced": cfg.advance_feedforward,
        "path_length_m": float(ref.s_m[-1]), "path_duration_s": float(ref.t_s[-1]),
        "tcp_speed_m_s": cfg.iso.speed_m_s, "tcp_acceleration_m_s2": cfg.iso.acceleration_m_s2,
        "feedforward_model": "identified" if identified else "nominal",
        "kinematics": "calibrated" if calibrated else "nominal",
        "tcp_error_max_m": {k: m["tcp_error_max_m"] for k, m in metrics.items()},
        "tcp_error_rms_m": {k: m["tcp_error_rms_m"] for k, m in metrics.items()},
        "tcp_error_registered_max_m": {k: m["tcp_error_registered_max_m"] for k, m in metrics.items()},
        "tcp_error_registered_rms_m": {k: m["tcp_error_registered_rms_m"] for k, m in metrics.items()},
        "tcp_tracking_error_max_m": {k: m["tcp_tracking_error_max_m"] for k, m in metrics.items()},
        "tcp_tracking_error_rms_m": {k: m["tcp_tracking_error_rms_m"] for k, m in metrics.items()},
        "lag_error_max_rad": {k: m["lag_error_max_rad"][:3] for k, m in metrics.items()},
        "lag_error_rms_rad": {k: m["lag_error_rms_rad"][:3] for k, m in metrics.items()},
        "max_torque_ratio": {k: max(m["max_torque_ratio"]) for k, m in metrics.items()},
        "saturation": {k: m["saturation"] for k, m in metrics.items() if m["saturation"] is not None},
        "tcp_error_rms_nominal_kinematics_m": rms_nominal_kin,
        "tcp_error_rms_calibrated_kinematics_m": metrics[main]["tcp_error_rms_m"],
        "servo_min_phase_margin_deg": {
            "velocity": min(r["velocity"]["phase_margin_deg"] for r in servo),
            "position": min(r["position"]["phase_margin_deg"] for r in servo)},
        # joints whose Kv the stick-slip floor raised above the bandwidth design (pipeline.control.design)
        "servo_stick_slip_joints": [r["joint"] for r in servo if r["kv_Nms_rad"]
                                    > 2 * np.pi * cfg.velocity_bandwidth_hz * r["inertia_kgm2"] * (1 + 1e-9)],
        "reference_time_s": t_ref,
        **speed,
    }
    if "none" in metrics and main != "none":
        a, b = metrics["none"], metrics[main]
        s["improvement"] = {
            "tcp_error_max": a["tcp_error_max_m"] / b["tcp_error_max_m"],
            "tcp_error_registered_max": a["tcp_error_registered_max_m"] / b["tcp_error_registered_max_m"],
            "tcp_tracking_error_max": a["tcp_tracking_error_max_m"] / b["tcp_tracking_error_max_m"],
            "lag_error_max_axes_1_3": [x / y for x, y in zip(a["lag_error_max_rad"][:3], b["lag_error_max_rad"][:3],
                                                             strict=True)],
        }
    elastic = [k for k in ("elastic_flat", "elastic_static") if k in metrics]
    if elastic:
        key = "tcp_tracking_error_max_m"  # the control's part of the error (not the kinematic model's)
        best = min(elastic, key=lambda k: metrics[k][key])
        s["elastic_improvement"] = {"variant": best, **{
            f"{k}_over_elastic": metrics[k][key] / metrics[best][key] for k in ("none", "full_friction")
            if k in metrics}, **{
            f"path_error_max_{k}_over_elastic": metrics[k]["tcp_error_max_m"] / metrics[best]["tcp_error_max_m"]
            for k in ("none", "full_friction") if k in metrics}}
    return s


def _figures(ref, runs, path, tcp_at_ref, servo_models) -> dict:
    show = [k for k in ("none", "full_friction", "elastic_flat") if k in runs] or list(runs)
    lag = {k: runs[k].lag_error_rad for k in runs}
    tcp = {k: np.linalg.norm(runs[k].tcp_position_m - tcp_at_ref, axis=1) for k in runs}
    tcp_abs = {k: np.linalg.norm(runs[k].tcp_position_m - ref.tcp_d_m, axis=1) for k in runs}
    return {
        "lag_errors": lag_figure(ref.t_s, lag),
        "tcp_error": tcp_figure(ref.s_m, tcp, tcp_abs),
        # desired path + the tracking deviation (measured TCP - real robot at q_d), magnified
        "iso_path": path_figure(ref.tcp_d_m[::5], {k: (ref.tcp_d_m + runs[k].tcp_position_m - tcp_at_ref)[::5]
                                                   for k in show}, path.points),
        "servo_bode": bode_figure(servo_models, tuple(range(len(servo_models)))),
    }


def _report(summary, metrics, servo) -> str:
    rows = ["| feedforward | TCP max [mm] | TCP RMS [mm] | registered max [mm] | tracking max [mm] | "
            "lag max a1/a2/a3 [mdeg] | max torque ratio |", "|---|---|---|---|---|---|---|"]
    for k, m in metrics.items():
        lag = "/".join(f"{np.degrees(x) * 1e3:.1f}" for x in m["lag_error_max_rad"][:3])
        rows.append(f"| {k} | {m['tcp_error_max_m'] * 1e3:.3f} | {m['tcp_error_rms_m'] * 1e3:.3f} | "
                    f"{m['tcp_error_registered_max_m'] * 1e3:.3f} | {m['tcp_tracking_error_max_m'] * 1e3:.3f} | "
                    f"{lag} | {max(m['max_torque_ratio']):.2f} |")
    sat = summary["saturation"]
    if sat:
        rows += ["", "**Torque saturation** (control.on_saturation = clip; errors are limited by it): "
                 + "; ".join(f"{k}: first at t = {v['t_s']:.3f} s on joint {v['joint']}, peak |tau_cmd| / tau_max "
                             f"{v['max_ratio']:.2f}" for k, v in sat.items())]
    rows += ["", f"Real-time factor of the compiled loop: {summary['realtime_factor']:.1f}"
             + (f" (plain Python loop {summary['python_loop_realtime_factor']:.1f}, speed-up "
                f"{summary['speedup_vs_python_loop']:.1f}x)" if "python_loop_realtime_factor" in summary else ""),
             f"TCP RMS error, nominal kinematics {summary['tcp_error_rms_nominal_kinematics_m'] * 1e3:.3f} mm, "
             f"{summary['kinematics']} kinematics {summary['tcp_error_rms_calibrated_kinematics_m'] * 1e3:.3f} mm "
             f"(feedforward from the {summary['feedforward_model']} model); after a best-fit rigid registration "
             f"of the measured path (robot placement in the world, not separable from the tracker pose): "
             f"{summary['tcp_error_rms_registered_nominal_kinematics_m'] * 1e3:.3f} mm vs "
             f"{summary['tcp_error_rms_registered_calibrated_kinematics_m'] * 1e3:.3f} mm.",
             "", "| joint | J [kg m²] | Kp [1/s] | Kv [N m s/rad] | vel. PM [deg] | vel. BW [Hz] | pos. PM [deg] | "
             "pos. BW [Hz] |", "|---|---|---|---|---|---|---|---|"]
    raised = summary["servo_stick_slip_joints"]
    if raised:
        rows.insert(len(rows) - 2, f"Kv raised to the stick-slip floor (identified Stribeck slope x "
                    f"control.stick_slip_margin) on joint(s) {', '.join(map(str, raised))}.\n")
    for r in servo:
        rows.append(f"| {r['joint']} | {r['inertia_kgm2']:.2f} | {r['kp_1_s']:.1f} | {r['kv_Nms_rad']:.0f} | "
                    f"{r['velocity']['phase_margin_deg']:.0f} | {r['velocity_bandwidth_hz']:.1f} | "
                    f"{r['position']['phase_margin_deg']:.0f} | {r['position_bandwidth_hz']:.1f} |")
    return "\n".join(rows)
