"""Feedforward targets (rigid and elastic-joint truth) on the default profile
(model -> calibration -> identification -> control). Slow."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.core.config import load_config
from pipeline.core.progress import Progress
from pipeline.run.runner import run_pipeline
from pipeline.sim.truth import TruthConfig

RIGID = {"truth.joint_compliance_scale": 0.0, "truth.stribeck_excess_relative": 0.0,
         "truth.coulomb_load_coefficient": 0.0}


def _control_summary(tmp_path, values: dict) -> dict:
    cfg = load_config(None, stages="control", values={"name": "targets", **values})
    res = run_pipeline(cfg, out_root=tmp_path, progress=Progress(enabled=False), log=lambda _: None)
    return res.outputs["control"].summary


@pytest.mark.slow
def test_feedforward_targets_on_the_rigid_arm(tmp_path):
    """Rigid feedforward figures (>= 5x smaller TCP and lag errors) with elasticity and Stribeck friction
    set to 0 in the truth. The real-time factor is a speed figure: benchmarks/bench_control.py prints it."""
    if "joint_compliance_scale" not in {f.name for f in dataclasses.fields(TruthConfig)}:
        pytest.skip("truth.joint_compliance_scale (the calibration's stiffness block) is not in TruthConfig")
    s = _control_summary(tmp_path, RIGID)
    assert s["feedforward_model"] == "identified" and s["kinematics"] == "calibrated"
    none, ff = "none", "full_friction"
    # identified full feedforward: >= 5x smaller max TCP tracking error and max lag error of axes 1-3
    assert s["tcp_tracking_error_max_m"][none] >= 5 * s["tcp_tracking_error_max_m"][ff]
    assert s["tcp_error_registered_max_m"][none] >= 5 * s["tcp_error_registered_max_m"][ff]
    assert np.all(np.asarray(s["lag_error_max_rad"][none]) >= 5 * np.asarray(s["lag_error_max_rad"][ff]))
    assert s["tcp_error_rms_calibrated_kinematics_m"] < s["tcp_error_rms_nominal_kinematics_m"]
    assert max(s["max_torque_ratio"].values()) <= 1.0


@pytest.mark.slow
def test_elastic_feedforward_targets(tmp_path):
    """On the elastic, Stribeck truth the elastic-joint feedforward beats rigid full_friction >= 3x
    and no feedforward >= 10x in max TCP tracking error on the ISO path."""
    s = _control_summary(tmp_path, {})
    e = s["tcp_tracking_error_max_m"]
    assert e["full_friction"] >= 3 * e["elastic_flat"]
    assert e["none"] >= 10 * e["elastic_flat"]
    assert max(s["max_torque_ratio"].values()) <= 1.0
