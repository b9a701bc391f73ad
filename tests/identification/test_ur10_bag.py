"""The UNISA UR10 exciting trajectory (``data/unisa_ur10_bag``): a bare rosbag2 ``.db3`` of a
current-controlled cobot, ``sensor_msgs/JointState`` at 125 Hz, efforts as drive gain x motor current.
Through the CLI as a user would: example-robot-data's UR10 URDF through ``robot init`` (no options), then
``run --stages identification`` with the bag as ``identification.data_file`` and every other setting at
its default. Against the authors' model (Petrone et al. 2025) on the same held-out samples (the figures
of the record's README): the held-out torque RMS over all joints must be at or below theirs, and so on
each joint where the record's README says it is; on the others the stage must say that its model class
leaves structure there, not pass them silently."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from pipeline import cli
from pipeline.core.config import REPO_ROOT
from pipeline.robot.public_arms import arm_file, corpus_arm

BAG = REPO_ROOT / "data" / "unisa_ur10_bag" / "ur10_exciting_trajectory.db3"
#: Petrone, Ferrentino & Chiacchio 2025 (IEEE TII) on the same held-out 30 %, N·m (data/unisa_ur10_bag/README.md)
PETRONE_2025_HELD_OUT_RMS_NM = np.array([4.093, 3.165, 1.743, 0.485, 0.632, 1.006])
#: joints (1-based) on which the stage's defaults are at or below the authors' model (README)
JOINTS_AT_OR_BELOW = (1, 2, 5)


@pytest.mark.slow
def test_the_bag_as_shipped_against_the_published_model(tmp_path, capsys):
    urdf = arm_file(corpus_arm("ur10"))
    if urdf is None:
        pytest.skip("example-robot-data is not installed")
    arm = tmp_path / "ur10"
    arm.mkdir()
    shutil.copy(urdf, arm / "ur10.urdf")
    assert cli.main(["robot", "init", str(arm / "ur10.urdf")]) == 0
    out = tmp_path / "runs"
    code = cli.main(["run", "--set", f"robot={arm}", "--stages", "identification",
                     "--set", f"identification.data_file={BAG}", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((out / "ur10" / "identification" / "summary.json").read_text())
    rms = np.asarray(summary["validation_torque_rms_Nm"])
    assert rms.shape == (6,)
    assert np.sqrt(np.mean(rms ** 2)) <= np.sqrt(np.mean(PETRONE_2025_HELD_OUT_RMS_NM ** 2)), rms
    for joint in JOINTS_AT_OR_BELOW:
        assert rms[joint - 1] <= PETRONE_2025_HELD_OUT_RMS_NM[joint - 1], (joint, rms)
    worse = [j + 1 for j in range(6) if rms[j] > PETRONE_2025_HELD_OUT_RMS_NM[j]]
    assert set(worse) <= set(summary["model_class_structure_joints"]), (worse, summary["model_class_structure_joints"])
    assert summary["effort_unit_status"] == "joint torques"
