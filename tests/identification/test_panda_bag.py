"""The UNISA Panda exciting trajectory (``data/unisa_panda_bag``): a bare rosbag2 ``.db3`` without its
``metadata.yaml``, ``sensor_msgs/JointState`` at about 30 Hz with non-uniform stamps, link-side
torques from the joint torque sensors. Through the CLI as a user would: example-robot-data's Panda
URDF through ``robot init`` (no options), then ``run --stages identification`` with the bag as
``identification.data_file`` and every other setting at its default. The held-out torque RMS (last
30 % of the record) must be at or below the Gaz et al. 2019 model's on every joint (the figures of
the record's README), and no simulated stage may run."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.config import REPO_ROOT

from .helpers import identify_recorded_bag

BAG = REPO_ROOT / "data" / "unisa_panda_bag" / "panda_exciting_trajectory.db3"
#: Gaz et al. 2019 (IEEE RA-L 4(4)) on the same held-out 30 %, N·m (data/unisa_panda_bag/README.md)
GAZ_2019_HELD_OUT_RMS_NM = np.array([0.777, 0.698, 0.985, 0.944, 0.158, 0.219, 0.073])


@pytest.mark.slow
def test_the_bag_as_shipped_beats_the_published_model_on_every_joint(tmp_path):
    run, summary = identify_recorded_bag(tmp_path, "panda", BAG)
    assert sorted(p.name for p in run.iterdir() if (p / "summary.json").is_file()) == ["identification", "model"]
    rms = np.asarray(summary["validation_torque_rms_Nm"])
    assert rms.shape == (7,) and np.all(rms <= GAZ_2019_HELD_OUT_RMS_NM), rms
