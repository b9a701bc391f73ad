"""Sampled motions and joint states as CSV for controllers: one header line, SI units in the column names.

Motion: ``t_s, q_<joint>_rad..., qd_<joint>_rad_s..., qdd_<joint>_rad_s2..., tau_ff_<joint>_Nm...``
(every joint in each group, the groups in this order). Joint states: ``t_s, q_<joint>_rad...,
qd_<joint>_rad_s..., effort_<joint>_Nm...``. Numbers are written with 17 significant digits (a
float64 reads back bit for bit); the file is written atomically.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pipeline.core.artefacts import write_text
from pipeline.core.errors import DataFileError
from pipeline.exchange.motion import JointStates, SampledMotion

MOTION_GROUPS = (("q_", "_rad"), ("qd_", "_rad_s"), ("qdd_", "_rad_s2"), ("tau_ff_", "_Nm"))
STATE_GROUPS = (("q_", "_rad"), ("qd_", "_rad_s"), ("effort_", "_Nm"))


def motion_columns(joint_names: Sequence[str], groups: Sequence[tuple[str, str]] = MOTION_GROUPS) -> list[str]:
    """The header: ``t_s`` then each group's column for every joint."""
    return ["t_s", *(f"{prefix}{name}{suffix}" for prefix, suffix in groups for name in joint_names)]


def _write(path: str | Path, columns: list[str], t_s: np.ndarray, blocks: Sequence[np.ndarray]) -> Path:
    buffer = io.StringIO()
    table = np.column_stack([t_s, *blocks]) if t_s.size else np.zeros((0, len(columns)))
    np.savetxt(buffer, table, delimiter=",", fmt="%.17g", header=",".join(columns), comments="")
    return write_text(path, buffer.getvalue())


def _read(path: str | Path, groups: Sequence[tuple[str, str]]) -> tuple[list[str], np.ndarray, list[np.ndarray]]:
    source = Path(path)
    try:
        with source.open() as handle:
            header = handle.readline().strip().split(",")
            table = np.loadtxt(handle, delimiter=",", ndmin=2)
    except (OSError, ValueError) as exc:
        raise DataFileError(source, None, f"cannot read: {exc}") from exc
    header = [h.strip() for h in header]
    if not header or header[0] != "t_s":
        raise DataFileError(source, "header", f"the first column is {header[:1]}, expected t_s")
    n_cols = len(header) - 1
    if n_cols % len(groups):
        raise DataFileError(source, "header", f"{n_cols} data columns are not {len(groups)} groups of joints")
    n = n_cols // len(groups)
    first_prefix, first_suffix = groups[0]
    names = []
    for column in header[1:1 + n]:
        if not (column.startswith(first_prefix) and column.endswith(first_suffix)):
            raise DataFileError(source, "header", f"column {column!r} is not {first_prefix}<joint>{first_suffix}")
        names.append(column[len(first_prefix):len(column) - len(first_suffix)])
    expected = motion_columns(names, groups)
    if header != expected:
        wrong = next(h for h, e in zip(header, expected, strict=True) if h != e)
        raise DataFileError(source, "header", f"column {wrong!r} where {expected[header.index(wrong)]!r} belongs")
    if table.size and table.shape[1] != len(header):
        raise DataFileError(source, None, f"{table.shape[1]} values per row, the header names {len(header)}")
    table = table.reshape(-1, len(header))
    blocks = [table[:, 1 + g * n:1 + (g + 1) * n] for g in range(len(groups))]
    return names, table[:, 0], blocks


def is_joint_state_csv(path: str | Path) -> bool:
    """A ``.csv`` file whose header starts with ``t_s,q_``: the joint-state (or motion) layout, not a table
    of poses."""
    source = Path(path)
    if source.suffix.lower() != ".csv" or not source.is_file():
        return False
    try:
        with source.open(encoding="utf-8-sig") as handle:
            first = handle.readline()
    except (OSError, UnicodeDecodeError):
        return False
    cells = [c.strip() for c in first.split(",")]
    return len(cells) > 1 and cells[0] == "t_s" and cells[1].startswith(STATE_GROUPS[0][0])


def write_motion_csv(path: str | Path, motion: SampledMotion) -> Path:
    """``motion`` as CSV (header ``t_s,q_<j>_rad,...,qd_<j>_rad_s,...,qdd_<j>_rad_s2,...,tau_ff_<j>_Nm``)."""
    return _write(path, motion_columns(motion.joint_names), motion.t_s,
                  [motion.q_rad, motion.qd_rad_s, motion.qdd_rad_s2, motion.tau_ff_Nm])


def read_motion_csv(path: str | Path) -> SampledMotion:
    """A motion CSV written by :func:`write_motion_csv` (or by hand in its layout)."""
    names, t_s, (q, qd, qdd, tau) = _read(path, MOTION_GROUPS)
    try:
        return SampledMotion(tuple(names), t_s, q, qd, qdd, tau)
    except DataFileError as exc:
        raise DataFileError(path, exc.field, exc.problem) from exc


def write_joint_states_csv(path: str | Path, states: JointStates) -> Path:
    """``states`` as CSV (header ``t_s,q_<j>_rad,...,qd_<j>_rad_s,...,effort_<j>_Nm``)."""
    return _write(path, motion_columns(states.joint_names, STATE_GROUPS), states.t_s,
                  [states.q_rad, states.qd_rad_s, states.effort_Nm])


def read_joint_states_csv(path: str | Path) -> JointStates:
    """A joint-state CSV written by :func:`write_joint_states_csv`."""
    names, t_s, (q, qd, effort) = _read(path, STATE_GROUPS)
    try:
        return JointStates(tuple(names), t_s, q, qd, effort)
    except DataFileError as exc:
        raise DataFileError(path, exc.field, exc.problem) from exc
