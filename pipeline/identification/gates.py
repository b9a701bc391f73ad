"""Quality gates of the identification stage (:mod:`pipeline.quality`).

* :func:`check_data_excites` (a hard error, before any fit): every joint must move by at least
  ``min_joint_motion_rad`` (peak to peak) in the record, and the base regressor on the data must
  have full column rank (numerical rank, ``s_min > n eps s_max``) with a condition number below
  ``max_cond_base_regressor_data``. A record in which the robot never moves fails here with a
  message instead of an "identification" with cond 1e50.
* :func:`add_result_gates`: the physically consistent fit's IPOPT status is a success, the fitted
  base regressor's condition number within
  ``max_cond_data_over_design`` x the design criterion's (when an excitation was designed),
  the validation RMS per joint at most ``max_validation_rms_over_noise`` x the noise estimate,
  and the model's predicted torques on the validation path at most
  ``max_predicted_torque_over_limit`` x the joint torque limits.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.errors import DataFileError, PipelineError
from pipeline.core.solver_status import is_success
from pipeline.identification.config import Config
from pipeline.quality import QualityGates


def check_data_excites(
    q: np.ndarray, Wb: np.ndarray, joint_names: list[str], min_motion_rad: float, max_cond: float,
    source: str | None,
) -> float:
    """Raise unless the data excite the base parameters; returns ``cond(Wb)``."""
    field = "identification.data_file" if source else "identification.excitation"
    err = DataFileError if source else PipelineError
    motion = np.ptp(np.asarray(q, float), axis=0) if len(q) else np.zeros(len(joint_names))
    still = [f"{n} ({m:.2g} rad)" for n, m in zip(joint_names, motion, strict=True) if not m >= min_motion_rad]
    if still:
        raise err(source, field, f"the robot does not move enough to identify its dynamics: joint(s) "
                  f"{', '.join(still)} move less than identification.min_joint_motion_rad = {min_motion_rad:g} rad "
                  "peak to peak")
    s = np.linalg.svd(Wb, compute_uv=False) if Wb.size else np.zeros(1)
    tol = max(Wb.shape) * np.finfo(float).eps * (s[0] if s.size else 0.0)
    rank = int(np.sum(s > tol))
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else float("inf")
    if rank < Wb.shape[1]:
        raise err(source, field, f"the base regressor on the data has rank {rank} < {Wb.shape[1]} base parameters: "
                  "the motion does not excite every base parameter")
    if not cond <= max_cond:
        raise err(source, field, f"the base regressor on the data has condition number {cond:.3g} > "
                  f"identification.max_cond_base_regressor_data = {max_cond:.3g}: the motion does not excite "
                  "every base parameter")
    return cond


def add_result_gates(
    gates: QualityGates, cfg: Config, cond_data: float, cond_design: float | None, rms_over_noise: np.ndarray,
    predicted_Nm: np.ndarray, effort_limit_Nm: np.ndarray, physical_status: str = "Solve_Succeeded",
    joint_numbers: np.ndarray | None = None,
) -> None:
    """The result gates (see module doc) with the thresholds of ``cfg`` (stage Config). The per-joint
    arrays hold the measured joints only; ``joint_numbers`` (1-based) names them (default 1..n)."""
    ratio = np.asarray(rms_over_noise, float)
    numbers = np.arange(1, ratio.size + 1) if joint_numbers is None else np.asarray(joint_numbers, int)
    gates.require("physical_fit_status", is_success(physical_status),
                  f"IPOPT returned {physical_status} for the physically consistent fit (identification."
                  "physical_max_iter)")
    if cond_design is not None:
        gates.check("cond_data_over_design", cond_data / cond_design, "<=", cfg.max_cond_data_over_design,
                    "fitted base regressor on the data vs the design criterion (identification."
                    "max_cond_data_over_design)")
    worst = int(np.nanargmax(ratio)) if ratio.size and np.any(np.isfinite(ratio)) else 0
    gates.check("validation_rms_over_noise", float(np.max(ratio)) if ratio.size else float("nan"), "<=",
                cfg.max_validation_rms_over_noise,
                f"worst joint {numbers[worst]}; identification.max_validation_rms_over_noise")
    lim = np.asarray(effort_limit_Nm, float)
    over = np.max(np.abs(predicted_Nm), axis=0) / lim if len(predicted_Nm) else np.zeros_like(lim)
    j = int(np.argmax(over))
    gates.check("predicted_torque_over_limit", float(over[j]), "<=", cfg.max_predicted_torque_over_limit,
                f"joint {numbers[j]}: max |predicted torque| on the validation path / torque limit "
                f"{lim[j]:.4g} N·m; identification.max_predicted_torque_over_limit")
