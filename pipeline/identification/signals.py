"""Signal processing for identification data (paper ``004_abbe750b8bbcc3aa.txt`` §4.1).

Positions are low-pass filtered with a zero-phase Butterworth filter (``scipy.signal.butter`` in
second-order sections + ``sosfiltfilt``), differentiated by central differences (``np.gradient``) to velocity and
acceleration, then the regressor rows and torques are decimated (the same zero-phase low-pass
before keeping every ``factor``-th sample, the "parallel decimation" of Gautier). Periodic
excitation data can be averaged over its periods, which divides the noise variance by the
number of periods.

Records logged with non-uniform time stamps are first resampled onto a uniform grid
(:func:`resample_uniform`): positions by a not-a-knot cubic spline (``scipy.interpolate.CubicSpline``,
C2, so the derivatives taken after filtering stay smooth), torques by linear interpolation
(``scipy.interpolate.make_interp_spline`` with ``k=1``: no overshoot between two logged values).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.interpolate
import scipy.signal

from pipeline.core.errors import DataFileError


@dataclass
class Resampled:
    """A record on a uniform grid (:func:`resample_uniform`)."""

    t_s: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    sample_time_s: float
    max_gap_s: float  # largest interval between two logged time stamps
    max_gap_index: int  # index of the logged sample that ends the largest gap
    method: str


def resample_uniform(t_s: np.ndarray, q: np.ndarray, tau: np.ndarray) -> Resampled:
    """Positions and torques logged at strictly increasing, non-uniform ``t_s`` on the uniform grid
    ``t_0 + k dt``, ``dt`` the median logged interval (module doc for the interpolation)."""
    t = np.asarray(t_s, float)
    dt_logged = np.diff(t)
    dt = float(np.median(dt_logged))
    n = int(np.floor((t[-1] - t[0]) / dt + 1e-9)) + 1
    grid = t[0] + np.arange(n) * dt
    q_u = scipy.interpolate.CubicSpline(t, np.asarray(q, float), axis=0)(grid)
    tau_u = scipy.interpolate.make_interp_spline(t, np.asarray(tau, float), k=1, axis=0)(grid)
    k = int(np.argmax(dt_logged))
    return Resampled(grid, q_u, tau_u, dt, float(dt_logged[k]), k + 1,
                     f"positions by a not-a-knot cubic spline, torques linearly, onto {dt * 1e3:.4g} ms steps "
                     f"(the median logged interval)")


def lowpass(x: np.ndarray, cutoff_hz: float, sample_rate_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0."""
    x = np.asarray(x, float)
    nyq = 0.5 * sample_rate_hz
    if not 0 < cutoff_hz < nyq:
        raise DataFileError(
            None, "cutoff_hz", f"{cutoff_hz} Hz must be in (0, {nyq}) (Nyquist of the data)"
        )
    # second-order sections: the (b, a) form loses all precision at cut-offs far below Nyquist
    sos = scipy.signal.butter(order, cutoff_hz / nyq, output="sos")
    padlen = 3 * (2 * len(sos) + 1)
    if x.shape[0] <= padlen:
        raise DataFileError(None, "samples", f"{x.shape[0]} samples are too few to filter")
    return scipy.signal.sosfiltfilt(sos, x, axis=0)


def differentiate(x: np.ndarray, sample_time_s: float) -> np.ndarray:
    """Central-difference derivative along axis 0 (second order, one-sided at the ends)."""
    return np.gradient(np.asarray(x, float), sample_time_s, axis=0)


@dataclass
class FilteredStates:
    """Filtered positions and their derivatives at the original sample rate."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray


def states_from_positions(
    q_meas: np.ndarray, sample_time_s: float, cutoff_hz: float, order: int = 4
) -> FilteredStates:
    """q filtered, v = dq/dt, a = dv/dt (each derivative of the filtered signal)."""
    fs = 1.0 / sample_time_s
    q = lowpass(q_meas, cutoff_hz, fs, order)
    v = differentiate(q, sample_time_s)
    a = differentiate(v, sample_time_s)
    return FilteredStates(q, v, a)


#: a recorded log's position low-pass by default: this cut-off, at most RECORD_CUTOFF_OVER_RATE x the rate
RECORD_CUTOFF_HZ = 20.0
RECORD_CUTOFF_OVER_RATE = 0.25
#: a recorded log is decimated by default to about this multiple of its position cut-off
RECORD_DECIMATED_RATE_OVER_CUTOFF = 5.0


def record_filter_settings(sample_rate_hz: float, cutoff_hz: float | None = None,
                           decimation: int | None = None) -> tuple[float, int]:
    """(position cut-off Hz, decimation) for a recorded log at ``sample_rate_hz``; given values are kept.

    Defaults follow from the rate: the cut-off ``min(20 Hz, rate / 4)`` (half the Nyquist
    frequency for slow logs: the 30 Hz ``joint_states`` of many ROS drivers get 7.5 Hz), and the
    decimation ``max(1, round(rate / (5 x cut-off)))`` (a 1 kHz log: 10, decimated to 100 Hz;
    25-80 Hz logs are not decimated): the decimated rate keeps five samples per cut-off period.
    """
    fs = float(sample_rate_hz)
    cutoff = float(cutoff_hz) if cutoff_hz is not None else min(RECORD_CUTOFF_HZ, RECORD_CUTOFF_OVER_RATE * fs)
    if decimation is None:
        decimation = max(1, int(round(fs / (RECORD_DECIMATED_RATE_OVER_CUTOFF * cutoff))))
    return cutoff, int(decimation)


def decimate(x: np.ndarray, factor: int, sample_rate_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase low-pass at 0.8 x the new Nyquist frequency, then keep every ``factor``-th row."""
    if factor <= 1:
        return np.asarray(x, float)
    cutoff = 0.8 * 0.5 * sample_rate_hz / factor
    return lowpass(x, cutoff, sample_rate_hz, order)[::factor]


def average_periods(x: np.ndarray, samples_per_period: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation over whole periods (axis 0 split into periods).

    Returns ``(mean (P, ...), std (P, ...))`` with ``P = samples_per_period``; a trailing
    incomplete period is dropped. Needs at least two periods for the standard deviation.
    """
    x = np.asarray(x, float)
    n_periods = x.shape[0] // samples_per_period
    if n_periods < 1:
        raise DataFileError(
            None, "samples", f"{x.shape[0]} samples < one period ({samples_per_period})"
        )
    xs = x[: n_periods * samples_per_period].reshape(n_periods, samples_per_period, *x.shape[1:])
    mean = xs.mean(axis=0)
    std = xs.std(axis=0, ddof=1) if n_periods > 1 else np.full_like(mean, np.nan)
    return mean, std
