"""Fuzzing the files a user hands in: a URDF, a calibration measurement CSV and a torque log, each
a valid file with hostile edits (NaN, inf, text, missing or extra cells, swapped limits, units,
repeated or dropped rows, dead or frozen columns). Every one is read, or refused in one
:class:`PipelineError` line naming the file (the CLI prints it and exits 2) with nothing written and
nothing on stderr (no urdfdom C++ lines); a file that is read gives finite values that pass the
reader's own checks. Inputs per reader are bounded in the fast suite (profile ``fuzz``), more in the
slow-marked variants (``fuzz-slow``); the run log counts them ("fuzz inputs per reader")."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from pipeline.calibration.measure import read_csv
from pipeline.core.errors import ConfigError, DataFileError, PipelineError, RobotFileError
from pipeline.identification.config import Config as IdentificationConfig
from pipeline.identification.record import load_user_record
from pipeline.robot.model import RobotModel
from pipeline.robot.urdf_checks import NUMERIC_ATTRIBUTES
from tests.reliability.fuzzing import fast_and_slow


def _refused_in_one_line(exc: PipelineError, path: Path) -> None:
    line = exc.one_line()
    assert line and "\n" not in line and path.name in line, line


HOSTILE = ["nan", "NaN", "inf", "-inf", "1e999", "-1e999", "abc", "", " ", "1 2", "0x10", "1,5", "-0", "0",
           "-1", "1e-300", "1e300", "1e6", "None", "\u00a01"]
hostile_cells = st.one_of(st.sampled_from(HOSTILE), st.floats().map(repr), st.text(max_size=6))

# ------------------------------------------------------------------------------------ URDF
ROBOT_DIR = Path(__file__).resolve().parents[2] / "robots" / "rx130l"
URDF_TEXT = (ROBOT_DIR / "rx130l.urdf").read_text()


def _numeric_values(text: str) -> list[tuple[int, int]]:
    """(start, end) of every numeric attribute value of the URDF's elements."""
    spans = []
    for element in re.finditer(r"<(\w+)\b([^>]*)>", text):
        numeric = NUMERIC_ATTRIBUTES.get(element.group(1), {})
        for attribute in re.finditer(r"(\w+)=\"([^\"]*)\"", element.group(2)):
            if attribute.group(1) in numeric:
                spans.append((element.start(2) + attribute.start(2), element.start(2) + attribute.end(2)))
    return spans


URDF_VALUES = _numeric_values(URDF_TEXT)


def _swapped_limits(text: str, k: int) -> str:
    limits = list(re.finditer(r"lower=\"([^\"]*)\" upper=\"([^\"]*)\"", text))
    m = limits[k % len(limits)]
    return text[:m.start()] + f'lower="{m.group(2)}" upper="{m.group(1)}"' + text[m.end():]


@fast_and_slow(share=0.6, edits=st.lists(st.tuples(st.integers(0, len(URDF_VALUES) - 1), hostile_cells),
                                         min_size=1, max_size=2), swap=st.one_of(st.none(), st.integers(0, 5)))
def _urdf(tmp_path, capfd, fuzz_inputs, edits, swap):
    fuzz_inputs["URDF"] += 1
    folder = tmp_path / "arm"
    if not folder.exists():
        shutil.copytree(ROBOT_DIR, folder)
    text = URDF_TEXT
    for k, value in sorted(edits, reverse=True):        # from the end: earlier offsets stay valid
        start, end = URDF_VALUES[k]
        text = text[:start] + value.replace('"', "").replace("<", "").replace("&", "") + text[end:]
    text = _swapped_limits(text, swap) if swap is not None else text
    path = folder / "rx130l.urdf"
    path.write_text(text)
    before = set(folder.rglob("*"))
    capfd.readouterr()
    try:
        robot = RobotModel.load(folder)
    except RobotFileError as exc:
        _refused_in_one_line(exc, path)
    else:
        assert np.all(np.isfinite([robot.model.inertias[j].mass for j in range(1, robot.model.njoints)]))
        assert np.all(robot.limits.lower_rad < robot.limits.upper_rad)
    assert set(folder.rglob("*")) == before
    assert "Error" not in capfd.readouterr().err           # urdfdom's C++ lines never reach stderr


test_any_urdf_edit_loads_or_is_one_line, test_many_urdf_edits = _urdf


# --------------------------------------------------------------------- calibration CSV
def _measurements(robot: RobotModel, n: int = 12) -> np.ndarray:
    """Joint angles and reflector positions (tracker frame) of ``n`` random poses."""
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    Q = np.random.default_rng(0).uniform(0.8 * lo, 0.8 * hi, (n, robot.nq))
    T = robot.tracker.transform_tracker_to_base                     # p_base = T p_tracker
    return np.column_stack([Q, (robot.positions(Q, robot.frame_reflector) - T.translation) @ T.rotation])


def _csv_text(header: list[str], rows: list[list[str]]) -> str:
    return "\n".join([",".join(header), *(",".join(r) for r in rows)]) + "\n"


edits_of_a_table = st.lists(st.tuples(st.sampled_from(["cell", "drop_cell", "add_cell", "blank", "duplicate",
                                                       "delete", "header", "degrees", "millimetres"]),
                                      st.integers(0, 200), st.integers(0, 20), hostile_cells),
                            min_size=1, max_size=3)


def _edited(header: list[str], rows: list[list[str]], edits) -> tuple[list[str], list[list[str]]]:
    header, rows = list(header), [list(r) for r in rows]
    for how, i, j, cell in edits:
        if not rows:
            break
        i, j = i % len(rows), j % len(rows[i % len(rows)] or [""])
        if how == "cell" and rows[i]:
            rows[i][j] = cell
        elif how == "drop_cell" and rows[i]:
            del rows[i][j]
        elif how == "add_cell":
            rows[i].append(cell)
        elif how == "blank":
            rows.insert(i, [""])
        elif how == "duplicate":
            rows.insert(i, list(rows[i]))
        elif how == "delete":
            del rows[i]
        elif how == "header" and header:
            header[j % len(header)] = cell
        elif how in ("degrees", "millimetres"):
            scale, cols = (57.29577951308232, range(6)) if how == "degrees" else (1000.0, range(6, 9))
            rows = [[repr(float(c) * scale) if k in cols and _number(c) else c for k, c in enumerate(r)]
                    for r in rows]
    return header, rows


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


CAL_HEADER = ["q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z"]


@fast_and_slow(edits=edits_of_a_table)
def _calibration_file(tmp_path, rx130l, fuzz_inputs, edits):
    fuzz_inputs["calibration file"] += 1
    rows = [[repr(float(v)) for v in r] for r in _measurements(rx130l)]
    header, rows = _edited(CAL_HEADER, rows, edits)
    path = tmp_path / "measurements.csv"
    path.write_text(_csv_text(header, rows), encoding="utf-8")
    before = set(tmp_path.iterdir())
    try:
        meas = read_csv(path, rx130l, min_rows=3)
    except DataFileError as exc:
        _refused_in_one_line(exc, path)
    else:
        assert np.all(np.isfinite(meas.Q)) and np.all(np.isfinite(meas.Y)) and len(meas.Q) >= 3
        assert np.all((meas.Q >= rx130l.limits.lower_rad - 1e-9) & (meas.Q <= rx130l.limits.upper_rad + 1e-9))
    assert set(tmp_path.iterdir()) == before


test_any_calibration_file_edit_is_read_or_one_line, test_many_calibration_file_edits = _calibration_file


# ---------------------------------------------------------------------------- torque log
LOG_HEADER = ["t", *(f"q{i}" for i in range(1, 7)), *(f"tau{i}" for i in range(1, 7))]


def _torque_log(n: int = 600, dt: float = 0.004) -> list[list[str]]:
    t = np.arange(n) * dt
    q = 0.4 * np.sin(np.outer(t, np.arange(1, 7)) * 1.3)
    tau = 20.0 * np.cos(np.outer(t, np.arange(1, 7)) * 0.9) + 0.01 * np.random.default_rng(1).normal(size=(n, 6))
    return [[repr(float(v)) for v in row] for row in np.column_stack([t, q, tau])]


LOG_ROWS = _torque_log()

log_edits = st.one_of(
    edits_of_a_table.filter(lambda e: all(how not in ("degrees", "millimetres") for how, *_ in e)),
    st.sampled_from(["frozen", "dead", "milliseconds", "reversed"]).map(lambda how: [(how, 0, 0, "")]))


def _log_edited(edits) -> tuple[list[str], list[list[str]]]:
    how = edits[0][0]
    rows = [list(r) for r in LOG_ROWS]
    if how == "frozen":                         # the arm at rest: constant positions (and torques)
        return LOG_HEADER, [[r[0], *rows[0][1:7], *rows[0][7:]] for r in rows]
    if how == "dead":                           # every torque column constant
        return LOG_HEADER, [[*r[:7], *["1.5"] * 6] for r in rows]
    if how == "milliseconds":
        return LOG_HEADER, [[repr(float(r[0]) * 1000), *r[1:]] for r in rows]
    if how == "reversed":
        return LOG_HEADER, rows[::-1]
    return _edited(LOG_HEADER, rows, edits)


@fast_and_slow(edits=log_edits)
def _torque_log_file(tmp_path, rx130l, fuzz_inputs, edits):
    fuzz_inputs["torque log"] += 1
    header, rows = _log_edited(edits)
    path = tmp_path / "record.csv"
    path.write_text(_csv_text(header, rows), encoding="utf-8")
    before = set(tmp_path.iterdir())
    try:
        rec = load_user_record(IdentificationConfig(data_file=str(path)), rx130l)
    except (DataFileError, ConfigError) as exc:
        _refused_in_one_line(exc, path)
    else:
        assert np.all(np.isfinite(rec.q_rad)) and np.all(np.isfinite(rec.tau_Nm)) and np.all(np.diff(rec.t_s) > 0)
        assert len(rec.unmeasured) < rec.q_rad.shape[1]
    assert set(tmp_path.iterdir()) == before


test_any_torque_log_edit_is_read_or_one_line, test_many_torque_log_edits = _torque_log_file
