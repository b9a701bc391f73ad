"""Identification data: the hidden robot following a trajectory, a CSV file or a ROS 2 bag.

Paper ``004_abbe750b8bbcc3aa.txt`` §4.3: the excitation is run for several periods and joint
positions and motor torques are recorded. Two sources:

* **simulation**: ``real.execute_joint_trajectory`` (ideal tracking of the commanded Fourier
  trajectory; encoder and motor-torque noise added by the hidden robot's sensors);
* **files**: a recording of joint states (:func:`load_joint_recording`): a ROS 2 bag of
  ``sensor_msgs/JointState`` or the joint-state CSV of :mod:`pipeline.exchange.motion_csv`
  (``t_s, q_<joint>_rad..., qd_<joint>_rad_s..., effort_<joint>_Nm...``, as ``arm play`` logs it), joints
  matched by name; or a numbered CSV with a header (:func:`load_joint_csv`): columns ``t`` or ``t_s``
  (s, optional if ``sample_time_s`` is given), joint positions ``q1..qn`` and torques ``tau1..taun``.
  Motor-side columns (``side="motor"``) are
  converted with the gear matrix ``K`` of ``robot.yaml``: ``q = K^-1 q_motor``,
  ``tau = K^T tau_motor``.

Processing (:func:`process_periodic`, :func:`process_record`) turns them into samples of
``(q, v, a, tau)`` for the regressor; see :mod:`pipeline.identification.signals`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.core.errors import DataFileError
from pipeline.exchange.csv_header import number, sniff_delimiter
from pipeline.exchange.recording import read_recorded_joint_states
from pipeline.identification import signals
from pipeline.identification.fourier import FourierTrajectory
from pipeline.identification.joints import unmeasured_torque_columns
from pipeline.identification.regressor import RegressorModel, check_state_arrays
from pipeline.robot.model import RobotModel


@dataclass
class JointRecord:
    """Raw joint-side record: time, measured positions, measured torques (N, nq)."""

    t_s: np.ndarray
    q_rad: np.ndarray
    tau_Nm: np.ndarray
    source: str = ""
    line_numbers: np.ndarray | None = None  # file line of each sample (header = line 1), if from a file
    #: logged with non-uniform time stamps: the largest logged interval [s] and how it was resampled
    max_gap_s: float | None = None
    max_gap_where: str = ""  # "line 57": the logged sample that ends the largest interval
    resampling: str = ""
    #: torque columns that carry no signal (joint index -> reason), found on the logged values
    unmeasured: dict[int, str] = field(default_factory=dict)

    def where(self, k: int) -> str:
        """``"line 57"`` for a file record, else ``"sample 55"``."""
        if self.line_numbers is not None and 0 <= k < len(self.line_numbers):
            return f"line {int(self.line_numbers[k])}"
        return f"sample {k}"

    @property
    def sample_time_s(self) -> float:
        return float(np.median(np.diff(self.t_s)))

    def validate(self, nq: int, min_samples: int = 10) -> None:
        f = self.source or None
        t = np.asarray(self.t_s, float)
        for name, x in (("q", self.q_rad), ("tau", self.tau_Nm)):
            if x.ndim != 2 or x.shape[1] != nq:
                raise DataFileError(f, name, f"shape {x.shape}, expected (N, {nq})")
            if not np.all(np.isfinite(x)):
                k, j = (int(i) for i in np.argwhere(~np.isfinite(x))[0])
                raise DataFileError(f, f"{name}{j + 1}", f"NaN or inf ({self.where(k)})")
        if not (len(t) == len(self.q_rad) == len(self.tau_Nm)):
            raise DataFileError(
                f, "t/q/tau", f"mismatched lengths {len(t)}, {len(self.q_rad)}, {len(self.tau_Nm)}"
            )
        if len(t) < min_samples:
            raise DataFileError(f, "samples", f"{len(t)} samples, need at least {min_samples}")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            bad = np.flatnonzero(~np.isfinite(t[1:]) | (np.diff(t) <= 0))
            where = f" ({self.where(int(bad[0]) + 1)})" if bad.size else ""
            raise DataFileError(f, "t", f"time stamps must be finite and strictly increasing{where}")
        dt = np.diff(t)
        if np.max(np.abs(dt - np.median(dt))) > 1e-3 * np.median(dt) + 1e-9:
            raise DataFileError(f, "t", "samples are not uniformly spaced (resample first)")


def simulate_excitation(
    real: Any, traj: FourierTrajectory,  # Any: the simulated hidden robot (joint sensors)
    periods: int, sample_time_s: float, rng: np.random.Generator
) -> JointRecord:
    """The hidden robot runs ``periods`` periods of ``traj`` (ideal tracking), sampled every
    ``sample_time_s`` with its encoder and torque-sensor noise."""
    n_per = int(round(traj.period_s / sample_time_s))
    if abs(n_per * sample_time_s - traj.period_s) > 1e-9 * traj.period_s:
        raise DataFileError(
            None,
            "identification.sample_time_s",
            f"{sample_time_s} s does not divide the period {traj.period_s} s",
        )
    t = np.arange(n_per * periods) * sample_time_s
    q, v, a = traj.evaluate(t)
    meas = real.execute_joint_trajectory(t, q, v, a, rng)
    return JointRecord(meas.t_s, meas.q_rad, meas.tau_Nm, "simulation")


def read_csv_table(path: str | Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Read a numeric CSV file with a header line: ``(names, data (N, n_columns), line_numbers)``.

    The delimiter is that of the header line (``,``, ``;`` with decimal commas, or tab:
    :func:`pipeline.exchange.csv_header.sniff_delimiter`).
    ``line_numbers[k]`` is the file line of data row ``k`` (the header is line 1); blank lines are
    skipped. Every problem raises :class:`DataFileError` naming the file, the line and the column:
    a missing header, no data rows, a row with too few or too many values, a value that is not a
    number. NaN/inf values are returned as read (checked per column by :func:`load_joint_csv`).
    """
    path = Path(path)
    if not path.is_file():
        raise DataFileError(path, None, "file not found")
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(path, None, f"cannot read: {exc}") from None
    numbered = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip()]
    if not numbered:
        raise DataFileError(path, None, "empty file (expected a header line and data rows)")
    header_line, header_text = numbered[0]
    delimiter = sniff_delimiter(header_text)
    header = [h.strip() for h in header_text.split(delimiter)]
    if any(not h for h in header):
        raise DataFileError(path, f"line {header_line}", "empty column name in the header")
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataFileError(path, f"line {header_line}", f"duplicate column names {dup}")
    try:
        [float(h) for h in header]
    except ValueError:
        pass
    else:
        raise DataFileError(path, f"line {header_line}", "no header line (the first line is numbers)")
    rows = numbered[1:]
    if not rows:
        raise DataFileError(path, None, f"no data rows (only the header on line {header_line})")
    n_col = len(header)
    cells = []
    for line_no, text in rows:
        parts = text.split(delimiter)
        if len(parts) != n_col:
            raise DataFileError(path, f"line {line_no}",
                                f"{len(parts)} values, expected {n_col} (one per header column)")
        cells.append(parts)
    line_numbers = np.array([ln for ln, _ in rows], dtype=int)
    try:
        data = np.array(cells if delimiter != ";" else [[number(c, delimiter) for c in parts] for parts in cells],
                        dtype=float)
    except ValueError:
        for (line_no, _), parts in zip(rows, cells, strict=True):
            for name, cell in zip(header, parts, strict=True):
                try:
                    number(cell, delimiter)
                except ValueError:
                    raise DataFileError(path, f"line {line_no}",
                                        f"column {name}: {cell.strip()!r} is not a number") from None
        raise
    return header, data.reshape(len(rows), n_col), line_numbers


def load_joint_csv(
    path: str | Path,
    robot: RobotModel,
    side: str = "joint",
    sample_time_s: float | None = None,
    q_offset_rad: np.ndarray | None = None,
    min_samples: int = 10,
) -> JointRecord:
    """Read a numbered CSV record (``q1..qn``, ``tau1..taun``; the module docstring); ``side`` = "joint" or
    "motor". The time column is ``t`` or ``t_s``. Errors name the file, the column (``q3``) and the file
    line (header = line 1)."""
    path = Path(path)
    nq = robot.nq
    if side not in ("joint", "motor"):
        raise DataFileError(path, "side", f"must be 'joint' or 'motor', got {side!r}")
    header, data, line_numbers = read_csv_table(path)
    col = {h: i for i, h in enumerate(header)}
    time_name = "t_s" if "t_s" in col and "t" not in col else "t"
    q_names = [f"q{i + 1}" for i in range(nq)]
    tau_names = [f"tau{i + 1}" for i in range(nq)]
    missing = [n for n in q_names + tau_names if n not in col]
    if missing:
        raise DataFileError(path, "header", f"missing columns {missing} (found {header})")
    used = ([time_name] if time_name in col else []) + q_names + tau_names
    for name in used:
        bad = np.flatnonzero(~np.isfinite(data[:, col[name]]))
        if bad.size:
            raise DataFileError(path, name, f"NaN or inf on line {line_numbers[bad[0]]}"
                                + (f" ({bad.size} values)" if bad.size > 1 else ""))
    if len(data) < min_samples:
        raise DataFileError(path, "samples", f"{len(data)} data rows, need at least {min_samples}")
    q = data[:, [col[n] for n in q_names]]
    tau = data[:, [col[n] for n in tau_names]]
    if time_name in col:
        t = data[:, col[time_name]]
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            raise DataFileError(path, time_name,
                                f"time stamps must increase strictly (line {line_numbers[bad[0] + 1]})")
    elif sample_time_s is not None:
        t = np.arange(len(data)) * sample_time_s
    else:
        raise DataFileError(path, "t", "no time column and no sample_time_s given")
    if side == "motor":
        q, tau = motor_to_joint(q, tau, robot.actuation.gear_matrix)
    if q_offset_rad is not None:
        q = q + np.asarray(q_offset_rad, float)
    return _uniform_record(t, q, tau, str(path), line_numbers, nq, min_samples)


#: a record resampled onto more than this many uniform steps per logged sample is mostly gaps: refused
#: before the grid is built (a stray time stamp of 1e6 s would otherwise allocate gigabytes)
MAX_RESAMPLED_PER_LOGGED = 4


def _uniform_record(t: np.ndarray, q: np.ndarray, tau: np.ndarray, source: str, line_numbers: np.ndarray | None,
                    nq: int, min_samples: int) -> JointRecord:
    """A :class:`JointRecord` on uniform time stamps: non-uniform ones resampled
    (:func:`~pipeline.identification.signals.resample_uniform`), the largest gap and where it ends kept."""
    unmeasured = unmeasured_torque_columns(tau)
    max_gap_s, gap_where, how = None, "", ""
    dt = np.diff(t)
    if len(t) > 2 and np.max(np.abs(dt - np.median(dt))) > 1e-3 * np.median(dt) + 1e-9:
        grid_samples = (t[-1] - t[0]) / np.median(dt) + 1
        if not grid_samples <= MAX_RESAMPLED_PER_LOGGED * len(t):
            k = int(np.argmax(dt))
            where = f"line {line_numbers[k + 1]}" if line_numbers is not None else f"message {k + 2}"
            raise DataFileError(source, "t", f"the time stamps leave a gap of {dt[k]:g} s ({where}): the record's "
                                f"{len(t)} samples span {t[-1] - t[0]:g} s, {grid_samples:.3g} steps of the median "
                                f"interval {np.median(dt):g} s; cut the record at its gaps")
        logged_t = t
        res = signals.resample_uniform(t, q, tau)
        t, q, tau, max_gap_s, how = res.t_s, res.q, res.tau, res.max_gap_s, res.method
        if line_numbers is not None:
            gap_where = f"line {line_numbers[res.max_gap_index]}"
            line_numbers = line_numbers[np.searchsorted(logged_t, t, side="right") - 1]
        else:
            gap_where = f"message {int(res.max_gap_index) + 1}"
    rec = JointRecord(t, q, tau, source, line_numbers, max_gap_s, gap_where, how, unmeasured)
    rec.validate(nq, min_samples)
    return rec


def load_joint_recording(
    path: str | Path,
    robot: RobotModel,
    side: str = "joint",
    name_map: dict[str, str] | None = None,
    min_samples: int = 10,
) -> JointRecord:
    """A recording of joint states (a ROS 2 bag's ``sensor_msgs/JointState``, ``/joint_states`` or the one
    topic of that type, or the joint-state CSV; :func:`pipeline.exchange.recording.read_recorded_joint_states`)
    as a record: positions and efforts of the model's joints, matched by name in any order (``name_map`` =
    {recorded: model}, ``identification.joint_names``); other joints ignored. ``side="motor"`` converts
    through the gear matrix."""
    names = [str(n) for n in robot.model.names[1:]]
    states, _ = read_recorded_joint_states(path, names, name_map, field="identification.joint_names")
    for label, x in (("position", states.q_rad), ("effort", states.effort_Nm)):
        if not np.all(np.isfinite(x)):
            k, j = (int(i) for i in np.argwhere(~np.isfinite(x))[0])
            raise DataFileError(path, label, f"joint {names[j]}: empty or NaN in sample {k + 1}")
    if states.n_samples < min_samples:
        raise DataFileError(path, "samples", f"{states.n_samples} joint states, need at least {min_samples}")
    q, tau = states.q_rad, states.effort_Nm
    if side == "motor":
        q, tau = motor_to_joint(q, tau, robot.actuation.gear_matrix)
    return _uniform_record(states.t_s, q, tau, str(path), None, robot.nq, min_samples)


def motor_to_joint(
    q_motor: np.ndarray, tau_motor: np.ndarray, gear_matrix: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``q = K^-1 q_motor``, ``tau = K^T tau_motor`` (rows are samples)."""
    K = np.asarray(gear_matrix, float)
    q = np.linalg.solve(K, np.asarray(q_motor, float).T).T
    tau = (K.T @ np.asarray(tau_motor, float).T).T
    return q, tau


@dataclass
class ProcessedData:
    """Samples ready for estimation: regressor rows (sample-major) and torques."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    tau: np.ndarray  # (N, n_rows): the measured joints (RegressorModel.rows)
    Y: np.ndarray  # (N*n_rows, n_std) standard regressor after the parallel decimation
    sample_time_s: float
    noise_sigma_Nm: np.ndarray | None = None  # per raw sample, from the spread between periods
    #: (N, decimation, nq) full-rate velocities behind each block mean (process_periodic), for a
    #: model term non-linear in v (Stribeck) averaged like the regressor; None: ``v`` itself
    v_full: np.ndarray | None = None
    rows: np.ndarray | None = None  # the joints of the torque columns (RegressorModel.rows); None: all

    @property
    def n_samples(self) -> int:
        return self.q.shape[0]

    @property
    def v_blocks(self) -> np.ndarray:
        """(N, k, n_rows) velocities of the torque columns' joints whose mean of a function gives that
        function's processed sample."""
        vb = self.v[:, None, :] if self.v_full is None else self.v_full
        return vb if self.rows is None else vb[..., self.rows]

    @property
    def y(self) -> np.ndarray:
        return self.tau.ravel()


def _periodic_lowpass(x: np.ndarray, cutoff_hz: float, fs: float, order: int = 4) -> np.ndarray:
    """Zero-phase low-pass of one period of a periodic signal (three periods tiled)."""
    n = x.shape[0]
    tiled = np.concatenate([x, x, x], axis=0)
    return signals.lowpass(tiled, cutoff_hz, fs, order)[n : 2 * n]


def process_periodic(
    rec: JointRecord,
    reg: RegressorModel,
    samples_per_period: int,
    state_cutoff_hz: float,
    decimation: int,
    skip_periods: int = 0,
) -> ProcessedData:
    """Average over periods, filter the positions (zero phase, periodic), differentiate,
    build the regressor at the full rate, then decimate regressor rows and torques in parallel
    by block means of ``decimation`` samples.

    A block mean is a linear combination of equations applied to both sides, so the model stays
    exact (aliasing cannot bias it), and it keeps the torque noise white (sigma / sqrt(block)),
    which a low-pass before subsampling does not: its correlated noise would make the
    least-squares covariance too optimistic. ``noise_sigma_Nm`` is the per-sample torque noise
    estimated from the spread between periods (pooled over the period)."""
    nq = reg.nv
    rec.validate(nq)
    dt = rec.sample_time_s
    fs = 1.0 / dt
    n_periods = rec.q_rad.shape[0] // samples_per_period - skip_periods
    if n_periods < 1:
        raise DataFileError(rec.source or None, "samples", "less than one full period recorded")
    start = skip_periods * samples_per_period
    q_mean, _ = signals.average_periods(rec.q_rad[start:], samples_per_period)
    tau_mean, tau_std = signals.average_periods(rec.tau_Nm[start:], samples_per_period)
    noise = np.sqrt(np.mean(tau_std**2, axis=0)) if n_periods > 1 else np.full(nq, np.nan)
    q = _periodic_lowpass(q_mean, state_cutoff_hz, fs)
    n = q.shape[0]
    tiled = np.concatenate([q, q, q], axis=0)
    v3 = signals.differentiate(tiled, dt)
    a3 = signals.differentiate(v3, dt)
    v, a = v3[n : 2 * n], a3[n : 2 * n]
    Y = reg.stacked(q, v, a)
    rows = np.arange(nq) if reg.rows is None else np.asarray(reg.rows)
    nr = len(rows)
    tau_mean, noise = tau_mean[:, rows], noise[rows]
    dec = max(int(decimation), 1)
    m = n // dec
    if m * nr <= Y.shape[1]:
        raise DataFileError(
            rec.source or None, "identification.decimation",
            f"{m} samples after decimation by {dec} are too few for {Y.shape[1]} parameters",
        )
    p = Y.shape[1]
    Yd = Y[: m * dec * nr].reshape(m, dec, nr, p).mean(axis=1).reshape(m * nr, p)
    taud = tau_mean[: m * dec].reshape(m, dec, nr).mean(axis=1)
    mid = np.arange(m) * dec + dec // 2
    return ProcessedData(q[mid], v[mid], a[mid], taud, Yd, dt * dec, noise, v[: m * dec].reshape(m, dec, nq),
                         reg.rows)


def process_record(
    rec: JointRecord,
    reg: RegressorModel,
    state_cutoff_hz: float | None,
    decimation: int | None,
    border_samples: int = 20,
) -> ProcessedData:
    """Non-periodic record (e.g. the TX40 file): filter positions, differentiate, decimate
    states and torques in parallel (zero-phase low-pass then every ``decimation``-th sample),
    and drop ``border_samples`` decimated samples at both ends (filter transients). A cut-off or
    decimation of None follows from the record's rate (:func:`signals.record_filter_settings`)."""
    nq = reg.nv
    rec.validate(nq)
    dt = rec.sample_time_s
    fs = 1.0 / dt
    state_cutoff_hz, decimation = signals.record_filter_settings(fs, state_cutoff_hz, decimation)
    st = signals.states_from_positions(rec.q_rad, dt, state_cutoff_hz)
    q = signals.decimate(st.q, decimation, fs)
    v = signals.decimate(st.v, decimation, fs)
    a = signals.decimate(st.a, decimation, fs)
    tau = signals.decimate(rec.tau_Nm if reg.rows is None else rec.tau_Nm[:, reg.rows], decimation, fs)
    b = border_samples
    if q.shape[0] <= 2 * b + 1:
        raise DataFileError(rec.source or None, "samples", f"{rec.q_rad.shape[0]} samples are too few")
    q, v, a, tau = (x[b:-b] if b > 0 else x for x in (q, v, a, tau))
    check_state_arrays(q, v, a, nq, rec.source or None)
    return ProcessedData(q, v, a, tau, reg.stacked(q, v, a), dt * decimation, rows=reg.rows)


# ------------------------------------------------------------ the stiction band (an arm whose dry friction sticks)
#: the stiction band of an arm whose dry friction sticks, in multiples of the model's Coulomb smoothing width
#: (``tanh(2) = 0.96``: below ``2 w`` the smooth sign is not yet the Coulomb level;
#: :mod:`pipeline.identification.validate`)
STICTION_BAND_OVER_WIDTH = 2.0


def stiction_band_speed(coulomb_width_rad_s: float) -> float:
    """``v_s = STICTION_BAND_OVER_WIDTH * w`` (rad/s): below it a joint whose dry friction sticks is held
    or breaking away, and the model's ``tanh(v / w)`` is a smoothing of the sign, not a friction law."""
    return STICTION_BAND_OVER_WIDTH * float(coulomb_width_rad_s)


def in_stiction_band(v_rad_s: np.ndarray, coulomb_width_rad_s: float) -> np.ndarray:
    """``|v| < v_s`` elementwise (:func:`stiction_band_speed`; ``w = 0``: only ``v = 0``)."""
    return np.abs(np.asarray(v_rad_s, float)) < max(stiction_band_speed(coulomb_width_rad_s), 1e-300)


@dataclass
class StictionExclusion:
    """The samples a fit on an arm whose dry friction sticks leaves out (:func:`without_stiction_band`)."""

    band_rad_s: float                 # v_s
    in_band_per_joint: np.ndarray     # (n_rows,) int: samples in which that joint's block is in the band
    n_left_out: int                   # samples left out (any joint in the band)
    n_total: int                      # samples before


def without_stiction_band(data: ProcessedData, coulomb_width_rad_s: float) -> tuple[ProcessedData, StictionExclusion]:
    """``data`` without the samples in which a measured joint is in the stiction band, and what was left out.

    A joint held by its dry friction or breaking away carries the torque its drive commands within the
    friction band, not a function of the state (the validation leaves such samples out for the same
    reason, :mod:`pipeline.identification.validate`); fitted, they pull the Coulomb level towards the
    breakaway torque. Sample ``k`` is in the band for joint ``j`` when a full-rate velocity of its
    decimation block (:attr:`ProcessedData.v_blocks`) has ``|v_j| < v_s`` or the block holds a reversal
    (``v_j`` of both signs: the continuous velocity crossed the band between two readings). The whole
    sample (all its rows) is left out, so every sample keeps one row per measured joint; the torque noise
    (``noise_sigma_Nm``, from the spread between periods) is kept."""
    vb = data.v_blocks
    band = (np.any(in_stiction_band(vb, coulomb_width_rad_s), axis=1)
            | (np.any(vb > 0.0, axis=1) & np.any(vb < 0.0, axis=1)))      # (N, n_rows)
    keep = ~np.any(band, axis=1)
    n, nr = data.tau.shape
    Y = data.Y.reshape(n, nr, -1)[keep].reshape(-1, data.Y.shape[1])
    kept = ProcessedData(data.q[keep], data.v[keep], data.a[keep], data.tau[keep], Y, data.sample_time_s,
                         data.noise_sigma_Nm, None if data.v_full is None else data.v_full[keep], data.rows)
    return kept, StictionExclusion(stiction_band_speed(coulomb_width_rad_s), np.sum(band, axis=0).astype(int),
                                   int(n - np.sum(keep)), int(n))
