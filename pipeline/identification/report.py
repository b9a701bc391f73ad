"""Summary, arrays, data, figures and report tables of the identification stage (measured vs
predicted torques, parameter errors, condition-number convergence, the TX40 comparison)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from pipeline.identification import design as design_mod
from pipeline.identification.config import Config
from pipeline.identification.effort_unit import EffortUnit
from pipeline.identification.friction_terms import not_handed_on_note, report_lines
from pipeline.identification.handed_on import unmeasured_joints_note, unseen_rotor_note
from pipeline.identification.measure import StictionExclusion
from pipeline.identification.outcome import Outcome, ValidationTrajectory
from pipeline.identification.regressor import BaseParameters
from pipeline.identification.tx40 import Tx40Result
from pipeline.robot.iso9283 import IsoPathConfig
from pipeline.robot.model import RobotModel
from pipeline.robot.plotting import distinct_colors
from pipeline.stage_api import StageResult


def torques_figure(t: np.ndarray, measured: np.ndarray, predicted: np.ndarray, title: str,
                   joint_numbers: np.ndarray | None = None) -> Figure:
    """Measured and predicted torque per column, one panel each (one column: one panel);
    ``joint_numbers`` (1-based) labels the columns (default 1..n)."""
    nq = measured.shape[1]
    numbers = np.arange(1, nq + 1) if joint_numbers is None or len(joint_numbers) != nq else joint_numbers
    fig = Figure(figsize=(10, 1.6 * max(nq, 2)))
    axes = fig.subplots(nq, 1, sharex=True, squeeze=False)[:, 0]
    for j in range(nq):
        ax = axes[j]
        ax.plot(t, measured[:, j], lw=0.6, color="0.6", label="measured")
        ax.plot(t, predicted[:, j], lw=1.0, color="C0", label="predicted")
        ax.set_ylabel(f"tau{int(numbers[j])} [N m]")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title(title)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def parameters_figure(base: BaseParameters, beta: np.ndarray, sigma: np.ndarray, beta_phys: np.ndarray,
                    beta_nom: np.ndarray, z: np.ndarray | None) -> Figure:
    """Base parameters: WLS estimate with 3-sigma error bars, the physically consistent fit and the
    nominal model, each divided by a per-parameter scale; with a truth score, the z-scores too. Each
    base parameter is named on the axis by its independent standard parameter (``base.set_names``;
    the combination it stands for: ``base.names``, in results.json)."""
    fig = Figure(figsize=(max(12.0, 0.16 * base.n_base), 8 if z is not None else 5))
    axes = fig.subplots(2 if z is not None else 1, 1, squeeze=False, sharex=True)[:, 0]
    k = np.arange(base.n_base)
    scale = np.maximum.reduce([np.abs(beta), np.abs(beta_nom), 3 * sigma, np.full_like(beta, 1e-9)])
    ax = axes[0]
    ax.errorbar(k, beta / scale, yerr=3 * sigma / scale, fmt="o", ms=3, lw=0.8, color="tab:blue",
                label="WLS +- 3 sigma")
    ax.plot(k, beta_phys / scale, "x", ms=4, color="tab:orange", label="physically consistent fit")
    ax.plot(k, beta_nom / scale, "_", ms=8, color="k", label="nominal model")
    ax.set_ylabel("value / scale")
    ax.set_title("base parameters (scale per parameter: max of |estimate|, |nominal|, 3 sigma)")
    ax.legend(fontsize=8, ncol=3)
    if z is not None:
        axes[1].errorbar(k, z, yerr=np.ones_like(z), fmt="o", ms=3, lw=0.8, color="tab:blue")
        axes[1].axhline(3, color="tab:red", lw=0.6)
        axes[1].axhline(-3, color="tab:red", lw=0.6)
        axes[1].set_ylabel("(estimate - truth) / sigma")
    axes[-1].set_xticks(k, base.set_names, rotation=90, fontsize=6)
    axes[-1].set_xlabel("base parameter (its independent standard parameter; the combinations: results.json)")
    fig.tight_layout()
    return fig


def convergence_figure(res: design_mod.ExcitationResult) -> Figure:
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    colors = distinct_colors(len(res.cond_history))
    for i, h in enumerate(res.cond_history):
        if h:
            ax.semilogy(np.arange(len(h)), h, color=colors[i], label=f"start {i + 1}")
    # the starts take the tab10 colours; the two reference lines black, told apart by their dashes
    ax.axhline(res.cond_random_median, color="k", ls="--", lw=0.8, label="median of random feasible")
    ax.axhline(res.cond_optimized, color="k", ls=":", lw=1.4,
               label="optimised (fine-grid feasible)" if res.source == "optimised" else "best random (fallback)")
    ax.set_xlabel("IPOPT iteration")
    ax.set_ylabel("cond(W_base)")
    ax.set_title("excitation optimisation")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig




def _numbers(values: list[float | None]) -> str:
    return "[" + ", ".join("-" if v is None else f"{v:.3g}" for v in values) + "]"


def report_markdown(summary: dict, tx: Tx40Result | None) -> str:
    if summary["cond_optimized"] is None:
        head = (f"Excitation: from the user's record ({summary['data_source']}); condition number of "
                f"its base regressor {summary['cond_base_regressor_data']:.1f} "
                f"({summary['cond_base_regressor_data_structural']:.1f} for the structural base parameters, "
                f"the excitation criterion). Validation on the "
                f"{summary['validation_trajectory']}; noise sigma from the {summary['torque_noise_source']}.")
    else:
        which = "optimised" if summary["excitation"].startswith("optimised") else "best random (fallback)"
        head = (f"Excitation: cond {summary['cond_optimized']:.1f} {which} vs median "
                f"{summary['cond_random_median']:.1f} of random feasible Fourier trajectories "
                f"({summary['cond_improvement']:.1f}x), for the {summary['n_base_parameters_structural']} "
                "structural base parameters (decided on the nominal model, the same set is fitted). "
                f"Condition number of the fitted base regressor on the measured data: "
                f"{summary['cond_base_regressor_data']:.3g}.")
    if summary.get("fit_samples_left_out_stiction") is not None:
        head += (f" The arm's dry friction sticks: {summary['fit_samples_left_out_stiction']} of "
                 f"{summary['fit_samples_before_stiction_exclusion']} samples, those with a joint in the stiction "
                 f"band (|v| < {summary['fit_stiction_band_rad_s']:.3g} rad/s or a reversal in the block; per "
                 f"joint {_numbers(summary['fit_samples_in_stiction_band_per_joint'])}), are left out of the fits.")
    lines = [
        head,
        "",
        "| joint | validation RMS [N m] | noise sigma [N m] | RMS / sigma |",
        "|---|---|---|---|",
    ]
    sig = summary["torque_noise_sigma_Nm"] or [float("nan")] * len(summary["validation_torque_rms_Nm"])
    unmeasured = summary.get("joints_unmeasured") or {}
    names = list(unmeasured)
    for j, (r, s) in enumerate(zip(summary["validation_torque_rms_Nm"], sig, strict=True)):
        lines.append(f"| {j + 1} | {r:.3f} | {s:.3f} | {r / s:.2f} |" if r is not None and s is not None else
                     f"| {j + 1} | unmeasured | | |")
    if unmeasured:
        lines += ["", f"Joints left out of the fit, the gates and the headline ({len(names)}; their drive-train "
                  "parameters stay nominal): " + "; ".join(f"{n}: {why}" for n, why in unmeasured.items()) + "."]
    if summary.get("record_resampling"):
        gap_ms = summary["record_max_gap_s"] * 1e3
        lines += ["", f"The record's time stamps are not uniform (largest gap {gap_ms:.3g} ms): resampled, "
                  f"{summary['record_resampling']}."]
    if summary.get("effort_unit_status"):
        lines += ["", effort_unit_line(summary)]
    if summary.get("coulomb_width_rad_s") is not None:
        lines += ["", f"Coulomb smoothing width per joint {_numbers(summary['coulomb_width_rad_s'])} rad/s "
                  "(robot.yaml: "
                  f"{_numbers(summary['coulomb_width_stated_rad_s'])}), {summary['coulomb_width_selection']}; training "
                  f"residual RMS {_numbers(summary['coulomb_width_train_rms_stated_Nm'])} N m at robot.yaml's widths, "
                  f"{_numbers(summary['coulomb_width_train_rms_chosen_Nm'])} N m at these."]
    if summary.get("dwell_rows_left_out_of_fits") is not None:
        lines += ["", f"Rows at which a joint is at rest ({summary['dwell_rule']}) left out of the fits, per joint: "
                  f"{_numbers(summary['dwell_rows_left_out_of_fits'])}; the held-out tail is scored on every sample."]
    if summary.get("base_covariance"):
        lines += ["", f"Base-parameter sigmas: {summary['base_covariance']}; median "
                  f"{summary['base_sigma_hac_over_white_median']:.2f} x the white-residual WLS sigma."]
    by_model = summary.get("friction_heldout_rms_over_noise")
    if by_model:
        stribeck = ("" if summary.get("stribeck_static_excess_Nm") is None else
                    f"; Stribeck static excess {_numbers(summary['stribeck_static_excess_Nm'])} N m, at most "
                    f"{summary.get('stribeck_static_excess_bound_over_limit', float('nan')):.0%} of the torque limit, "
                    f"Stribeck velocity {_numbers(summary['stribeck_velocity_rad_s'])} rad/s")
        load = ("" if summary.get("load_friction_coefficient") is None else
                f"; load-dependent Coulomb coefficient (N m per N m of load) "
                f"{_numbers(summary['load_friction_coefficient'])}")
        lines += ["", f"Friction models on the same validation torques (handed on, chosen by them: "
                  f"`{summary.get('friction_model_handed_on', summary['friction_model'])}`{stribeck}{load}):", "",
                  "| joint | " + " | ".join(f"{k} RMS / sigma" for k in by_model) + " |",
                  "|---|" + "---|" * len(by_model)]
        lines += [f"| {j + 1} | " + " | ".join("unmeasured" if by_model[k][j] is None else f"{by_model[k][j]:.2f}"
                                              for k in by_model) + " |"
                  for j in range(len(next(iter(by_model.values()))))]
    lines += report_lines(summary)   # a record's friction/actuation terms and the model-class check
    if tx is not None:
        lines += [
            "",
            "| TX40 record | ours | reference (README) |",
            "|---|---|---|",
            f"| base parameters | {tx.n_base_parameters} | 58 |",
            f"| condition number | {tx.condition_number:.0f} | ~970 |",
            f"| RMS, OLS fitted and scored on all samples, raw torques [N m] | "
            f"{tx.rms_all_ols_raw_torque_Nm:.2f} | ~3.35 |",
            f"| RMS, same, low-passed torques [N m] | {tx.rms_all_ols_Nm:.2f} | |",
            f"| held-out RMS (last 30 %), OLS [N m] | {tx.heldout_rms_Nm['ols']:.2f} | |",
            f"| held-out RMS (last 30 %), physically consistent [N m] | {tx.heldout_rms_Nm['physical']:.2f} | |",
            f"| physically consistent | {tx.physically_consistent} | no (negative rotor inertia axis 6) |",
        ]
    return "\n".join(lines)


def effort_unit_line(summary: dict) -> str:
    """One paragraph: what the record's efforts were read as, against the nominal model (:mod:`.effort_unit`)."""
    status, median = summary["effort_unit_status"], summary.get("effort_nominal_ratio_median")
    ratios = _numbers(summary.get("effort_nominal_ratio") or [])
    against = ("" if median is None else
               f" (against the nominal model's torques: median ratio {median:.3g}; per joint {ratios})")
    scale = _numbers(summary.get("effort_scale_Nm_per_unit") or [])
    return {"joint torques": f"The record's efforts read as joint torques in N·m{against}.",
            "converted": f"The record's efforts are not joint torques in N·m{against}: ASSUMED converted with the "
                         f"nominal model's scale, {scale} N·m per logged unit.",
            "stated": f"The record's efforts are scaled by the stated `identification.effort_scale`, {scale} N·m per "
                      f"logged unit{against}.",
            "unchecked": f"The record's efforts are taken as joint torques in N·m, their unit unchecked{against}.",
            }[status]


def replay(t: np.ndarray, q: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Every k-th sample so that the replay runs at about ``rate_hz``."""
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0 / rate_hz
    step = max(1, int(round(1.0 / (rate_hz * dt))))
    return t[::step] - t[0], q[::step]


def excitation_label(exc: design_mod.ExcitationResult | None, criterion: str) -> str:
    """The excitation as the summary names it."""
    if exc is None:
        return "from the user's record"
    if exc.source != "optimised":
        return f"best random feasible Fourier trajectory ({exc.fallback_reason})"
    return f"optimised Fourier trajectory ({criterion})"


def summary(cfg: Config, o: Outcome) -> dict[str, Any]:
    """The stage's summary.json."""
    base, sel, rec, exc, ex = o.regs.base, o.regs.selection, o.regs.record, o.measured.excitation, cfg.excitation
    f, v, wls, truth = o.fits, o.val, o.fits.wls, o.truth
    pj = sel.per_joint
    summary: dict[str, Any] = {
        "n_base_parameters": base.n_base,
        "n_base_parameters_structural": o.regs.base_design.n_base,
        "excitation": excitation_label(exc, ex.criterion),
        "excitation_fallback_reason": None if exc is None else (exc.fallback_reason or None),
        "base_parameter_set": base.set_names,
        "design_dropped_base_parameters": list(o.regs.dropped),
        "design_dropped_cond_full_set": o.regs.dropped_cond,
        "cond_optimized": None if exc is None else exc.cond_optimized,
        "cond_random_median": None if exc is None else exc.cond_random_median,
        "cond_improvement": None if exc is None else exc.cond_random_median / exc.cond_optimized,
        "cond_base_regressor_data": f.cond_data,
        "cond_base_regressor_data_structural": f.cond_data_structural,
        "excitation_criterion": None if exc is None else ex.criterion,
        # largest TCP speed / acceleration of the excitation (fine grid, nominal kinematics) and the bounds
        "excitation_tcp_speed_max_m_s": None if exc is None else exc.feasibility.tcp_speed_max_m_s,
        "excitation_tcp_acceleration_max_m_s2": None if exc is None else exc.feasibility.tcp_acceleration_max_m_s2,
        "excitation_tcp_speed_bound_m_s": ex.max_tcp_speed_m_s,
        "excitation_tcp_acceleration_bound_m_s2": ex.max_tcp_acceleration_m_s2,
        "validation_trajectory": v.trajectory.label,
        "validation_torque_rms_Nm": pj(v.rms_phys),
        "validation_relative_error": pj(v.rel_phys),
        "validation_torque_rms_wls_Nm": pj(v.rms_wls),
        "torque_noise_sigma_Nm": None if v.noise_sigma is None else pj(v.noise_sigma),
        "torque_noise_source": v.noise_source,
        "validation_rms_over_noise": pj(v.rms_over_noise),
        **sel.to_dict(),
        # a record logged with non-uniform time stamps, resampled (signals.resample_uniform)
        "record_max_gap_s": None if rec is None else rec.max_gap_s,
        "record_resampling": None if rec is None or not rec.resampling else rec.resampling,
        "base_covariance": (f"HAC sandwich (Newey & West 1987), Bartlett kernel, bandwidth {o.hac.bandwidth:.2f} "
                            "samples (Andrews 1991 AR(1) plug-in)"),
        "base_sigma_hac_over_white_median": float(np.median(wls.sigma / np.maximum(o.white_sigma, 1e-300))),
        "fraction_within_3sigma": None if truth is None else truth["fraction_within_3sigma"],
        "physically_consistent": bool(f.phys.consistent),
        # 1-based joints on which the robot handed on keeps robot.yaml's rotor inertia (no torque showed it)
        "rotor_inertia_stated_joints": [int(j) + 1 for j in f.stated_rotor_joints],
        "fit_rms_Nm_wls": wls.rms_Nm,
        "data_source": o.measured.source,
        "actuator_coupling": "gear matrix" if o.regs.coupled else "diagonal (joint side)",
        "n_samples_fit": o.measured.data.n_samples,
        **stiction_summary(o.measured.stiction, pj),
        **({} if o.measured.effort_unit is None else effort_unit_summary(o.measured.effort_unit, pj)),
        **({} if o.measured.coulomb_widths is None else o.measured.coulomb_widths.summary(pj)),
        **({} if o.measured.dwells is None else o.measured.dwells.summary(pj)),
        "friction_model": cfg.friction_model,
        **o.friction,
        "runtime_s": o.timings["total_s"],
    }
    if o.tx is not None:
        summary.update(o.tx.summary())
    return summary


def stiction_summary(ex: StictionExclusion | None, pj: Callable[[np.ndarray], list[float | None]]) -> dict[str, Any]:
    """The summary entries of the samples left out of the fits in the stiction band
    (:func:`.measure.without_stiction_band`); {} when none were (the arm's friction does not stick)."""
    if ex is None:
        return {}
    return {"fit_stiction_band_rad_s": ex.band_rad_s,
            "fit_samples_in_stiction_band_per_joint": pj(ex.in_band_per_joint),
            "fit_samples_left_out_stiction": ex.n_left_out,
            "fit_samples_before_stiction_exclusion": ex.n_total}


def effort_unit_summary(unit: EffortUnit, pj: Callable[[np.ndarray], list[float | None]]) -> dict[str, Any]:
    """The summary entries of what a record's efforts were read as (:mod:`.effort_unit`), per joint."""
    def finite(x: np.ndarray) -> list[float | None]:
        return [v if v is None or np.isfinite(v) else None for v in pj(x)]

    return {"effort_unit_status": unit.status,
            "effort_scale_Nm_per_unit": finite(unit.scale_Nm_per_unit),
            "effort_nominal_ratio": finite(unit.nominal_ratio),
            "effort_nominal_partial_r2": finite(unit.partial_r2),
            "effort_nominal_ratio_median": unit.median_ratio}


def arrays(cfg: Config, o: Outcome) -> dict[str, np.ndarray]:
    """The stage's arrays: the excitation for the viewer replay, base and standard parameters, the
    validation torques, the excitation's coefficients and the truth scores when there are any."""
    exc, traj, data, truth = o.measured.excitation, o.measured.trajectory, o.measured.data, o.truth
    f, vt = o.fits, o.val.trajectory
    if traj is not None:
        t_rep = np.arange(0.0, traj.period_s, 1.0 / cfg.replay_rate_hz)
        q_rep, _, _ = traj.evaluate(t_rep)
    else:  # the user's (processed: filtered, decimated, borders dropped) trajectory
        t_rep, q_rep = replay(np.arange(data.n_samples) * data.sample_time_s, data.q, cfg.replay_rate_hz)
    out: dict[str, np.ndarray] = {
        "trajectory_excitation_t": t_rep,
        "trajectory_excitation_q": q_rep,
        "base_beta": f.wls.beta,
        "base_sigma": f.wls.sigma,
        "base_beta_ols": f.ols.beta,
        "base_matrix_E": o.regs.base.matrix,
        "standard_parameters_physical": f.phys.p,
        "standard_parameters_nominal": f.p_nom,
        "validation_t_s": vt.t_s,
        "validation_q": vt.q,
        "validation_tau_measured_Nm": o.val.tau_Nm,
        "validation_tau_predicted_Nm": o.val.pred_phys,
    }
    if exc is not None and traj is not None:
        out["excitation_coefficients"] = traj.coefficients
        out["cond_random"] = np.asarray(exc.cond_random)
    if truth is not None:
        out["base_beta_true"] = truth["beta_true"]
        out["base_z"] = truth["z"]
    if f.load is not None:   # handed on: fl per measured joint and its HAC sigma (0 / NaN: no term)
        term = f.load.load
        sigma = np.full(len(term.coefficient), np.nan)
        sigma[term.joints] = o.hac.sigma[len(o.hac.sigma) - len(term.joints):]
        out["load_friction_coefficient"], out["load_friction_sigma"] = term.coefficient, sigma
    return out


def data(cfg: Config, o: Outcome) -> dict[str, Any]:
    """The stage's data.json: parameter names, the excitation's details, estimation, validation, timings."""
    base, exc, traj, phys, vt = o.regs.base, o.measured.excitation, o.measured.trajectory, o.fits.phys, o.val.trajectory
    truth, tx = o.truth, o.tx
    if exc is not None and traj is not None:
        excitation_data: dict[str, Any] = {
            "trajectory": traj.to_dict(),
            "starts": exc.start_results,
            "feasibility": exc.feasibility.to_dict(),
            "cond_starts": exc.cond_starts,
            "cond_history": exc.cond_history,
            **exc.details,
        }
    else:
        excitation_data = {"source": "user record", "file": str(cfg.data_file),
                           "cond_base_regressor": o.fits.cond_data}
    data_out = {
        "base_parameter_names": base.names,
        "standard_parameter_names": base.standard_names,
        "base_qr_tolerance": base.tolerance,
        "base_rank_gap": base.rank_gap,
        "excitation": excitation_data,
        "estimation": {
            "joint_sigma_Nm_wls": o.fits.wls.joint_sigma_Nm.tolist(),
            "physical_status": phys.status,
            "physical_iterations": phys.iterations,
            "min_pseudo_inertia_eig": phys.min_pseudo_inertia_eig,
        },
        "validation": {"label": vt.label, "note": vt.note, "rms_wls_Nm": o.val.rms_wls.tolist(),
                       "relative_wls": o.val.rel_wls.tolist()},
        "timings_s": o.timings,
    }
    if truth is not None:
        data_out["truth_scores"] = {"max_abs_z": truth["max_abs_z"],
                                    "fraction_within_3sigma": truth["fraction_within_3sigma"]}
    if tx is not None:
        data_out["tx40"] = {
            "heldout_rms_per_joint_Nm": tx.heldout_rms_per_joint_Nm,
            "train_rms_Nm": tx.train_rms_Nm,
            "ols_rotor_inertia_axis6_base": tx.details.get("ols_ia6_base_value"),
            **{k: v for k, v in tx.details.items() if k != "ols_ia6_base_value"},
        }
    return data_out


def figures(o: Outcome) -> dict[str, Figure]:
    """Convergence of the excitation, base parameters, validation torques, the TX40 held-out torques."""
    exc, base, wls, truth, tx = o.measured.excitation, o.regs.base, o.fits.wls, o.truth, o.tx
    vt = o.val.trajectory
    figures: dict[str, Figure] = {}
    if exc is not None:
        figures["convergence"] = convergence_figure(exc)
    figures["parameters"] = parameters_figure(base, wls.beta, wls.sigma, base.from_standard(o.fits.phys.p),
                                            base.from_standard(o.fits.p_nom), None if truth is None else truth["z"])
    figures["validation_torques"] = torques_figure(vt.t_s, o.val.tau_Nm, o.val.pred_phys,
                                                 f"validation on {vt.label}: measured vs identified model",
                                                 np.asarray(o.regs.used) + 1)
    if tx is not None:
        figures["tx40_heldout"] = torques_figure(
            tx.heldout_t_s, tx.heldout_tau_Nm, tx.heldout_pred_Nm["physical"],
            "TX40 held-out 30 %: measured vs physically consistent fit")
    return figures


def stage_result(cfg: Config, o: Outcome, robot: RobotModel) -> StageResult:
    """The stage's result (summary, arrays, data, figures, report text) handing on ``robot``."""
    exc = o.measured.excitation
    s = summary(cfg, o)
    for kept_note in (unmeasured_joints_note(o.regs.selection), unseen_rotor_note(robot, o.fits.stated_rotor_joints)):
        if kept_note:
            s["warnings"] = [*s.get("warnings", []), kept_note]
    if o.regs.dropped:
        s["warnings"] = [*s.get("warnings", []), (
            f"{len(o.regs.dropped)} base parameter(s) the excitation cannot bring under identification."
            "max_cond_base_regressor_data are left out of the design and the fits (combined into the others; "
            "report.md names them)")]
    unit_note = None if o.measured.effort_unit is None else o.measured.effort_unit.note(o.regs.used + 1)
    if unit_note:
        s["warnings"] = [*s.get("warnings", []), unit_note]
    width_note = None if o.measured.coulomb_widths is None else o.measured.coulomb_widths.note()
    if width_note:
        s["warnings"] = [*s.get("warnings", []), width_note]
    terms_note = not_handed_on_note(s)
    if terms_note:
        s["warnings"] = [*s.get("warnings", []), terms_note]
    fallback_md = "" if exc is None or not exc.fallback_reason else (
        f"**Excitation: the best random feasible trajectory is used** ({exc.fallback_reason}).\n\n")
    if o.regs.dropped:
        fallback_md += (f"**Excitation: {len(o.regs.dropped)} base parameter(s) left out of the design and the fits**: "
                        f"the best excitation of the full set within the limits has cond {o.regs.dropped_cond:.3g} > "
                        f"`identification.max_cond_base_regressor_data` = {cfg.max_cond_base_regressor_data:.3g}, "
                        "so the columns over the bound (pivoted QR) are each replaced by their least-squares "
                        "combination of the others on the excitation: "
                        + "; ".join(f"`{n}`" for n in o.regs.dropped) + ".\n\n")
    validation_md = "" if o.val.iso is None else validation_markdown(cfg, o.val.trajectory, o.val.iso, robot)
    return StageResult(summary=s, arrays=arrays(cfg, o), data=data(cfg, o), figures=figures(o), robot=robot,
                       report_md=fallback_md + validation_md + report_markdown(s, o.tx))


def validation_markdown(cfg: Config, vt: ValidationTrajectory, iso: IsoPathConfig, robot: RobotModel) -> str:
    """One paragraph for report.md: which trajectory validated the model; a visible warning
    when the EN ISO 9283 path was asked for but could not be used."""
    if vt.label == "iso9283":
        return f"Validation on the EN ISO 9283 path of `control.iso` ({vt.note}).\n\n"
    if cfg.validation != "iso9283":
        return ("Validation on a random feasible Fourier trajectory "
                f"(`identification.validation: {cfg.validation}`).\n\n")
    why = vt.note.split("; ")[0] if vt.note else "not reachable"
    fix = ("Set `control.ik_seeds_deg` to a configuration near the path (or the robot's `run_defaults`)"
           if "ik_seeds" in why or "IK" in why else
           "Set `control.iso.centre_m` and `control.iso.edge_m` (or the robot's `run_defaults`) to a cube inside "
           "its workspace")
    return ("**Warning: validation fell back to a random Fourier trajectory.** The EN ISO 9283 path "
            f"(`control.iso.centre_m` = {None if iso.centre_m is None else list(iso.centre_m)} m, "
            f"`control.iso.edge_m` = {iso.edge_m} m) "
            f"cannot be followed by {robot.name}: {why}. {fix}.\n\n")
