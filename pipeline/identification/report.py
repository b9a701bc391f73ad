"""Figures and report tables of the identification stage (measured vs predicted torques,
parameter errors, condition-number convergence, the TX40 comparison)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from pipeline.identification import design as design_mod
from pipeline.identification.regressor import BaseParameters
from pipeline.identification.tx40 import Tx40Result


def torques_figure(t: np.ndarray, measured: np.ndarray, predicted: np.ndarray, title: str) -> Figure:
    nq = measured.shape[1]
    fig = Figure(figsize=(10, 1.6 * nq))
    axes = fig.subplots(nq, 1, sharex=True)
    for j in range(nq):
        ax = axes[j]
        ax.plot(t, measured[:, j], lw=0.6, color="0.6", label="measured")
        ax.plot(t, predicted[:, j], lw=1.0, color="C0", label="predicted")
        ax.set_ylabel(f"tau{j + 1} [N m]")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title(title)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def parameters_figure(base: BaseParameters, beta: np.ndarray, sigma: np.ndarray, beta_phys: np.ndarray,
                    beta_nom: np.ndarray, z: np.ndarray | None) -> Figure:
    """Base parameters: WLS estimate with 3-sigma error bars, the physically consistent fit and the
    nominal model, each divided by a per-parameter scale; with a truth score, the z-scores too."""
    fig = Figure(figsize=(12, 7 if z is not None else 4))
    axes = fig.subplots(2 if z is not None else 1, 1, squeeze=False)[:, 0]
    k = np.arange(base.n_base)
    scale = np.maximum.reduce([np.abs(beta), np.abs(beta_nom), 3 * sigma, np.full_like(beta, 1e-9)])
    ax = axes[0]
    ax.errorbar(k, beta / scale, yerr=3 * sigma / scale, fmt="o", ms=3, lw=0.8, label="WLS +- 3 sigma")
    ax.plot(k, beta_phys / scale, "x", ms=4, label="physically consistent fit")
    ax.plot(k, beta_nom / scale, "_", ms=8, color="k", label="nominal model")
    ax.set_ylabel("value / scale")
    ax.set_title("base parameters (scale per parameter: max of |estimate|, |nominal|, 3 sigma)")
    ax.legend(fontsize=8, ncol=3)
    if z is not None:
        axes[1].errorbar(k, z, yerr=np.ones_like(z), fmt="o", ms=3, lw=0.8)
        axes[1].axhline(3, color="r", lw=0.6)
        axes[1].axhline(-3, color="r", lw=0.6)
        axes[1].set_ylabel("(estimate - truth) / sigma")
    axes[-1].set_xlabel("base parameter index (names in results.json)")
    fig.tight_layout()
    return fig


def convergence_figure(res: design_mod.ExcitationResult) -> Figure:
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    for i, h in enumerate(res.cond_history):
        if h:
            ax.semilogy(np.arange(len(h)), h, label=f"start {i + 1}")
    ax.axhline(res.cond_random_median, color="k", ls="--", lw=0.8, label="median of random feasible")
    ax.axhline(res.cond_optimized, color="g", ls=":", lw=0.8,
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
    if summary.get("base_covariance"):
        lines += ["", f"Base-parameter sigmas: {summary['base_covariance']}; median "
                  f"{summary['base_sigma_hac_over_white_median']:.2f} x the white-residual WLS sigma."]
    by_model = summary.get("friction_heldout_rms_over_noise")
    if by_model:
        lines += ["", f"Friction models on the same validation torques (handed on, chosen by them: "
                  f"`{summary.get('friction_model_handed_on', summary['friction_model'])}`; Stribeck static excess "
                  f"{_numbers(summary['stribeck_static_excess_Nm'])} N m, at most "
                  f"{summary.get('stribeck_static_excess_bound_over_limit', float('nan')):.0%} of the torque limit, "
                  f"Stribeck velocity {_numbers(summary['stribeck_velocity_rad_s'])} rad/s):", "",
                  "| joint | " + " | ".join(f"{k} RMS / sigma" for k in by_model) + " |",
                  "|---|" + "---|" * len(by_model)]
        lines += [f"| {j + 1} | " + " | ".join("unmeasured" if by_model[k][j] is None else f"{by_model[k][j]:.2f}"
                                              for k in by_model) + " |"
                  for j in range(len(next(iter(by_model.values()))))]
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
