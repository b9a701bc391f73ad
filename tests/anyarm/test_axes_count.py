"""An arm with other than 6 or 7 axes: `robot init` names in one line the stages it can run, and
the plan holds exactly those."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.core.config import CONFIGS_DIR, load_config
from pipeline.core.errors import ConfigError
from pipeline.robot.example_robots import example_arm_urdf
from pipeline.robot.model import RobotModel
from pipeline.run.stage_plan import MAX_PLANNED_AXES, plan_stages, unavailable_stages


def _eight_axis_ur5(tmp_path: Path) -> Path:
    """A UR5 whose two fixed flange joints turn, one after the other (an 8-axis chain)."""
    urdf = example_arm_urdf("ur5")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    text = urdf.read_text()
    limit = '<limit effort="28.0" lower="-3.0" upper="3.0" velocity="3.2"/><axis xyz="0 0 1"/>'
    for name in ("ee_fixed_joint", "wrist_3_link-tool0_fixed_joint"):
        head = f'<joint name="{name}" type="fixed">'
        assert head in text
        text = text.replace(head, f'<joint name="{name}" type="revolute">{limit}')
    text = text.replace('<parent link="wrist_3_link"/>\n    <child link="tool0"/>',
                        '<parent link="ee_link"/>\n    <child link="tool0"/>')
    target = tmp_path / "ur5_8axis.urdf"
    target.write_text(text)
    return target


def test_eight_axis_arm_names_its_stages_at_robot_init_and_plans_them(tmp_path, capsys):
    urdf = _eight_axis_ur5(tmp_path)
    assert main(["robot", "init", str(urdf), "--out", str(tmp_path / "arm" / "robot.yaml")]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if "axes:" in line]
    assert len(lines) == 1
    assert "8 axes: stages model, calibration, identification run; control, trajectory do not" in lines[0]
    robot = RobotModel.load(tmp_path / "arm")
    assert robot.nq == 8 > MAX_PLANNED_AXES
    unavailable = unavailable_stages(robot)
    plans = plan_stages(load_config(None, [f"robot={tmp_path / 'arm'}"]), unavailable)
    assert [p.name for p in plans] == ["model", "calibration", "identification"]
    with pytest.raises(ConfigError, match="8 axes") as err:   # the quick profile names every stage
        plan_stages(load_config(CONFIGS_DIR / "quick.yaml", [f"robot={tmp_path / 'arm'}"]), unavailable)
    assert "\n" not in str(err.value)


def test_six_axis_arm_prints_no_stage_line(tmp_path, capsys):
    urdf = example_arm_urdf("ur5")
    if urdf is None:
        pytest.skip("example-robot-data not installed")
    assert main(["robot", "init", str(urdf), "--out", str(tmp_path / "robot.yaml")]) == 0
    assert "axes:" not in capsys.readouterr().out
