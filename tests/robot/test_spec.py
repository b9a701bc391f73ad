"""robot.yaml reader: booleans are not numbers, gear_coupling entries are checked."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from pipeline.core.errors import RobotFileError
from pipeline.robot.model import ROBOTS_DIR, RobotModel


def _robot_with(tmp_path: Path, edit, name: str = "staubli_tx40") -> Path:  # noqa: ANN001
    folder = tmp_path / name
    shutil.copytree(ROBOTS_DIR / name, folder)
    data = yaml.safe_load((folder / "robot.yaml").read_text())
    edit(data)
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    return folder


def _error(folder: Path) -> RobotFileError:
    with pytest.raises(RobotFileError) as info:
        RobotModel.load(folder)
    return info.value


@pytest.mark.parametrize(
    ("coupling", "field", "problem"),
    [
        ([[5, 4, True]], "actuation.gear_coupling[0]", "value must be a finite number, got True"),
        ([[5, 4, float("nan")]], "actuation.gear_coupling[0]", "value must be a finite number"),
        ([[5, 4, float("inf")]], "actuation.gear_coupling[0]", "value must be a finite number"),
        ([[True, 4, 32.0]], "actuation.gear_coupling[0]", "row must be an integer joint index 0..5, got True"),
        ([[5, False, 32.0]], "actuation.gear_coupling[0]", "col must be an integer joint index 0..5, got False"),
        ([[5.0, 4, 32.0]], "actuation.gear_coupling[0]", "row must be an integer joint index 0..5, got 5.0"),
        ([[6, 4, 32.0]], "actuation.gear_coupling[0]", "row must be an integer joint index 0..5, got 6"),
        ([[5, -1, 32.0]], "actuation.gear_coupling[0]", "col must be an integer joint index 0..5, got -1"),
        ([[4, 4, 32.0]], "actuation.gear_coupling[0]", "row and col must differ"),
        ([[5, 4, 32.0], [5, 4, 1.0]], "actuation.gear_coupling[1]", "already set by gear_coupling[0]"),
        ([[5, 4]], "actuation.gear_coupling[0]", "expected [row, col, value]"),
        ([5, 4, 32.0], "actuation.gear_coupling[0]", "expected [row, col, value]"),
        (False, "actuation.gear_coupling", "expected a list of [row, col, value], got False"),
    ],
)
def test_bad_gear_coupling(tmp_path: Path, coupling, field: str, problem: str) -> None:  # noqa: ANN001
    folder = _robot_with(tmp_path, lambda d: d["actuation"].update(gear_coupling=coupling))
    error = _error(folder)
    assert Path(error.file).name == "robot.yaml"
    assert error.field == field
    assert problem in error.problem


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["actuation"]["gear_ratio"].__setitem__(0, True), "actuation.gear_ratio"),
        (lambda d: d["limits"].update(lower_rad=[False, -1, -1, -1, -1, -1]), "limits.lower_rad"),
        (lambda d: d["limits"]["acceleration_rad_s2"].__setitem__(2, True), "limits.acceleration_rad_s2"),
        (lambda d: d["tool"]["transform_tcp_to_flange"].update(xyz=[0, 0, True]), "tool.transform_tcp_to_flange.xyz"),
        (lambda d: d.update(payload_kg=True), "payload_kg"),
        (lambda d: d["tracker"].update(noise_const_m=False), "tracker.noise_const_m"),
        (lambda d: d["actuation"].update(coulomb_smoothing_rad_s=True), "actuation.coulomb_smoothing_rad_s"),
        (lambda d: d["capsules"][0].update(radius_m=True), "capsules[0].radius_m"),
        (lambda d: d["collision"].update(floor_z_m=True), "collision.floor_z_m"),
        (lambda d: d["collision"].update(floor_check_from_joint=True), "collision.floor_check_from_joint"),
        (lambda d: d["collision"].update(floor_check_from_joint=2.7), "collision.floor_check_from_joint"),
        (lambda d: d["collision"].update(floor_check_from_joint=7), "collision.floor_check_from_joint"),
        (lambda d: d.update(capsules=False), "capsules"),
    ],
)
def test_booleans_and_non_integers_are_rejected(tmp_path: Path, edit, field: str) -> None:  # noqa: ANN001
    error = _error(_robot_with(tmp_path, edit))
    assert Path(error.file).name == "robot.yaml"
    assert error.field == field


def test_valid_couplings_and_empty_lists_still_load(tmp_path: Path) -> None:
    def edit(d: dict) -> None:
        d["actuation"]["gear_coupling"] = [[5, 4, 32], [4, 3, -1.5]]  # int value is a number
        d["collision"]["floor_check_from_joint"] = 6

    robot = RobotModel.load(_robot_with(tmp_path, edit))
    assert robot.actuation.gear_matrix[5, 4] == 32.0 and robot.actuation.gear_matrix[4, 3] == -1.5
    assert robot.spec.collision.floor_check_from_joint == 6
    robot = RobotModel.load(_robot_with(tmp_path / "b", lambda d: d["actuation"].update(gear_coupling=None)))
    assert robot.actuation.gear_matrix[5, 4] == 0.0


@pytest.mark.parametrize(
    ("values", "field", "problem"),
    [
        ({"static_friction_excess_Nm": [1.0] * 6}, "actuation.stribeck_velocity_rad_s", "together"),
        ({"static_friction_excess_Nm": [1.0] * 6, "stribeck_velocity_rad_s": [0.05] * 5},
         "actuation.stribeck_velocity_rad_s", "expected 6 numbers"),
        ({"static_friction_excess_Nm": [-1.0] * 6, "stribeck_velocity_rad_s": [0.05] * 6},
         "actuation.static_friction_excess_Nm", "must not be negative"),
        ({"static_friction_excess_Nm": [1.0] * 6, "stribeck_velocity_rad_s": [0.0] * 6},
         "actuation.stribeck_velocity_rad_s", "must be positive"),
    ],
)
def test_bad_stribeck_friction(tmp_path: Path, values: dict, field: str, problem: str) -> None:
    err = _error(_robot_with(tmp_path, lambda d: d["actuation"].update(values)))
    assert field in str(err) and problem in str(err)
