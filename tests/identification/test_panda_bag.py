"""The UNISA Panda exciting trajectory (``data/unisa_panda_bag``): a bare rosbag2 ``.db3`` without its
``metadata.yaml``, ``sensor_msgs/JointState`` at about 30 Hz with non-uniform stamps, link-side
torques from the joint torque sensors. Through the CLI as a user would: example-robot-data's Panda
URDF through ``robot init`` (no options), then ``run --stages identification`` with the bag as
``identification.data_file`` and every other setting at its default. The held-out torque RMS (last
30 % of the record) must be at or below the Gaz et al. 2019 model's on every joint (the figures of
the record's README), and no simulated stage may run."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from pipeline import cli
from pipeline.core.config import REPO_ROOT
from pipeline.robot.public_arms import arm_file, corpus_arm

BAG = REPO_ROOT / "data" / "unisa_panda_bag" / "panda_exciting_trajectory.db3"
#: Gaz et al. 2019 (IEEE RA-L 4(4)) on the same held-out 30 %, N·m (data/unisa_panda_bag/README.md)
GAZ_2019_HELD_OUT_RMS_NM = np.array([0.777, 0.698, 0.985, 0.944, 0.158, 0.219, 0.073])


@pytest.mark.slow
def test_the_bag_as_shipped_beats_the_published_model_on_every_joint(tmp_path, capsys):
    urdf = arm_file(corpus_arm("panda"))
    if urdf is None:
        pytest.skip("example-robot-data is not installed")
    arm = tmp_path / "panda"
    arm.mkdir()
    shutil.copy(urdf, arm / "panda.urdf")
    assert cli.main(["robot", "init", str(arm / "panda.urdf")]) == 0
    out = tmp_path / "runs"
    code = cli.main(["run", "--set", f"robot={arm}", "--stages", "identification",
                     "--set", f"identification.data_file={BAG}", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    run = out / "panda"
    assert sorted(p.name for p in run.iterdir() if (p / "summary.json").is_file()) == ["identification", "model"]
    summary = json.loads((run / "identification" / "summary.json").read_text())
    rms = np.asarray(summary["validation_torque_rms_Nm"])
    assert rms.shape == (7,) and np.all(rms <= GAZ_2019_HELD_OUT_RMS_NM), rms
