"""Run names come from the robot and profile; a run never replaces another robot's run unless forced."""

from __future__ import annotations

import shutil

import pytest
import yaml

from pipeline import cli
from pipeline.core.config import CONFIGS_DIR, REPO_ROOT, load_config
from pipeline.core.run_names import default_run_name, robot_label


@pytest.fixture
def my_arm(tmp_path):
    """A user's robot folder (a copy of the built-in one under another name)."""
    dst = tmp_path / "robots" / "my_arm"
    shutil.copytree(REPO_ROOT / "robots" / "rx130l", dst)
    return dst


def test_default_names_come_from_robot_and_profile(tmp_path):
    assert load_config(None).name == "rx130l"
    assert load_config(CONFIGS_DIR / "quick.yaml").name == "rx130l-quick"
    assert load_config(CONFIGS_DIR / "quick.yaml", ["robot=staubli_tx40"]).name == "staubli_tx40-quick"
    assert load_config(None, ["robot=staubli_tx40", "name=mine"]).name == "mine"      # a name given wins
    assert default_run_name("/arms/iiwa/model.urdf", "quick") == "model-quick"
    assert default_run_name("arms/iiwa/", "full") == robot_label("iiwa") == "iiwa"


def test_a_users_arm_and_the_built_in_robot_keep_both_runs(fake_stages, my_arm, tmp_path, capsys):
    out = tmp_path / "runs"
    assert cli.main(["run", "--set", "profile=quick", "--set", f"robot={my_arm}", "--out", str(out)]) == 0
    assert cli.main(["run", "--set", "profile=quick", "--out", str(out)]) == 0
    assert (out / "my_arm-quick" / "report.md").is_file() and (out / "rx130l-quick" / "report.md").is_file()
    stored = yaml.safe_load((out / "my_arm-quick" / "config.yaml").read_text())
    assert robot_label(stored["robot"]) == "my_arm"


@pytest.mark.parametrize("command", ["run", "check"])
def test_another_robot_into_a_run_directory_is_refused_unless_forced(command, fake_stages, my_arm, tmp_path, capsys):
    out = tmp_path / "runs"
    assert cli.main(["run", "--set", "name=shared", "--out", str(out)]) == 0
    before = {p: p.read_bytes() for p in (out / "shared").rglob("*") if p.is_file()}
    capsys.readouterr()
    args = [command, "--set", "name=shared", "--set", f"robot={my_arm}", "--out", str(out)]
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {out / 'shared' / 'config.yaml'}: robot: ")
    assert "'rx130l'" in err and "'my_arm'" in err and "--force" in err
    assert {p: p.read_bytes() for p in (out / "shared").rglob("*") if p.is_file()} == before
    assert cli.main([*args, "--force"]) == 0
    if command == "run":
        stored = yaml.safe_load((out / "shared" / "config.yaml").read_text())
        assert robot_label(stored["robot"]) == "my_arm"


def test_a_ros_package_urdf_folder_is_named_after_its_package():
    assert robot_label("/ws/kuka_kr16_support/urdf") == "kuka_kr16_support"
    assert robot_label("/ws/kuka_kr16_support/urdf/kr16_2.urdf") == "kr16_2"
