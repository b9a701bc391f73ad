"""Issue 5 targets on the default profile (model -> calibration -> identification -> control). Slow."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import load_config
from pipeline.progress import Progress
from pipeline.runner import run_pipeline


@pytest.mark.slow
def test_feedforward_targets_on_the_iso_path(tmp_path):
    cfg = load_config(None, stages="control", values={"name": "targets"})
    res = run_pipeline(cfg, out_root=tmp_path, progress=Progress(enabled=False), log=lambda _: None)
    s = res.outputs["control"].summary
    assert s["feedforward_model"] == "identified" and s["kinematics"] == "calibrated"
    none, ff = "none", "full_friction"
    # identified full feedforward: >= 5x smaller max TCP tracking error and max lag error of axes 1-3
    assert s["tcp_tracking_error_max_m"][none] >= 5 * s["tcp_tracking_error_max_m"][ff]
    assert s["tcp_error_registered_max_m"][none] >= 5 * s["tcp_error_registered_max_m"][ff]
    assert np.all(np.asarray(s["lag_error_max_rad"][none]) >= 5 * np.asarray(s["lag_error_max_rad"][ff]))
    assert s["realtime_factor"] >= 10
    assert s["tcp_error_rms_calibrated_kinematics_m"] < s["tcp_error_rms_nominal_kinematics_m"]
    assert max(s["max_torque_ratio"].values()) <= 1.0
