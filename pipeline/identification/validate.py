"""Validation of an identified model (paper ``004_abbe750b8bbcc3aa.txt`` §4.3, Fig. 5(b)).

* Torque prediction on a trajectory that was not used for the fit: the EN ISO 9283 path
  (DESIGN.md; built with stage 3's ``iso9283_path`` + ``cartesian_reference`` from the run's
  ``control.iso`` section, robot ``run_defaults`` included) or, when that path is out of reach of
  the robot, a different random Fourier trajectory (the label says which).
  The measured torque (sensor noise included) is compared with the model's prediction at the
  commanded states: per joint RMS error and relative error ``RMS / RMS(measured)``.
* In simulation, each base parameter's error against the truth in units of its estimated
  standard deviation, ``z_k = (beta_hat_k - beta_true_k) / sigma_k`` (tests only, or
  :func:`truth_scores` when the stage is explicitly allowed to score against the truth).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.control.config import ControlConfig
from pipeline.core.errors import PipelineError
from pipeline.identification import fourier
from pipeline.identification.config import ExcitationConfig
from pipeline.identification.regressor import BaseParameters
from pipeline.robot.defaults import ik_seeds_or_derived_rad, iso_or_derived, iso_rotation
from pipeline.robot.iso9283 import IsoPathConfig, iso9283_path
from pipeline.robot.model import RobotModel
from pipeline.robot.paths import start_configuration
from pipeline.robot.reference import cartesian_reference


@dataclass
class ValidationTrajectory:
    t_s: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    label: str
    note: str = ""


def run_control_config(run: object) -> ControlConfig:
    """The run's validated ``control`` section (robot ``run_defaults`` merged in; read through the
    stage's ``CONFIG_READS``), or the built-in ``ControlConfig()`` when the run has none (a plain
    dict: module missing, or a bare RunConfig)."""
    sections = getattr(run, "sections", None) if run is not None else None
    control = sections.get("control") if isinstance(sections, dict) else None
    return control if isinstance(control, ControlConfig) else ControlConfig()


def run_iso_config(run: object) -> IsoPathConfig:
    """The EN ISO 9283 path settings of the run (``control.iso``, :func:`run_control_config`)."""
    return run_control_config(run).iso


def ik_seeds_rad(control: ControlConfig | None, robot: RobotModel) -> np.ndarray:
    """The run's ``control.ik_seeds_deg`` as (k, nq) rad; none given -> seeds derived from the
    robot (:func:`pipeline.robot.defaults.ik_seeds_or_derived_rad`). A seed of the wrong length
    raises :class:`PipelineError` naming the field."""
    nq = robot.nq
    seeds = getattr(control, "ik_seeds_deg", None)
    if seeds is None or len(seeds) == 0:
        return ik_seeds_or_derived_rad(robot, None)
    arr = [np.asarray(s, float).ravel() for s in seeds]
    bad = [i for i, s in enumerate(arr) if s.size != nq]
    if bad:
        raise PipelineError(None, f"control.ik_seeds_deg[{bad[0]}]",
                            f"{arr[bad[0]].size} values, the robot has {nq} joints")
    return np.radians(np.vstack(arr))


def iso_validation_trajectory(robot: RobotModel, sample_time_s: float,
                             control: ControlConfig | None = None) -> ValidationTrajectory:
    """The ISO 9283 path of the run's ``control.iso`` as joint reference of the control stage's path
    frame (``control.path_frame``: the tracker's reflector or the TCP), started by IK
    from the run's ``control.ik_seeds_deg`` with its ``control.ik_tolerance_m`` (``control`` from
    :func:`run_control_config`; None: the built-in control defaults)."""
    cfg = ControlConfig() if control is None else control
    iso = iso_or_derived(robot, cfg.iso)
    rotation = iso_rotation(robot, iso.plane, iso.tool_orientation)
    path = iso9283_path(robot, iso.edge_m, iso.centre_m, iso.plane, rotation, iso.corner_fraction,
                        iso.large_circle_fraction, iso.small_circle_fraction, tuple(iso.segments))
    seeds = ik_seeds_rad(cfg, robot)
    frame = robot.frame_reflector if cfg.path_frame == "reflector" else robot.frame_tcp   # as the control stage
    q_start = start_configuration(robot, path.poses([0.0])[0], seeds, frame)
    ref = cartesian_reference(robot, path, sample_time_s, iso.speed_m_s, iso.acceleration_m_s2,
                              iso.jerk_m_s3, q_start, frame, cfg.ik_tolerance_m)
    return ValidationTrajectory(ref.t_s, ref.q_d, ref.v_d, ref.a_d, "iso9283",
                                f"edge {iso.edge_m} m, centre {list(iso.centre_m)} m, {iso.speed_m_s} m/s")


def fourier_validation(robot: RobotModel, limits: fourier.ExcitationLimits, ex: ExcitationConfig,
                       sample_time_s: float, rng: np.random.Generator) -> ValidationTrajectory:
    """One period of a random feasible Fourier trajectory (the fallback when the ISO path cannot be used)."""
    tr = fourier.random_feasible_trajectories(robot, limits, ex.harmonics, ex.base_frequency_hz, 1, rng)[0]
    t = np.arange(int(round(tr.period_s / sample_time_s))) * sample_time_s
    q, v, a = tr.evaluate(t)
    return ValidationTrajectory(t, q, v, a, "fourier", "a random feasible Fourier trajectory")


def validation_trajectory(
    robot: RobotModel, sample_time_s: float, fallback: Callable[[], ValidationTrajectory], use_iso: bool = True,
    control: ControlConfig | None = None,
) -> ValidationTrajectory:
    """ISO 9283 path of the run's control section (None: built-in defaults) if it can be built for
    ``robot`` (within limits), else ``fallback()`` with ``note`` saying the real reason."""
    note = ""
    if use_iso:
        try:
            vt = iso_validation_trajectory(robot, sample_time_s, control)
            lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
            out_q = np.flatnonzero(np.any((vt.q < lo) | (vt.q > hi), axis=0))
            out_v = np.flatnonzero(np.any(np.abs(vt.v) > robot.limits.velocity_rad_s * 1.0001, axis=0))
            if not out_q.size and not out_v.size:
                return vt
            note = "the ISO 9283 path from the IK seeds of control.ik_seeds_deg leaves " + "; ".join(
                [f"the position limits of joint(s) {', '.join(str(j + 1) for j in out_q)}"] * bool(out_q.size)
                + [f"the velocity limits of joint(s) {', '.join(str(j + 1) for j in out_v)}"] * bool(out_v.size))
        except (PipelineError, ImportError) as exc:
            note = f"ISO 9283 path unavailable: {exc}"
    vt = fallback()
    vt.note = (note + "; " if note else "") + vt.note
    return vt


def torque_rms(measured: np.ndarray, predicted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per joint RMS error and relative error ``RMS(err) / RMS(measured)``."""
    err = np.asarray(measured, float) - np.asarray(predicted, float)
    rms = np.sqrt(np.mean(err**2, axis=0))
    rel = rms / np.maximum(np.sqrt(np.mean(np.asarray(measured, float) ** 2, axis=0)), 1e-12)
    return rms, rel


def z_scores(beta: np.ndarray, sigma: np.ndarray, beta_true: np.ndarray) -> np.ndarray:
    return (np.asarray(beta) - np.asarray(beta_true)) / np.maximum(np.asarray(sigma), 1e-300)


def fraction_within(z: np.ndarray, k: float = 3.0) -> float:
    return float(np.mean(np.abs(z) <= k))


def truth_scores(real: Any,  # Any: the simulated hidden robot (its true parameters)
                  base: BaseParameters, beta: np.ndarray, sigma: np.ndarray) -> dict:
    """Score the base estimate against the hidden robot (evaluation only: call it after the
    estimate is final; the stage does so only with ``score_against_truth``)."""
    p_true = np.asarray(real.dynamic_parameters, float)
    beta_true = base.from_standard(p_true)
    z = z_scores(beta, sigma, beta_true)
    return {
        "beta_true": beta_true,
        "z": z,
        "fraction_within_3sigma": fraction_within(z, 3.0),
        "max_abs_z": float(np.max(np.abs(z))),
    }
