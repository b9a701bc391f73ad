"""`python -m pipeline robot init` and the stage plan of a robot without a tracker."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pipeline.cli import main
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import ConfigError
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.run.runner import prepare_run
from pipeline.run.stage_plan import plan_stages, unavailable_stages


def _ur5() -> Path:
    path = example_arm_urdf("ur5")
    if path is None:
        pytest.skip("example-robot-data not installed")
    return path


@pytest.fixture(scope="module")
def ur5_folder(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("ur5")
    assert main(["robot", "init", str(_ur5()), "--out", str(folder / "robot.yaml")]) == 0
    return folder


def test_robot_init_writes_a_loadable_yaml_and_refuses_to_overwrite(ur5_folder, capsys):
    robot = RobotModel.load(ur5_folder)
    assert robot.nq == 6 and robot.has_tracker
    assert main(["robot", "init", str(_ur5()), "--out", str(ur5_folder / "robot.yaml")]) == 2
    assert "already exists" in capsys.readouterr().err


def test_robot_without_tracker_has_no_calibration_stage(ur5_folder, tmp_path):
    data = yaml.safe_load((ur5_folder / "robot.yaml").read_text())
    data.pop("tracker")
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    robot = RobotModel.load(tmp_path)
    assert not robot.has_tracker
    unavailable = unavailable_stages(robot)
    assert "calibration" in unavailable and "tracker" in unavailable["calibration"]
    plans = plan_stages(load_config(None, [f"robot={tmp_path}"]), unavailable)
    names = [p.name for p in plans]
    assert "calibration" not in names and "identification" in names
    assert all("calibration" not in p.depends and "calibration" not in p.closure for p in plans)
    with pytest.raises(ConfigError, match="no tracker"):
        plan_stages(load_config(None, [f"robot={tmp_path}"], stages="calibration"), unavailable)


def test_five_axis_arm_is_refused_with_one_line_before_anything_runs(tmp_path):
    """A 5-axis arm (a UR5 whose last joint is fixed) cannot follow the 6-D tool pose of the ISO 9283
    and CP paths: check time names it (stages, calibration's working region), nothing is written."""
    text = _ur5().read_text().replace('<joint name="wrist_3_joint" type="revolute">',
                                      '<joint name="wrist_3_joint" type="fixed">')
    urdf = tmp_path / "ur5_5axis.urdf"
    urdf.write_text(text)
    robot = RobotModel.load(urdf)
    assert robot.nq == 5
    unavailable = unavailable_stages(robot)
    assert "5 axes" in unavailable["control"] and "5 axes" in unavailable["trajectory"]
    out = tmp_path / "runs"
    with pytest.raises(ConfigError, match="5 axes") as err:       # the quick profile names every stage
        prepare_run(load_config(CONFIGS_DIR / "quick.yaml", [f"robot={urdf}"]), out_root=out)
    assert "\n" not in str(err.value)
    cfg = load_config(None, [f"robot={urdf}"], stages="calibration")
    with pytest.raises(ConfigError, match="working_region"):
        prepare_run(cfg, out_root=out)
    assert not out.exists()
