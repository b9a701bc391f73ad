"""Measurements: the simulated laser tracker on the hidden robot, or a CSV file.

CSV format (one row per configuration, comma separated, header recommended)::

    q1,q2,q3,q4,q5,q6,x,y,z[,rx,ry,rz]

``q*`` joint angles in rad (Pinocchio order), ``x, y, z`` the reflector position in the tracker
frame in m, optional ``rx, ry, rz`` the rotation vector (axis * angle, rad) of the reflector frame
in the tracker frame (a 6-D tracker probe); used by the validation only. Any problem (missing
file, wrong column count, non-numeric or NaN/inf value, too few rows) raises
:class:`pipeline.errors.DataFileError` naming the file, the row/column and the problem, before
anything is written.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import DataFileError


@dataclass
class Measurements:
    """Joint configurations and tracker readings (tracker frame)."""

    Q: np.ndarray                 # (N, nq) rad
    Y: np.ndarray                 # (N, 3) m
    sigma_m: np.ndarray           # (N,) isotropic 1-sigma of each reading
    source: str                   # "simulated tracker" or the file path
    rotvec: np.ndarray | None = None   # (N, 3) optional orientation
    n_requested: int = 0          # configurations commanded (simulated), before visibility
    invisible: np.ndarray | None = None  # commanded configurations the tracker could not see

    def __len__(self) -> int:
        return len(self.Q)


def measure_simulated(real, Q: np.ndarray, rng: np.random.Generator) -> Measurements:
    """Command ``Q`` on the real robot and read the tracker; invisible rows are dropped."""
    Q = np.atleast_2d(np.asarray(Q, float))
    reading = real.tracker.measure(Q, rng)
    vis = np.asarray(reading.visible, bool)
    return Measurements(Q[vis], np.asarray(reading.position_m)[vis], np.asarray(reading.sigma_m)[vis],
                        "simulated tracker", None, len(Q), Q[~vis])


def noise_model_sigma(robot, Y: np.ndarray) -> np.ndarray:
    """Sigma of the robot's tracker noise model at the range of each reading."""
    return robot.tracker.noise_const_m + robot.tracker.noise_per_m * np.linalg.norm(Y, axis=1)


def read_csv(path: str | Path, robot, min_rows: int = 1) -> Measurements:
    """Read and validate a measurement CSV (format in the module docstring)."""
    path = Path(path)
    nq = robot.nq
    names = [f"q{i}" for i in range(1, nq + 1)] + ["x", "y", "z"]
    if not path.is_file():
        raise DataFileError(path, "file", "does not exist")
    try:
        with path.open(newline="") as fh:
            rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DataFileError(path, "file", f"cannot be read as CSV ({exc})") from None
    if not rows:
        raise DataFileError(path, "rows", "the file is empty")
    header = [c.strip().lower() for c in rows[0]]
    has_header = any(not _is_number(c) for c in header)
    if has_header:
        allowed = (names, names + ["rx", "ry", "rz"])
        if header not in allowed:
            raise DataFileError(path, "header", f"expected columns {','.join(names)}[,rx,ry,rz], got "
                                f"{','.join(header)}")
        ncol = len(header)
        data_rows = rows[1:]
        first_line = 2
    else:
        ncol = len(rows[0])
        if ncol not in (nq + 3, nq + 6):
            raise DataFileError(path, "row 1", f"expected {nq + 3} or {nq + 6} columns "
                                f"({','.join(names)}[,rx,ry,rz]), got {ncol}")
        data_rows = rows
        first_line = 1
    values = np.empty((len(data_rows), ncol))
    for k, r in enumerate(data_rows):
        line = first_line + k
        if len(r) != ncol:
            raise DataFileError(path, f"row {line}", f"expected {ncol} columns, got {len(r)}")
        for j, c in enumerate(r):
            try:
                v = float(c)
            except ValueError:
                col = header[j] if has_header else f"column {j + 1}"
                raise DataFileError(path, f"row {line}, {col}", f"not a number: {c.strip()!r}") from None
            if not np.isfinite(v):
                col = header[j] if has_header else f"column {j + 1}"
                raise DataFileError(path, f"row {line}, {col}", f"NaN or infinite value {c.strip()!r}")
            values[k, j] = v
    if len(values) < min_rows:
        raise DataFileError(path, "rows", f"{len(values)} measurement rows, need at least {min_rows} "
                            "(one per identifiable parameter)")
    Q = values[:, :nq]
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    bad = np.flatnonzero(np.any((Q < lo - 1e-9) | (Q > hi + 1e-9), axis=1))
    if bad.size:
        raise DataFileError(path, f"row {first_line + int(bad[0])}", "joint angles outside the robot's limits "
                            "(angles must be in rad)")
    Y = values[:, nq : nq + 3]
    rot = values[:, nq + 3 : nq + 6] if ncol == nq + 6 else None
    return Measurements(Q, Y, noise_model_sigma(robot, Y), str(path), rot, len(Q), np.zeros((0, nq)))


def write_csv(path: str | Path, meas: Measurements) -> Path:
    """Write measurements in the format :func:`read_csv` reads."""
    path = Path(path)
    nq = meas.Q.shape[1]
    header = [f"q{i}" for i in range(1, nq + 1)] + ["x", "y", "z"]
    cols = [meas.Q, meas.Y]
    if meas.rotvec is not None:
        header += ["rx", "ry", "rz"]
        cols.append(meas.rotvec)
    data = np.concatenate(cols, axis=1)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for row in data:
            w.writerow([repr(float(v)) for v in row])
    return path


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True
