"""The user's joint record (``identification.data_file``): read and checked before any stage runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.core.errors import ConfigError, DataFileError
from pipeline.identification import measure as meas_mod
from pipeline.identification.config import DATA_BORDER_SAMPLES, MAX_SAMPLE_TIME_S, Config
from pipeline.robot.model import RobotModel


def load_user_record(cfg: Config, robot: RobotModel) -> meas_mod.JointRecord:
    """Read and check ``cfg.data_file``: format, columns, NaN, time stamps (non-uniform ones are
    resampled, :func:`~pipeline.identification.signals.resample_uniform`, unless the largest gap is
    longer than half the period of the position filter's cut-off), joint limits, enough samples for
    the held-out fit, and a position cut-off below the Nyquist frequency."""
    file = cfg.data_file
    rec = meas_mod.load_joint_csv(file, robot, cfg.data_side)
    check_record_limits(rec, robot, file)
    dt = rec.sample_time_s
    fs = 1.0 / dt
    if dt > MAX_SAMPLE_TIME_S:
        hint = " (the values look like milliseconds)" if dt / 1000 <= MAX_SAMPLE_TIME_S else ""
        raise DataFileError(file, "t", f"column t implies a sample interval of {dt:g} s ({fs:g} Hz sample rate), "
                            f"implausible for a torque record (at most {MAX_SAMPLE_TIME_S:g} s, typically "
                            f"0.1-10 ms): the t column must be in seconds{hint}")
    if not cfg.data_cutoff_hz < 0.5 * fs:
        raise ConfigError(None, "identification.data_cutoff_hz",
                          f"{cfg.data_cutoff_hz} Hz is not below the Nyquist frequency {0.5 * fs:g} Hz of {file} "
                          f"(its column t implies a {fs:g} Hz sample rate; t must be in seconds)")
    max_gap = 0.5 / cfg.data_cutoff_hz   # half the period of the filter's cut-off: the band it keeps is sampled
    if rec.max_gap_s is not None and rec.max_gap_s > max_gap:
        raise DataFileError(file, "t", f"the time stamps leave a gap of {rec.max_gap_s:g} s ({rec.max_gap_where}), "
                            f"longer than 1 / (2 x identification.data_cutoff_hz) = {max_gap:g} s: the position "
                            "filter's band cannot be resampled across it; cut the record there or lower data_cutoff_hz")
    n_raw = rec.q_rad.shape[0]
    n_proc = -(-n_raw // cfg.data_decimation) - 2 * DATA_BORDER_SAMPLES
    n_train = int(cfg.data_train_fraction * n_proc)
    n_params = 10 * (robot.model.njoints - 1) + 4 * robot.nq  # standard parameters >= base ones
    # the physically consistent fit (standard regressor) needs more samples than parameters
    if n_train <= n_params or n_proc - n_train < 1:
        need_train = n_params + 1
        need_raw = (int(np.ceil(need_train / cfg.data_train_fraction)) + 1 + 2 * DATA_BORDER_SAMPLES) \
            * cfg.data_decimation
        raise DataFileError(
            file, "samples",
            f"{n_raw} samples are too few: the fit on the first {cfg.data_train_fraction:g} of the record "
            f"(after decimation by {cfg.data_decimation}, {DATA_BORDER_SAMPLES} samples dropped at each "
            f"end) needs more samples than the {n_params} standard parameters; record at least about {need_raw} "
            "samples")
    return rec



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
