"""`robot init --torque-side` and the drive values of the nominal torque prediction: a value robot
init assumed (rotor inertia, viscous and Coulomb friction) is left out while unedited, and a
link-side torque sensor sees none of them, so the nominal prediction is the bare URDF's."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from pipeline.cli import main
from pipeline.identification.regressor import RegressorModel, standard_parameters
from pipeline.robot.assumed_values import predicted_drive_values
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.robot.yaml_init import detect_torque_side


def _urdf(name: str) -> Path:
    path = example_arm_urdf(name)
    if path is None:
        pytest.skip("example-robot-data not installed")
    return path


def _init(urdf: Path, folder: Path, *extra: str) -> RobotModel:
    assert main(["robot", "init", str(urdf), "--out", str(folder / "robot.yaml"), *extra]) == 0
    return RobotModel.load(folder)


def _nominal_torques(robot: RobotModel, drive: dict[str, np.ndarray], q, v, a) -> np.ndarray:
    reg = RegressorModel(robot.model, np.eye(robot.nq), robot.actuation.coulomb_smoothing_rad_s)
    p = standard_parameters(robot.model, drive["rotor_inertia_kgm2"], drive["viscous_Nms_rad"], drive["coulomb_Nm"])
    return (reg.stacked(q, v, a) @ p).reshape(-1, robot.nq)


def _bare_urdf_torques(robot: RobotModel, q, v, a) -> np.ndarray:
    model = robot.model.copy()
    model.armature[:] = 0.0
    data = model.createData()
    return np.array([pin.rnea(model, data, qi, vi, ai) for qi, vi, ai in zip(q, v, a, strict=True)])


def _states(robot: RobotModel, n: int = 20):
    rng = np.random.default_rng(3)
    lo, hi = robot.limits.lower_rad, robot.limits.upper_rad
    return rng.uniform(lo, hi, (n, robot.nq)), rng.normal(0, 1, (n, robot.nq)), rng.normal(0, 3, (n, robot.nq))


@pytest.mark.parametrize(("arm", "extra", "side"), [("panda", (), "link"), ("ur5", (), "motor"),
                                                    ("ur5", ("--torque-side", "link"), "link")])
def test_the_nominal_prediction_of_an_initialised_robot_is_the_bare_urdf(tmp_path, arm, extra, side):
    robot = _init(_urdf(arm), tmp_path, *extra)
    assert robot.actuation.torque_side == side
    written = yaml.safe_load((tmp_path / "robot.yaml").read_text())
    assert written["actuation"]["torque_side"] == side
    assert ("actuation.torque_side" in written["assumed"]) == (not extra)   # detected: marked ASSUMED
    q, v, a = _states(robot)
    drive = predicted_drive_values(robot.actuation, robot.spec.assumed)
    np.testing.assert_allclose(_nominal_torques(robot, drive, q, v, a), _bare_urdf_torques(robot, q, v, a),
                               atol=1e-9)
    # the drive values robot.yaml holds (for the simulated plant) would change the prediction
    kept = {n: np.asarray(getattr(robot.actuation, n), float) for n in drive}
    assert np.abs(_nominal_torques(robot, kept, q, v, a) - _bare_urdf_torques(robot, q, v, a)).max() > 1e-3


def test_a_link_side_sensor_sees_no_drive_values_even_edited_ones(tmp_path):
    _init(_urdf("ur5"), tmp_path, "--torque-side", "link")
    path = tmp_path / "robot.yaml"
    data = yaml.safe_load(path.read_text())
    data["actuation"]["coulomb_Nm"] = [1.0, 2.0, 3.0, 0.5, 0.5, 0.5]
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    robot = RobotModel.load(tmp_path)
    assert np.any(robot.actuation.rotor_inertia_kgm2)        # the drive is there (simulated plant) ...
    drive = predicted_drive_values(robot.actuation, robot.spec.assumed)
    assert not any(np.any(v) for v in drive.values())         # ... but not in a link-side torque


def test_an_edited_drive_value_is_a_fact_and_kept(tmp_path):
    _init(_urdf("ur5"), tmp_path, "--torque-side", "motor")
    path = tmp_path / "robot.yaml"
    text = path.read_text()
    data = yaml.safe_load(text)
    data["actuation"]["coulomb_Nm"] = [1.0, 2.0, 3.0, 0.5, 0.5, 0.5]
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    robot = RobotModel.load(tmp_path)
    drive = predicted_drive_values(robot.actuation, robot.spec.assumed)
    np.testing.assert_allclose(drive["coulomb_Nm"], [1.0, 2.0, 3.0, 0.5, 0.5, 0.5])
    assert not np.any(drive["rotor_inertia_kgm2"])          # still as robot init assumed it


def test_torque_side_detection_from_the_urdf(tmp_path):
    assert detect_torque_side(_urdf("panda"), [])[0] == "link"
    assert detect_torque_side(_urdf("ur5"), [])[0] == "motor"
    # a force_torque sensor on every arm joint (Gazebo tags), whatever the arm is called
    text = _urdf("ur5").read_text()
    joints = ["shoulder_pan_joint", "elbow_joint"]
    tags = "".join(f'<gazebo reference="{j}"><sensor name="s{j}" type="force_torque"/></gazebo>' for j in joints)
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(text.replace("</robot>", tags + "</robot>"))
    assert detect_torque_side(urdf, joints)[0] == "link"
    assert detect_torque_side(urdf, [*joints, "wrist_1_joint"])[0] == "motor"


def test_a_bad_torque_side_is_one_line(tmp_path, capsys):
    shutil.copy(_urdf("ur5"), tmp_path / "ur5.urdf")
    _init(tmp_path / "ur5.urdf", tmp_path)
    path = tmp_path / "robot.yaml"
    path.write_text(path.read_text().replace("torque_side: motor", "torque_side: sideways"))
    assert main(["check", "--set", f"robot={tmp_path}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "actuation.torque_side" in err[0] and "link, motor" in err[0]
