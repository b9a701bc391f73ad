"""The table of a sweep: headline figures of many runs side by side (CSV, markdown, spread plot).

Each run contributes one row: its grid coordinates (``run``, ``robot``, ``seed``, the varied
settings), ``status`` ("ok" or the one-line error of a run that failed) and the scalar entries of
every stage's ``summary.json`` flattened to ``<stage>.<key>`` (nested dicts with ``.``, short
numeric lists with ``[i]``; long lists and strings in lists are left out).

The spread of a figure over the runs of one robot is summarised by its median and its 95th
percentile (``numpy.percentile``, linear interpolation), e.g. the calibration held-out RMS over
100 hidden robots (paper 000 reports its design study over 90 notional arms the same way).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from pipeline.core import artefacts

#: a cell of the table
Cell = str | int | float | bool | None
Row = dict[str, Cell]

#: headline figures shown in the markdown table and the plot when present (first match wins order)
DEFAULT_METRICS: tuple[str, ...] = (
    "calibration.heldout_rms_position_error_after_m",
    "identification.validation_torque_rms_Nm[0]",
    "control.tcp_error_rms_calibrated_kinematics_m",
    "trajectory.cp_duration_s",
)
#: longest list flattened element by element (one entry per joint)
MAX_LIST_LENGTH = 12
#: the grid columns, always first
KEY_COLUMNS: tuple[str, ...] = ("run", "robot", "seed", "status")


def is_timing_column(name: str) -> bool:
    """True for wall-clock figures (they differ between two runs of the same configuration)."""
    leaf = name.rsplit(".", 1)[-1]
    return "timings_s" in name or leaf.endswith("time_s") or leaf.endswith("_wall_s")


def flatten_summary(prefix: str, value: object, out: Row) -> None:
    """Flatten ``value`` into ``out`` under ``prefix`` (see the module docstring)."""
    if isinstance(value, Mapping):
        for key, item in value.items():
            flatten_summary(f"{prefix}.{key}", item, out)
    elif isinstance(value, list | tuple):
        numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        if numeric and 0 < len(value) <= MAX_LIST_LENGTH:
            for i, item in enumerate(value):
                out[f"{prefix}[{i}]"] = float(item)
    elif value is None or isinstance(value, str | bool | int | float):
        out[prefix] = value


def columns_of(rows: Sequence[Row], varied: Sequence[str] = ()) -> list[str]:
    """Key columns, the varied settings, then every other column sorted."""
    first = [*KEY_COLUMNS, *varied]
    rest = sorted({k for row in rows for k in row} - set(first))
    return first + rest


def _cell_text(value: Cell) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return str(value)


def to_csv(rows: Sequence[Row], columns: Sequence[str]) -> str:
    """CSV text (floats with ``repr``: full precision, the same run gives the same text)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell_text(row.get(c)) for c in columns])
    return buf.getvalue()


def numeric_values(rows: Sequence[Row], column: str) -> np.ndarray:
    """Finite float values of ``column`` over the rows that have one."""
    vals = [float(v) for r in rows if isinstance((v := r.get(column)), int | float) and not isinstance(v, bool)]
    arr = np.asarray(vals, float)
    return arr[np.isfinite(arr)]


def pick_metrics(rows: Sequence[Row], requested: Sequence[str] = ()) -> list[str]:
    """``requested`` (those present), else the :data:`DEFAULT_METRICS` present, else the first
    numeric non-timing figure of a stage."""
    present = {k for row in rows for k in row}
    if requested:
        return [m for m in requested if m in present]
    found = [m for m in DEFAULT_METRICS if m in present]
    if found:
        return found
    for col in sorted(present - set(KEY_COLUMNS)):
        if "." in col and not is_timing_column(col) and numeric_values(rows, col).size:
            return [col]
    return []


def spread(values: np.ndarray) -> dict[str, float]:
    """n, median, 95th percentile and maximum of ``values`` (NaN when empty)."""
    if values.size == 0:
        return {"n": 0.0, "median": math.nan, "p95": math.nan, "max": math.nan}
    return {"n": float(values.size), "median": float(np.median(values)),
            "p95": float(np.percentile(values, 95.0)), "max": float(values.max())}


def _groups(rows: Sequence[Row], varied: Sequence[str] = ()) -> dict[str, list[Row]]:
    """Rows by robot and varied settings (the runs that differ only by their seed)."""
    groups: dict[str, list[Row]] = {}
    for row in rows:
        key = " ".join([str(row.get("robot"))] + [f"{c.removeprefix('set.')}={row.get(c)}" for c in varied])
        groups.setdefault(key, []).append(row)
    return groups


def to_markdown(rows: Sequence[Row], metrics: Sequence[str], varied: Sequence[str] = ()) -> str:
    """Spread per robot and metric, then one line per run with the metrics."""
    lines = ["# Sweep", "", f"{len(rows)} runs, {sum(r.get('status') == 'ok' for r in rows)} ok.", ""]
    if metrics:
        lines += ["## Spread over the seeds", "", "| robot (settings) | figure | n | median | 95th percentile | max |",
                  "|---|---|---|---|---|---|"]
        for robot, group in _groups(rows, varied).items():
            for m in metrics:
                s = spread(numeric_values(group, m))
                lines.append(f"| {robot} | {m} | {int(s['n'])} | {s['median']:.6g} | {s['p95']:.6g} | "
                             f"{s['max']:.6g} |")
        lines.append("")
    cols = [*KEY_COLUMNS, *varied, *metrics]
    lines += ["## Runs", "", "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in rows:
        cells = []
        for c in cols:
            v = row.get(c)
            cells.append(f"{v:.6g}" if isinstance(v, float) else _cell_text(v).replace("|", "/"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def spread_figure(rows: Sequence[Row], metrics: Sequence[str], varied: Sequence[str] = ()) -> Figure:
    """One panel per metric: every run's value per robot and settings (dots), median and 95th
    percentile over the seeds."""
    groups = _groups(rows, varied)
    fig = Figure(figsize=(max(4.0, 1.6 * len(groups) + 2.0), 3.0 * max(1, len(metrics))))
    for i, m in enumerate(metrics or [""]):
        ax = fig.add_subplot(max(1, len(metrics)), 1, i + 1)
        for j, (_robot, group) in enumerate(groups.items()):
            vals = numeric_values(group, m) if m else np.zeros(0)
            if vals.size == 0:
                continue
            x = j + np.linspace(-0.15, 0.15, vals.size)
            ax.plot(x, vals, "o", color="tab:blue", alpha=0.6, markersize=4)
            s = spread(vals)
            ax.hlines(s["median"], j - 0.3, j + 0.3, color="k", label="median" if j == 0 else None)
            ax.hlines(s["p95"], j - 0.3, j + 0.3, color="tab:red", linestyles="--",
                      label="95th percentile" if j == 0 else None)
        ax.set_xticks(range(len(groups)), list(groups), fontsize=7)
        ax.set_ylabel(m, fontsize=7)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def write_outputs(out_dir: Path, rows: Sequence[Row], varied: Sequence[str],
                  metrics: Sequence[str]) -> dict[str, Path]:
    """``sweep.csv``, ``sweep.md`` and ``sweep.png`` in ``out_dir`` (atomic writes)."""
    columns = columns_of(rows, varied)
    chosen = pick_metrics(rows, metrics)
    paths = {"csv": artefacts.write_text(out_dir / "sweep.csv", to_csv(rows, columns)),
             "markdown": artefacts.write_text(out_dir / "sweep.md", to_markdown(rows, chosen, varied))}
    paths["plot"] = artefacts.save_figure(out_dir / "sweep.png", spread_figure(rows, chosen, varied))
    return paths
