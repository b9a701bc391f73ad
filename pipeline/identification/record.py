"""The user's joint record (``identification.data_file``: CSV or ROS 2 bag): read and checked before any stage runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.core.errors import ConfigError, DataFileError
from pipeline.exchange.recording import is_recording
from pipeline.identification import measure as meas_mod
from pipeline.identification.config import DATA_BORDER_SAMPLES, MAX_SAMPLE_TIME_S, Config
from pipeline.identification.signals import record_filter_settings
from pipeline.robot.model import RobotModel


def load_user_record(cfg: Config, robot: RobotModel) -> meas_mod.JointRecord:
    """Read and check ``cfg.data_file``: format, columns, NaN, time stamps (non-uniform ones are
    resampled, :func:`~pipeline.identification.signals.resample_uniform`, unless the largest gap is
    longer than half the period of the position filter's cut-off), joint limits, enough samples for
    the held-out fit, and a position cut-off below the Nyquist frequency."""
    file = cfg.data_file
    if is_recording(file):
        rec = meas_mod.load_joint_recording(file, robot, cfg.data_side, cfg.joint_names or None)
    else:
        rec = meas_mod.load_joint_csv(file, robot, cfg.data_side)
    check_record_limits(rec, robot, file)
    check_record_signals(rec, cfg, file)
    dt = rec.sample_time_s
    fs = 1.0 / dt
    if dt > MAX_SAMPLE_TIME_S:
        unit = next((name for name, scale in (("milliseconds", 1e3), ("microseconds", 1e6), ("nanoseconds", 1e9))
                     if dt / scale <= MAX_SAMPLE_TIME_S), None)
        hint = f" (the values look like {unit})" if unit else ""
        raise DataFileError(file, "t", f"column t implies a sample interval of {dt:g} s ({fs:g} Hz sample rate), "
                            f"implausible for a torque record (at most {MAX_SAMPLE_TIME_S:g} s, typically "
                            f"0.1-10 ms): the t column must be in seconds{hint}")
    cutoff_hz, decimation = record_filter_settings(fs, cfg.data_cutoff_hz, cfg.data_decimation)
    if not cutoff_hz < 0.5 * fs:
        raise ConfigError(None, "identification.data_cutoff_hz",
                          f"{cutoff_hz} Hz is not below the Nyquist frequency {0.5 * fs:g} Hz of {file} "
                          f"(its time stamps imply a {fs:g} Hz sample rate; t must be in seconds); set it below "
                          f"{0.5 * fs:g} Hz or leave it unset (null: from the rate)")
    max_gap = 0.5 / cutoff_hz   # half the period of the filter's cut-off: the band it keeps is sampled
    if rec.max_gap_s is not None and rec.max_gap_s > max_gap:
        raise DataFileError(file, "t", f"the time stamps leave a gap of {rec.max_gap_s:g} s ({rec.max_gap_where}), "
                            f"longer than 1 / (2 x identification.data_cutoff_hz) = {max_gap:g} s: the position "
                            "filter's band cannot be resampled across it; cut the record there or lower data_cutoff_hz")
    n_raw = rec.q_rad.shape[0]
    n_proc = -(-n_raw // decimation) - 2 * DATA_BORDER_SAMPLES
    n_train = int(cfg.data_train_fraction * n_proc)
    n_params = 10 * (robot.model.njoints - 1) + 4 * robot.nq  # standard parameters >= base ones
    # the physically consistent fit (standard regressor) needs more samples than parameters
    if n_train <= n_params or n_proc - n_train < 1:
        need_train = n_params + 1
        need_proc = int(np.ceil(need_train / cfg.data_train_fraction)) + 1 + 2 * DATA_BORDER_SAMPLES
        need_raw = need_proc * decimation
        fix = (f"record at least about {need_raw} samples" if decimation == 1 else
               f"record at least about {need_raw} samples or lower identification.data_decimation "
               f"(now {decimation}) to {max(1, n_raw // need_proc)}")
        raise DataFileError(
            file, "samples",
            f"{n_raw} samples are too few: the fit on the first {cfg.data_train_fraction:g} of the record "
            f"(after decimation by {decimation}, {DATA_BORDER_SAMPLES} samples dropped at each "
            f"end) needs more samples than the {n_params} standard parameters; {fix}")
    return rec



def check_record_signals(rec: meas_mod.JointRecord, cfg: Config, file: str | Path) -> None:
    """The record moves the arm and logs a torque signal, else one line naming the data file: no
    joint moving ``identification.min_joint_motion_rad`` peak to peak ("the joints never move"; a
    resting arm also logs constant torques), or, unless ``identification.joints`` names the joints,
    no torque column carrying a signal (:func:`~pipeline.identification.joints.unmeasured_torque_columns`)."""
    motion = np.ptp(rec.q_rad, axis=0) if len(rec.q_rad) else np.zeros(rec.q_rad.shape[1])
    if np.all(motion < cfg.min_joint_motion_rad) or not np.any(motion > 0):
        j = int(np.argmax(motion))
        raise DataFileError(file, "q", f"the joints never move: no q column spans "
                            f"identification.min_joint_motion_rad = {cfg.min_joint_motion_rad:g} rad peak to peak "
                            f"(the most, q{j + 1}: {motion[j]:.3g} rad); log the arm while it runs the excitation")
    nq = rec.q_rad.shape[1]
    if not cfg.joints and len(rec.unmeasured) == nq:
        columns: dict[str, list[str]] = {}
        for j, reason in sorted(rec.unmeasured.items()):
            columns.setdefault(reason, []).append(f"tau{j + 1}")
        why = "; ".join(f"{', '.join(cols)}: {reason}" for reason, cols in columns.items())
        raise DataFileError(file, "tau", f"no torque column carries a signal ({why}); log the joint torques "
                            "or the motor currents")


def check_record_limits(rec: meas_mod.JointRecord, robot: RobotModel, file: str | Path) -> None:
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    bad = np.argwhere((rec.q_rad < lo - 1e-6) | (rec.q_rad > hi + 1e-6))
    if bad.size:
        k, j = (int(i) for i in bad[0])
        q_rad = np.radians(rec.q_rad)
        hint = ("; q must be in rad (the values look like degrees)"
                if not np.any((q_rad < lo - 1e-6) | (q_rad > hi + 1e-6)) else "")
        raise DataFileError(file, f"q{j + 1}", f"{rec.where(k)}: {rec.q_rad[k, j]:.4f} rad outside the joint "
                            f"limits [{lo[j]:.4f}, {hi[j]:.4f}]{hint}")
