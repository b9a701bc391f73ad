"""Summary, figures, arrays and report text of the control stage (paper 004 §2.3.3, Fig. 2).

Summary (per feedforward variant where a dict): ``tcp_error_max_m`` / ``_rms_m`` (measured TCP vs
desired path in the base frame), ``tcp_error_registered_*`` (after a best-fit rigid registration),
``tcp_tracking_error_*`` (vs the real robot at the reference joints), ``lag_error_max_rad`` /
``_rms_rad`` (axes 1-3), ``max_torque_ratio``, ``saturation`` (first time and joint, with
``on_saturation = clip``), ``realtime_factor`` (wall) and ``realtime_factor_cpu``, the speed-up
against the plain Python loop, ``tcp_error_rms_{nominal,calibrated}_kinematics_m`` (and registered),
``servo_stick_slip_joints`` (joints whose ``Kv`` the stick-slip floor raised, :mod:`pipeline.control.design`),
``feedforward_coulomb_width_rad_s`` (only on an arm whose dry friction sticks: the friction feedforward's
Coulomb switching width, :func:`pipeline.control.simulate.feedforward_coulomb_width`),
``improvement`` (none / full_friction ratios), ``elastic_improvement`` (with an elastic variant:
max TCP tracking error of none and of rigid full_friction over the best elastic variant's, and the
same for the max path error ``path_error_max_*_over_elastic``), ``joint_stiffness`` (with an elastic
variant: the stiffness the feedforward uses, its source per joint, the gravity-model factor and the
deflection budget, :mod:`pipeline.control.joint_stiffness`).

Figures: lag errors of axes 1-3 (Fig. 2(a)), TCP error along the path (Fig. 2(b)), the desired
path with the magnified deviations, Bode plots of the servo loops. Every figure shows the simulated
closed loop on the hidden robot.
"""

from __future__ import annotations

from typing import Any

import control as ct
import numpy as np
from matplotlib.figure import Figure

from pipeline.control.config import ControlConfig
from pipeline.control.design import IsoReference, ServoDesign
from pipeline.control.joint_stiffness import StiffnessChoice
from pipeline.control.measure import ServoRuns, measured_tcp
from pipeline.robot.plotting import LINE_STYLES, distinct_colors
from pipeline.robot.reference import PATH_TORQUE_SHARE


def summary(cfg: ControlConfig, iso_run: IsoReference, metrics: dict[str, dict], main: str,
            speed: dict[str, float], rms_nominal_kin: float, calibrated: bool, identified: bool, servo: list[dict]
            ) -> dict[str, Any]:
    """The stage's summary.json (module docstring) from the runs' metrics; the speeds are those the
    reference ran (``iso_run.iso``: derived fields filled, a derived path slowed to the torque limits,
    then ``path_time_scale`` states by how much)."""
    ref, iso, t_ref = iso_run.ref, iso_run.iso, iso_run.time_s
    s = {
        "sample_time_s": cfg.sample_time_s,
        "velocity_sample_time_s": cfg.sample_time_s / cfg.velocity_samples_per_position_sample,
        "delay_samples": {"setpoint": cfg.setpoint_delay_samples, "measurement": cfg.measurement_delay_samples},
        "feedforward_advanced": cfg.advance_feedforward,
        "path_length_m": float(ref.s_m[-1]), "path_duration_s": float(ref.t_s[-1]),
        "tcp_speed_m_s": iso.speed_m_s, "tcp_acceleration_m_s2": iso.acceleration_m_s2,
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
    if iso_run.time_scale < 1.0:
        s["path_time_scale"] = iso_run.time_scale
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




def figures(iso: IsoReference, measured: ServoRuns, servo: ServoDesign, cfg: ControlConfig, nq: int
            ) -> dict[str, Figure]:
    """The stage's figures: lag errors, TCP error, the ISO path, Bode plots of every axis."""
    ref, runs, path, tcp_at_ref = iso.ref, measured.runs, iso.path, measured.tcp_at_ref
    servo_models = servo.loop_models(nq, cfg.sample_time_s, cfg.measurement_delay_samples)
    show: list[str] = [k for k in ("none", "full_friction", "elastic_flat") if k in runs] or list(runs)
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


def report_markdown(summary: dict[str, Any], metrics: dict[str, dict], servo: list[dict]) -> str:
    """The stage's report.md part: a row per run, saturation, speed, kinematics, the servo table."""
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
    if "path_time_scale" in summary:
        rows += ["", f"The derived ISO path is slowed by {summary['path_time_scale']:.2f} (speed "
                 f"{summary['tcp_speed_m_s']:.3g} m/s, acceleration {summary['tcp_acceleration_m_s2']:.3g} m/s²) "
                 f"so that the model's inverse dynamics asks at most {PATH_TORQUE_SHARE:.0%} of every torque limit."]
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


def stiffness_summary(choice: StiffnessChoice, budget: dict[str, list[float]]) -> dict[str, Any]:
    """The summary's ``joint_stiffness``: the feedforward's stiffness, its source, the deflection budget."""
    return {"Nm_rad": choice.stiffness_Nm_rad.tolist(), "source": choice.source,
            "gravity_model_factor": choice.gravity_factor.tolist(), "nominal_joints": choice.nominal_joints,
            **budget}


def arrays(iso: IsoReference, measured: ServoRuns, servo: ServoDesign, cfg: ControlConfig) -> dict[str, np.ndarray]:
    """The stage's arrays: the main run and the reference at 2 ms for the viewer replay, the full
    reference, the gains, and every run's lag error, TCP and torque command."""
    ref, runs, main, gains = iso.ref, measured.runs, measured.main, servo.gains
    step = max(1, int(round(0.002 / cfg.sample_time_s)))  # 2 ms for the viewer replay
    out = {
        "trajectory_iso_t": runs[main].t_s[::step], "trajectory_iso_q": runs[main].q[::step],
        "trajectory_iso_desired_t": ref.t_s[::step], "trajectory_iso_desired_q": ref.q_d[::step],
        "iso_tcp_desired_m": ref.tcp_d_m, "iso_path_s_m": ref.s_m, "iso_t_s": ref.t_s,
        "iso_q_d": ref.q_d, "iso_v_d": ref.v_d, "iso_a_d": ref.a_d,
        "servo_kp_1_s": gains.kp, "servo_kv_Nms_rad": gains.kv, "servo_ki_Nm_rad": gains.ki,
    }
    for name, res in runs.items():
        out[f"lag_error_{name}_rad"] = res.lag_error_rad
        out[f"tcp_{name}_m"] = measured_tcp(res)
        out[f"tau_cmd_{name}_Nm"] = res.tau_cmd
    return out


def data(iso: IsoReference, measured: ServoRuns, servo: ServoDesign) -> dict[str, Any]:
    """The stage's data.json: metrics, servo table, ISO points, segments, start configuration."""
    return {"metrics": measured.metrics, "servo": servo.report,
            "iso_points_m": {k: v.tolist() for k, v in iso.path.points.items()},
            "segments": iso.ref.segment_labels, "q_start_rad": iso.q_start.tolist()}


VARIANT_STYLE = {"none": ("tab:red", "no feedforward"), "gravity": ("tab:orange", "gravity"),
                 "full": ("tab:green", "rigid body"), "full_friction": ("tab:blue", "rigid body + friction"),
                 "full_friction_nominal": ("tab:purple", "rigid body + friction (nominal model)"),
                 "elastic_static": ("tab:olive", "elastic: static deflection"),
                 "elastic_flat": ("tab:cyan", "elastic: two-mass inverse (flatness)")}


def lag_figure(t_s: np.ndarray, lag: dict[str, np.ndarray], axes: tuple[int, ...] = (0, 1, 2)) -> Figure:
    """Paper 004 Fig. 2(a): lag errors of axes 1-3 with and without feedforward."""
    fig = Figure(figsize=(8, 2.2 * len(axes)), constrained_layout=True)
    axs = fig.subplots(len(axes), 1, sharex=True)
    for ax, j in zip(np.atleast_1d(axs), axes, strict=True):
        for name, e in lag.items():
            color, label = VARIANT_STYLE.get(name, ("k", name))
            ax.plot(t_s, np.degrees(e[:, j]) * 1e3, color=color, lw=0.8, label=label)
        ax.set_ylabel(f"axis {j + 1} lag [mdeg]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axs)[0].legend(fontsize=7, ncol=2)
    np.atleast_1d(axs)[-1].set_xlabel("time [s]")
    fig.suptitle("Lag errors on the ISO 9283 path")
    return fig


def tcp_figure(s_m: np.ndarray, tcp_tracking: dict[str, np.ndarray], tcp_absolute: dict[str, np.ndarray]) -> Figure:
    """Paper 004 Fig. 2(b): TCP error along the path with and without feedforward.

    Top: tracking error (measured TCP against the real robot at the reference joints), bottom:
    absolute error against the desired Cartesian path (adds the kinematic model error).
    """
    fig = Figure(figsize=(8, 5.5), constrained_layout=True)
    axs = fig.subplots(2, 1, sharex=True)
    for ax, errs, title in ((axs[0], tcp_tracking, "TCP tracking error (vs. real robot at q_d)"),
                            (axs[1], tcp_absolute, "absolute TCP error (vs. desired path)")):
        for name, e in errs.items():
            color, label = VARIANT_STYLE.get(name, ("k", name))
            ax.plot(s_m, e * 1e3, color=color, lw=0.8, label=label)
        ax.set_ylabel("TCP error [mm]")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
        ax.set_title(title, fontsize=9)
    axs[0].legend(fontsize=7, ncol=2)
    axs[1].set_xlabel("path length [m]")
    return fig


def path_figure(desired_m: np.ndarray, actual: dict[str, np.ndarray], points: dict[str, np.ndarray],
                scale: float = 200.0) -> Figure:
    """Desired TCP path and the measured ones (deviations from it magnified ``scale`` times), 3-D."""
    fig = Figure(figsize=(6, 5.5), constrained_layout=True)
    ax = fig.add_subplot(111, projection="3d")
    ax.plot(*desired_m.T, color="k", lw=0.8, label="desired")
    for name, p in actual.items():
        color, label = VARIANT_STYLE.get(name, ("k", name))
        ax.plot(*(desired_m + scale * (p - desired_m)).T, color=color, lw=0.6, label=f"{label} (deviation x{scale:g})")
    for k, p in points.items():
        if k.startswith("P"):
            ax.scatter(*p, color="k", s=8)
            ax.text(*p, k, fontsize=7)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend(fontsize=7)
    return fig


def bode_figure(models: list[dict], joints: tuple[int, ...] | None = None) -> Figure:
    """Bode magnitude/phase of the velocity and position open loops of the axes ``joints`` (None: every
    axis of ``models``; python-control frequency response). Each axis has its own colour and dash
    pattern, the later ones drawn thinner over the earlier: axes whose loops coincide (gains designed
    from the reflected inertia give the same loop shape) stay visible and say so in the legend
    (``axis 4 (= axis 1)``), and an axis designed differently (e.g. a raised stick-slip ``Kv``) stands out."""
    joints = tuple(range(len(models))) if joints is None else joints
    colors = distinct_colors(len(joints))
    widths = np.linspace(2.4, 0.9, len(joints)) if len(joints) > 1 else np.array([1.2])
    fig = Figure(figsize=(9, 5.5), constrained_layout=True)
    axs = fig.subplots(2, 2, sharex="col")
    for col, key in enumerate(("velocity_open", "position_open")):
        drawn: list[tuple[int, np.ndarray]] = []
        for n, j in enumerate(joints):
            sys = models[j][key]
            w = np.logspace(0, np.log10(np.pi / sys.dt) - 0.01, 600)
            resp = np.asarray(ct.frequency_response(sys, w).complex).ravel()
            mag, phase = np.abs(resp), np.unwrap(np.angle(resp))
            same = next((i for i, r in drawn if r.shape == resp.shape and np.allclose(r, resp, rtol=1e-6)), None)
            drawn.append((j, resp))
            label = f"axis {j + 1}" + ("" if same is None else f" (= axis {same + 1})")
            style = {"color": colors[n], "ls": LINE_STYLES[n % len(LINE_STYLES)], "lw": widths[n]}
            axs[0, col].semilogx(w / 2 / np.pi, 20 * np.log10(mag), label=label, **style)
            axs[1, col].semilogx(w / 2 / np.pi, np.degrees(phase), **style)
        axs[0, col].legend(fontsize=7, ncol=2)
        axs[0, col].axhline(0, color="k", lw=0.5)
        axs[1, col].axhline(-180, color="k", lw=0.5)
        axs[0, col].set_title(key.replace("_", " ") + " loop")
        axs[1, col].set_xlabel("frequency [Hz]")
        for r in range(2):
            axs[r, col].grid(alpha=0.3, which="both")
    axs[0, 0].set_ylabel("magnitude [dB]")
    axs[1, 0].set_ylabel("phase [deg]")
    return fig
