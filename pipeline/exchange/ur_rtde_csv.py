"""A Universal Robots RTDE recording as the RTDE clients write it.

UR's RTDE Python client (``record.py``, its ``CSVWriter``: space-delimited) and ur_rtde
(``RTDEReceiveInterface.startFileRecording``: comma-delimited) write one header line of the recipe's output
names, a vector output as one column per element (``actual_q_0 .. actual_q_5``), then one row per sample:

* ``timestamp``: s since the controller started;
* ``actual_q_<i>`` (rad) and ``actual_qd_<i>`` (rad/s, optional), the joints in UR's order, base to wrist 3;
* the effort, the first there of :data:`EFFORT_OUTPUTS`: ``actual_current_as_torque_<i>`` (N·m, the
  measured currents as joint torques, PolyScope 5.23 and later), else ``actual_current_<i>`` (A, the
  measured motor currents). ``target_moment`` and ``target_current`` are the controller's commands, not
  measurements, and are never read. An effort in A is left as logged: the identification reads its unit
  against the nominal model (:mod:`pipeline.identification.effort_unit`) and ``arm verify`` against the
  feedforward.

**Stated assumption**: RTDE's joint ``i`` is the model's joint ``i`` in chain order (UR's joint order is the
chain's, base first); a model of another number of joints is refused.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.core.errors import DataFileError
from pipeline.exchange.csv_header import is_number
from pipeline.exchange.motion import JointStates

#: the effort columns read, in order of preference (module docstring)
EFFORT_OUTPUTS = ("actual_current_as_torque", "actual_current")
POSITION_OUTPUT = "actual_q"
VELOCITY_OUTPUT = "actual_qd"
TIME_OUTPUT = "timestamp"


def _cells(line: str) -> list[str]:
    return [c.strip() for c in (line.split(",") if "," in line else line.split())]


def _header(path: Path) -> list[str] | None:
    try:
        with path.open(encoding="utf-8-sig") as handle:
            first = handle.readline()
    except (OSError, UnicodeDecodeError):
        return None
    return _cells(first)


def is_rtde_csv(path: str | Path) -> bool:
    """A text file whose header names ``timestamp`` and ``actual_q_0`` (module docstring)."""
    source = Path(path)
    if not source.is_file():
        return False
    header = _header(source)
    return header is not None and TIME_OUTPUT in header and f"{POSITION_OUTPUT}_0" in header


def _vector(header: list[str], name: str) -> list[int]:
    """The columns ``name_0, name_1, ...`` in order (stops at the first index missing)."""
    index = {h: k for k, h in enumerate(header)}
    out: list[int] = []
    while f"{name}_{len(out)}" in index:
        out.append(index[f"{name}_{len(out)}"])
    return out


def read_rtde_csv(path: str | Path, n_joints: int) -> tuple[JointStates, str | None]:
    """The recording's joint states, joints named ``0 .. n-1`` in RTDE's order, times on the controller's
    clock (``timestamp``, s), and the effort output read (None: none, the effort is NaN). ``n_joints``: the
    model's; another number of ``actual_q`` columns is refused (module docstring)."""
    source = Path(path)
    header = _header(source)
    if header is None or TIME_OUTPUT not in header:
        raise DataFileError(source, "header", f"no {TIME_OUTPUT!r} column: not an RTDE recording")
    repeated = sorted({h for h in header if header.count(h) > 1})
    if repeated:
        raise DataFileError(source, "header", f"column(s) {repeated} more than once")
    q_cols = _vector(header, POSITION_OUTPUT)
    if len(q_cols) != n_joints:
        raise DataFileError(source, "header", f"{len(q_cols)} {POSITION_OUTPUT}_<i> columns for a model of "
                            f"{n_joints} joints (RTDE's joint i is read as the model's joint i)")
    effort_name = next((n for n in EFFORT_OUTPUTS if len(_vector(header, n)) == n_joints), None)
    lines = source.read_text(encoding="utf-8-sig").splitlines()
    rows = [(k + 1, ln) for k, ln in enumerate(lines[1:], start=1) if ln.strip()]
    try:   # one numpy parse of the whole table; a bad line is looked for only when it fails
        table = np.loadtxt([ln for _, ln in rows], delimiter="," if "," in lines[0] else None,
                           ndmin=2).reshape(len(rows), -1)
    except ValueError:
        table = np.empty((0, len(header)))
    if table.shape != (len(rows), len(header)):
        for line, text in rows:
            cells = _cells(text)
            if len(cells) != len(header):
                raise DataFileError(source, f"line {line}", f"{len(cells)} values, the header names {len(header)}")
            bad = next((c for c in cells if not is_number(c)), None)
            if bad is not None:
                raise DataFileError(source, f"line {line}", f"not a number: {bad!r}")
        raise DataFileError(source, "rows", "cannot be read as a table of numbers")
    if len(table) < 2:
        raise DataFileError(source, "rows", f"{len(table)} samples: too few for a recording")
    t = table[:, header.index(TIME_OUTPUT)]
    wrong = (np.flatnonzero(~np.isfinite(t[1:]) | ~(np.diff(t) > 0)) if np.all(np.isfinite(t[:1]))
             else np.array([-1]))
    if wrong.size:
        line = rows[int(wrong[0]) + 1][0]
        raise DataFileError(source, f"line {line}, {TIME_OUTPUT}", "time stamps must be finite and increase strictly")
    qd_cols = _vector(header, VELOCITY_OUTPUT)
    nan = np.full((len(table), n_joints), np.nan)
    qd = table[:, qd_cols] if len(qd_cols) == n_joints else nan
    effort = table[:, _vector(header, effort_name)] if effort_name else nan
    names = tuple(str(j) for j in range(n_joints))
    return JointStates(names, t, table[:, q_cols], qd, effort), effort_name

