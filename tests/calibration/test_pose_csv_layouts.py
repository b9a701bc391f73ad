"""A pose CSV as trackers and spreadsheets export it: columns in any order, joints by name, units in the
header, ``;`` or tab as delimiter with decimal commas; each reads as the plain file, and a bad header is
named."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.calibration import candidates as cd
from pipeline.calibration import measure as ms
from pipeline.core.errors import DataFileError
from pipeline.exchange.csv_header import header_column, sniff_delimiter
from pipeline.robot.model import RobotModel
from pipeline.sim.truth import RealRobot


@pytest.fixture(scope="module")
def poses(rx130l: RobotModel):
    rng = np.random.default_rng(5)
    Q, _ = cd.random_candidates(cd.chain_from_robot(rx130l), 12, rng)
    meas = ms.measure_simulated(RealRobot.create(rx130l, 5), Q, rng)
    rotvec = 0.3 * rng.normal(size=(len(meas.Q), 3))
    return meas.Q, meas.Y, rotvec


def _write(path, header: list[str], columns: list[np.ndarray], delimiter: str = ",", decimal: str = ".") -> None:
    rows = [delimiter.join(header)]
    for row in np.column_stack(columns):
        rows.append(delimiter.join(repr(float(v)).replace(".", decimal) for v in row))
    path.write_text("\n".join(rows) + "\n")


def test_header_cells_give_name_and_unit():
    assert header_column("x") == header_column("X ") and header_column("x").unit is None
    assert [header_column(c).unit for c in ("x_mm", "x [mm]", "x (mm)", "X[MM]", "x_m", "q1_deg", "q1 [rad]")] == \
        ["mm", "mm", "mm", "mm", "m", "deg", "rad"]
    assert header_column("wrist_1_joint [deg]").name == "wrist_1_joint"
    assert header_column("arm_m", known=["arm_m"]).unit is None          # a joint named like a unit
    assert [sniff_delimiter(s) for s in ("q1,q2", "q1;q2", "q1\tq2", "q1")] == [",", ";", "\t", ","]


def test_every_layout_reads_as_the_plain_file(tmp_path, rx130l: RobotModel, poses):
    Q, Y, rotvec = poses
    names = [str(n) for n in rx130l.model.names[1:]]
    plain = tmp_path / "plain.csv"
    _write(plain, [f"q{i}" for i in range(1, 7)] + ["x", "y", "z", "rx", "ry", "rz"], [Q, Y, rotvec])
    reference = ms.read_csv(plain, rx130l)
    deg, mm = 180.0 / math.pi, 1000.0
    layouts = {
        # tracker columns first, joints by name in reversed order, millimetres and degrees stated
        "names_units.csv": ([f"{a} [mm]" for a in "xyz"] + [f"{n} [deg]" for n in reversed(names)]
                            + ["rx_deg", "ry_deg", "rz_deg"], [Y * mm, Q[:, ::-1] * deg, rotvec * deg], ",", "."),
        "semicolon.csv": ([f"q{i}" for i in range(1, 7)] + ["X_mm", "Y_mm", "Z_mm", "rx", "ry", "rz"],
                          [Q, Y * mm, rotvec], ";", ","),
        "tab.csv": (["x", "y", "z", "rx", "ry", "rz"] + [f"q{i}" for i in range(1, 7)], [Y, rotvec, Q], "\t", "."),
    }
    for name, (header, columns, delimiter, decimal) in layouts.items():
        _write(tmp_path / name, header, columns, delimiter, decimal)
        back = ms.read_csv(tmp_path / name, rx130l)
        np.testing.assert_allclose(back.Q, reference.Q, rtol=1e-12, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(back.Y, reference.Y, rtol=1e-12, atol=1e-12, err_msg=name)
        assert back.rotvec is not None and reference.rotvec is not None
        np.testing.assert_allclose(back.rotvec, reference.rotvec, rtol=1e-12, atol=1e-12, err_msg=name)
        np.testing.assert_array_equal(back.lines, reference.lines)
    # roll, pitch, yaw (R = Rz Ry Rx) in degrees instead of the rotation vector
    rpy = Rotation.from_rotvec(rotvec).as_euler("xyz")
    _write(tmp_path / "rpy.csv", [f"q{i}" for i in range(1, 7)] + ["x", "y", "z", "roll_deg", "pitch_deg", "yaw_deg"],
           [Q, Y, rpy * deg])
    from_rpy = ms.read_csv(tmp_path / "rpy.csv", rx130l)
    assert from_rpy.rotvec is not None and reference.rotvec is not None
    np.testing.assert_allclose(from_rpy.rotvec, reference.rotvec, atol=1e-12)
    # what the project writes it reads back exactly
    written = ms.read_csv(ms.write_csv(tmp_path / "written.csv", reference), rx130l)
    np.testing.assert_array_equal(written.Q, reference.Q)
    np.testing.assert_array_equal(written.Y, reference.Y)


@pytest.mark.parametrize(("header", "problem"), [
    (["q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z", "note"], "unknown column(s) ['note']"),
    (["q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "x"], "repeats column 7"),
    (["q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z", "rx", "ry"], "missing column(s) ['rz']"),
    (["q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z", "rx", "ry", "rz", "roll", "pitch", "yaw"],
     "two orientations"),
    (["q1", "q2", "q3", "q4", "q5", "q6", "x [deg]", "y", "z"], "unit 'deg' is not one of a length's"),
    (["q1", "q2", "q3", "q4", "q5", "q7", "x", "y", "z"], "unknown column(s) ['q7']"),
])
def test_a_bad_header_is_named(tmp_path, rx130l: RobotModel, poses, header, problem):
    Q, Y, rotvec = poses
    columns = np.column_stack([Q, Y, rotvec])[:, :len(header)]
    path = tmp_path / "bad.csv"
    _write(path, header, [columns])
    with pytest.raises(DataFileError) as info:
        ms.read_csv(path, rx130l)
    assert str(path) in str(info.value) and problem in str(info.value), str(info.value)


def test_units_the_values_contradict_and_spreadsheet_quirks(tmp_path, rx130l: RobotModel, poses):
    Q, Y, rotvec = poses
    names = [str(n) for n in rx130l.model.names[1:]]
    q_cols = [f"q{i}" for i in range(1, 7)]
    cases = {   # a unit that the values contradict: refused, naming the unit to drop
        "mm_of_metres.csv": (q_cols + ["x_mm", "y_mm", "z_mm"], [Q, Y], "look like metres"),
        "deg_of_rad.csv": ([f"q{i}_deg" for i in range(1, 7)] + ["x", "y", "z"], [Q, Y], "look like radians"),
        "rpy_of_deg.csv": (q_cols + ["x", "y", "z", "roll", "pitch", "yaw"],
                           [Q, Y, np.degrees(Rotation.from_rotvec(rotvec).as_euler("xyz"))], "look like degrees"),
        "q_and_names.csv": (names + ["q1", "x", "y", "z"], [Q, Q[:, :1], Y], "unknown column(s) ['q1']"),
    }
    for name, (header, columns, problem) in cases.items():
        _write(tmp_path / name, header, columns)
        with pytest.raises(DataFileError, match=re.escape(problem)):
            ms.read_csv(tmp_path / name, rx130l)
    # a trailing delimiter on every line, and joints named with a common prefix, read as the plain file
    reference = ms.read_csv(_plain(tmp_path, Q, Y), rx130l)
    _write(tmp_path / "prefixed.csv", [f"robot_{n}" for n in names] + ["x", "y", "z", ""],
           [Q, Y, np.zeros((len(Q), 0))])
    text = (tmp_path / "prefixed.csv").read_text().splitlines()
    (tmp_path / "prefixed.csv").write_text("\n".join([text[0]] + [ln + "," for ln in text[1:]]) + "\n")
    back = ms.read_csv(tmp_path / "prefixed.csv", rx130l)
    np.testing.assert_array_equal(back.Q, reference.Q)
    np.testing.assert_array_equal(back.Y, reference.Y)


def _plain(tmp_path, Q, Y):
    path = tmp_path / "plain_q.csv"
    _write(path, [f"q{i}" for i in range(1, 7)] + ["x", "y", "z"], [Q, Y])
    return path
