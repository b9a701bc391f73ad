"""The calibration tour as controller programs (URScript, KRL, RAPID): each format reads back as written, and
the exported programs visit the tour's joint waypoints in its order, dwelling at the poses of the pose table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import main as cli_main
from pipeline.core.errors import DataFileError
from pipeline.exchange.joint_limits import JointLimitTable
from pipeline.exchange.motion_csv import read_motion_csv
from pipeline.exchange.robot_program import (
    PROGRAM_FORMATS,
    SUFFIX,
    PoseProgram,
    program_text,
    read_program,
    write_program,
)
from pipeline.robot.defaults import ready_pose_rad
from pipeline.robot.model import RobotModel
from pipeline.run.export_motions import ExportContext
from pipeline.run.export_tour import DWELL_S, calibration_files
from pipeline.stage_api import StageOutput


def _program(n_axes: int = 6) -> PoseProgram:
    rng = np.random.default_rng(3)
    q = rng.uniform(-2.5, 2.5, size=(5, n_axes))
    q[0, 0] = 1e-7                                       # a small angle: no exponent form in KRL or RAPID
    return PoseProgram("calibration_tour", tuple(f"joint_{j + 1}" for j in range(n_axes)), q,
                       np.array([0.0, 2.0, 2.0, 0.0, 0.0]), 0.6, 1.2, 50.0, 50.0)


@pytest.mark.parametrize("fmt", PROGRAM_FORMATS)
def test_each_format_reads_back_as_written(tmp_path: Path, fmt) -> None:
    program = _program()
    back = read_program(write_program(tmp_path / f"tour{SUFFIX[fmt]}", program, fmt, ["a note"]))
    assert back.name == program.name and back.joint_names == program.joint_names
    np.testing.assert_allclose(back.q_rad, program.q_rad, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(back.dwell_s, program.dwell_s)
    if fmt == "urscript":
        np.testing.assert_array_equal(back.q_rad, program.q_rad)          # repr: every digit
        assert (back.velocity_rad_s, back.acceleration_rad_s2) == (0.6, 1.2)
    if fmt == "krl":
        assert (back.velocity_percent, back.acceleration_percent) == (50.0, 50.0)
    if fmt == "rapid":
        assert back.velocity_rad_s == pytest.approx(0.6, rel=1e-6)


def test_a_program_needs_six_axes_and_a_file_of_another_kind_is_named(tmp_path: Path) -> None:
    with pytest.raises(DataFileError, match="6 axes"):
        program_text(_program(7), "krl")
    (tmp_path / "tour.src").write_text("DEF tour()\nEND\n")
    with pytest.raises(DataFileError, match="tour.src"):
        read_program(tmp_path / "tour.src")
    with pytest.raises(SystemExit) as info:
        cli_main(["export", str(tmp_path), "--program", "krl,fanuc"])
    assert info.value.code == 2


def test_the_exported_programs_follow_the_tour(tmp_path: Path, rx130l: RobotModel) -> None:
    start = ready_pose_rad(rx130l)
    poses = start + np.array([[0.3, 0.1, -0.1, 0.2, 0.2, 0.4], [-0.3, 0.15, 0.05, -0.3, 0.1, -0.2],
                              [0.1, -0.1, 0.1, 0.5, -0.2, 0.3]])
    staging = tmp_path / "export"
    staging.mkdir()
    ctx = ExportContext(staging, staging, rx130l, rx130l, JointLimitTable.of_model(rx130l), start, 100.0, "sqlite3",
                        "/rx130l/joint_trajectory", PROGRAM_FORMATS)
    calibration_files(ctx, StageOutput({}, {"configurations_selected": poses}, {}, None, tmp_path))
    template = np.loadtxt(staging / "calibration_measurements_template.csv", delimiter=",", skiprows=1,
                          usecols=range(6), ndmin=2)
    motion = read_motion_csv(staging / "calibration_tour.csv")
    for fmt in PROGRAM_FORMATS:
        assert f"calibration_tour{SUFFIX[fmt]}" in ctx.written
        program = read_program(staging / f"calibration_tour{SUFFIX[fmt]}")
        assert program.joint_names == tuple(str(n) for n in rx130l.model.names[1:])
        np.testing.assert_allclose(program.q_rad[[0, -1]], [start, start], atol=1e-10)
        at_poses = program.dwell_s > 0
        assert np.all(program.dwell_s[at_poses] == DWELL_S)
        np.testing.assert_allclose(program.q_rad[at_poses], template, atol=1e-10)    # the pose table's order
        # every waypoint is a rest of the exported motion, in the same order (the same joint-space path)
        rests = [k for k in range(len(motion.t_s)) if np.all(np.abs(motion.qd_rad_s[k]) < 1e-9)]
        visited = [motion.q_rad[rests[0]]]
        for k in rests[1:]:
            if not np.allclose(motion.q_rad[k], visited[-1], atol=1e-9):
                visited.append(motion.q_rad[k])
        np.testing.assert_allclose(np.array(visited), program.q_rad, atol=1e-10)
        assert program.velocity_rad_s <= 0.5 * float(np.min(ctx.limits.velocity_rad_s)) + 1e-12 or fmt == "krl"


def test_comments_are_not_read_and_a_program_it_cannot_read_back_is_named(tmp_path: Path) -> None:
    program = _program()
    notes = ["movej([0, 0, 0, 0, 0, 0], a=1, v=1)  PTP {A1 0} sleep(1.0) MoveAbsJ [[0]] WaitTime 1;"]
    for fmt in PROGRAM_FORMATS:
        back = read_program(write_program(tmp_path / f"tour{SUFFIX[fmt]}", program, fmt, notes))
        assert len(back.q_rad) == len(program.q_rad), fmt                  # the note's text is a comment
    blended = (tmp_path / "tour.script").read_text().replace("v=0.6)  # target 2", "v=0.6, r=0.01)  # target 2")
    (tmp_path / "blended.script").write_text(blended)
    with pytest.raises(DataFileError, match="blended"):
        read_program(tmp_path / "blended.script")
    krl = (tmp_path / "tour.src").read_text().replace(", A6 ", ", A7 ", 1)
    (tmp_path / "axis.src").write_text(krl)
    with pytest.raises(DataFileError, match="axis.src"):
        read_program(tmp_path / "axis.src")
    bad = PoseProgram("tour-1", program.joint_names, program.q_rad, program.dwell_s, 0.6, 1.2, 50.0, 50.0)
    with pytest.raises(DataFileError, match="no identifier"):
        program_text(bad, "krl")
    nan = PoseProgram("tour", program.joint_names, np.full((2, 6), np.nan), np.zeros(2), 0.6, 1.2, 50.0, 50.0)
    with pytest.raises(DataFileError, match="not finite"):
        program_text(nan, "rapid")
