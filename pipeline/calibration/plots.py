"""Figures of the calibration stage: held-out error histograms, fit residuals, index against iterations.

Each is a :class:`matplotlib.figure.Figure` of its own (no pyplot state, no backend chosen here): the
run writes it to a file, a notebook shows it inline.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure


def error_histograms(errors_before_m: np.ndarray, errors_after_m: np.ndarray, sigma_m: float,
                     predicted_rms_m: float | None = None) -> Figure:
    """Histograms of the held-out position errors before and after calibration (mm / µm)."""
    fig = Figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2)
    axes[0].hist(1e3 * errors_before_m, bins=40, color="tab:red", alpha=0.8)
    axes[0].set_xlabel("|e| before calibration [mm]")
    axes[0].set_ylabel("poses")
    axes[0].set_title(f"before: RMS {1e3 * np.sqrt(np.mean(errors_before_m ** 2)):.3f} mm")
    axes[1].hist(1e6 * errors_after_m, bins=40, color="tab:green", alpha=0.8)
    axes[1].axvline(3e6 * sigma_m, color="k", ls="--", label="3 σ tracker")
    if predicted_rms_m is not None:
        axes[1].axvline(1e6 * predicted_rms_m, color="tab:blue", ls=":", label="predicted RMS")
    axes[1].set_xlabel("|e| after calibration [µm]")
    axes[1].set_title(f"after: RMS {1e6 * np.sqrt(np.mean(errors_after_m ** 2)):.1f} µm")
    axes[1].legend()
    fig.tight_layout()
    return fig


def index_history(history: list[tuple[int, float]], index_name: str, method: str) -> Figure:
    """Observability index against the iterations of the selection algorithm."""
    h = np.asarray(history, float).reshape(-1, 2)
    fig = Figure(figsize=(6, 3.6))
    ax = fig.subplots()
    ax.plot(h[:, 0], h[:, 1], marker=".", lw=1)
    ax.set_xlabel("iteration (accepted exchange / addition)")
    ax.set_ylabel(index_name)
    ax.set_title(f"{method}: {index_name} against iterations")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def fit_residual_histogram(residuals_m: np.ndarray, sigma_m: float | None = None) -> Figure:
    """Histogram of the in-sample fit residuals |y - h| of the calibration measurements (µm)."""
    fig = Figure(figsize=(6, 3.6))
    ax = fig.subplots()
    ax.hist(1e6 * residuals_m, bins=min(40, max(5, len(residuals_m) // 2)), color="tab:gray", alpha=0.8)
    if sigma_m is not None:
        ax.axvline(3e6 * sigma_m, color="k", ls="--", label="3 σ tracker")
        ax.legend()
    ax.set_xlabel("|y - h| after the fit, calibration points [µm]")
    ax.set_ylabel("configurations")
    ax.set_title(f"fit residuals (in-sample): RMS {1e6 * np.sqrt(np.mean(residuals_m ** 2)):.1f} µm")
    fig.tight_layout()
    return fig


def stage_figures(out) -> dict:
    v = out.validation
    figs = {}
    if v is not None:
        figs["heldout_errors"] = error_histograms(v["errors_before_m"], v["errors_after_m"],
                                                  v["noise_total_sigma_m"], v["predicted_rms_m"])
    if out.fit is not None:
        sigma = float(np.sqrt(np.mean(out.measurements.sigma_m ** 2)))
        figs["fit_residuals"] = fit_residual_histogram(out.fit["residuals_after_m"], sigma)
    if out.selection is not None and len(out.selection.history) > 1:
        figs["index_history"] = index_history(out.selection.history, out.selection.index_name, out.selection.method)
    return figs
