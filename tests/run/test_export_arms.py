"""``python -m pipeline export`` on a quick run of every stage, for the built-in RX130L and a 7-axis
example arm (the example-robot-data Panda): every file of docs/exchange.md is written; the trajectory
bags read back with rosbags equal the plans (q to 1e-9 rad, effort to 1e-6 N·m); every exported motion
keeps the limits of the exported ``joint_limits.yaml`` on its own samples; ``joint_limits.yaml`` and the
URDF load (yourdfpy), with the source URDF's joint types (continuous stays continuous)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from pipeline.cli import main
from pipeline.core.config import CONFIGS_DIR
from pipeline.exchange.joint_limits import read_joint_limits_yaml, source_joint_types
from pipeline.exchange.motion_csv import read_motion_csv
from pipeline.exchange.ros2_bag import read_joint_trajectory
from pipeline.robot.model import RobotModel
from pipeline.run import export_motions as em
from pipeline.run.stage_io import load_run
from tests.example_arms import robot_setting

#: the quick profile made cheaper where no exported file depends on the size
CHEAPER = ["calibration.n_heldout=100", "calibration.design_table=false", "calibration.second_pass=never",
           "calibration.figures=false"]
MOTIONS = ("calibration_tour", "excitation", "trajectory_cp", "trajectory_ptp")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["rx130l", "panda"])
def test_export_of_a_quick_run_writes_every_file_and_keeps_the_plans(name: str, tmp_path: Path) -> None:
    robot_arg = robot_setting(name)
    sets = [f"robot={robot_arg}", f"name={name}", *CHEAPER]
    args = ["run", "--config", str(CONFIGS_DIR / "quick.yaml"), "--out", str(tmp_path / "runs"), "--accept-poor"]
    assert main([*args, *[a for s in sets for a in ("--set", s)]]) == 0
    run = tmp_path / "runs" / name
    out = tmp_path / "export"
    assert main(["export", str(run), "--to", str(out)]) == 0
    check_export(run, out, robot_arg)


def check_export(run: Path, out: Path, robot_arg: str) -> None:
    """The checks of the module docstring on the export ``out`` of the run ``run``."""
    stages = load_run(run)
    nominal = RobotModel.load(robot_arg)
    plans = sorted(k[:-2] for k in stages["trajectory"].arrays
                   if k.startswith("trajectory_") and k.endswith("_t") and f"{k[:-2]}_q" in stages["trajectory"].arrays)
    assert {"trajectory_cp", "trajectory_ptp"} <= set(plans)
    robot_dir = out / "robot"
    urdf_files = list(robot_dir.glob("*.urdf"))
    expected = ["calibration_poses.csv", "calibration_measurements_template.csv", "servo_gains.yaml",
                "robot/joint_limits.yaml", "robot/robot.yaml", "calibration_parameters.csv"]
    expected += [f"{m}.csv" for m in (*MOTIONS, *plans)]
    missing = [f for f in expected if not (out / f).is_file()]
    missing += [f"{m}/" for m in (*MOTIONS, *plans) if not (out / m / "metadata.yaml").is_file()]
    assert not missing and len(urdf_files) == 1, f"missing {missing}, URDFs {urdf_files}"

    limits = read_joint_limits_yaml(robot_dir / "joint_limits.yaml", [str(n) for n in nominal.model.names[1:]])
    torque_robot = stages["identification"].robot
    for motion_name in (*MOTIONS, *plans):
        bag, csv = read_joint_trajectory(out / motion_name), read_motion_csv(out / f"{motion_name}.csv")
        assert bag.joint_names == csv.joint_names == limits.joint_names
        em.check_limits(bag, limits, motion_name, tolerance=1e-6)          # on its own samples
        np.testing.assert_allclose(bag.q_rad, csv.q_rad, rtol=0, atol=1e-12)
        if motion_name in plans:   # the plan as stored, re-sampled (uniformly slowed where a note says so)
            t_plan = np.asarray(stages["trajectory"].arrays[f"{motion_name}_t"], float)
            q_plan = np.asarray(stages["trajectory"].arrays[f"{motion_name}_q"], float)
            t_plan = (t_plan - t_plan[0]) * (bag.t_s[-1] / (t_plan[-1] - t_plan[0]))
            q_expected = np.column_stack([np.interp(bag.t_s, t_plan, q_plan[:, j]) for j in range(nominal.nq)])
            np.testing.assert_allclose(bag.q_rad, q_expected, rtol=0, atol=1e-9)
            effort = em.model_torques(torque_robot, bag.q_rad, bag.qd_rad_s, bag.qdd_rad_s2)
            np.testing.assert_allclose(bag.tau_ff_Nm, effort, rtol=0, atol=1e-6)

    source_types = source_joint_types(nominal.urdf_path)
    exported = yourdfpy.URDF.load(str(urdf_files[0]), build_scene_graph=False, load_meshes=False)
    for joint, kind in source_types.items():
        assert exported.joint_map[joint].type == kind, joint
    for k, joint in enumerate(limits.joint_names):
        if source_types[joint] != "continuous":
            assert exported.joint_map[joint].limit.lower == pytest.approx(limits.lower_rad[k])
            assert exported.joint_map[joint].limit.upper == pytest.approx(limits.upper_rad[k])
    back = RobotModel.load(robot_dir)                   # the robot folder loads as the model handed on
    np.testing.assert_allclose(back.limits.upper_rad, limits.upper_rad, rtol=1e-12)
    np.testing.assert_array_equal(back.spec.actuation.viscous_Nms_rad, torque_robot.spec.actuation.viscous_Nms_rad)
