"""Stage ``control`` on the quick profile: runs without upstream stages, uses calibrated ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.control import stage
from pipeline.control.config import ControlConfig
from pipeline.control.estimate import with_dynamics_of
from pipeline.core.errors import ConfigError
from pipeline.core.progress import Progress
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.stage_api import StageContext, StageOutput, stage_rng

REQUIRED = ("sample_time_s", "delay_samples", "tcp_error_max_m", "tcp_error_rms_m", "lag_error_max_rad",
            "realtime_factor", "tcp_error_rms_nominal_kinematics_m", "tcp_error_rms_calibrated_kinematics_m")


def _ctx(quick_config, robot, real, upstream, tmp_path: Path) -> StageContext:
    return StageContext(run=quick_config, config=quick_config.control, robot=robot, real=real, upstream=upstream,
                        out_dir=tmp_path, rng=stage_rng(quick_config.seed, "control"),
                        progress=Progress(enabled=False))


@pytest.fixture(scope="module")
def real(rx130l):
    return RealRobot.create(rx130l, 1, TruthConfig())


def test_stage_without_upstream(quick_config, rx130l, real, tmp_path):
    """The quick profile on the ISO path's line alone (its large circle: the references of
    test_reference_simulate.py and test_paths.py; the whole quick path through the stage: the control
    notebook's slow twin and the whole-pipeline runs of make test-slow)."""
    quick_config.control.iso.segments = ["line"]
    res = stage.run(_ctx(quick_config, rx130l.copy(), real, {}, tmp_path))
    s = res.summary
    for key in REQUIRED:
        assert key in s, key
    assert set(s["tcp_error_max_m"]) == set(quick_config.control.variants) == set(s["tcp_error_registered_max_m"])
    assert {"none", "full_friction"} <= set(s["tcp_error_max_m"])
    if "elastic_flat" in s["tcp_error_max_m"]:   # no calibration: every joint's stiffness is nominal
        assert s["joint_stiffness"]["nominal_joints"] == [1, 2, 3, 4, 5, 6]
        assert "this run has no elastostatic calibration" in res.report_md
    assert len(s["lag_error_max_rad"]["none"]) == 3
    assert s["sample_time_s"] == 4e-4 and s["delay_samples"] == {"setpoint": 2, "measurement": 1}
    assert s["feedforward_model"] == "nominal" and s["kinematics"] == "nominal"
    # without calibration both kinematics numbers are the same run
    assert s["tcp_error_rms_nominal_kinematics_m"] == s["tcp_error_rms_calibrated_kinematics_m"]
    # feedforward (nominal model) reduces the lag errors of axes 1-3
    assert all(f < n for f, n in zip(s["lag_error_max_rad"]["full_friction"], s["lag_error_max_rad"]["none"],
                                      strict=True))
    assert s["realtime_factor"] > 0 and s["speedup_vs_python_loop"] > 1.0
    t, q = res.arrays["trajectory_iso_t"], res.arrays["trajectory_iso_q"]
    assert q.shape == (len(t), 6) and np.all(np.diff(t) > 0)
    assert {"lag_errors", "tcp_error", "iso_path", "servo_bode"} <= set(res.figures)


def test_stage_with_calibrated_kinematics_and_a_nominal_comparison(quick_config, rx130l, real, tmp_path):
    """A perfect calibration (the hidden kinematics with the nominal dynamics) and an identification stage
    upstream. compare_nominal_feedforward without the full_friction variant: the nominal-model run is an
    extra comparison, never the reported main variant (the user's last one)."""
    calibrated = with_dynamics_of(real.truth, rx130l)
    upstream = {"calibration": StageOutput({}, {}, {}, calibrated, tmp_path),
                "identification": StageOutput({}, {}, {}, calibrated.copy(), tmp_path)}
    cfg = quick_config.control
    # the main variant elastic_flat: on the elastic truth rigid feedforward leaves the mm-level joint deflection
    cfg.variants, cfg.compare_nominal_feedforward = ["none", "elastic_flat"], True
    cfg.benchmark_python_seconds = 0.0
    cfg.iso.segments = ["line"]
    res = stage.run(_ctx(quick_config, calibrated.copy(), real, upstream, tmp_path))
    s = res.summary
    assert s["kinematics"] == "calibrated" and s["feedforward_model"] == "identified"
    assert set(s["tcp_error_max_m"]) == {"none", "elastic_flat", "full_friction_nominal"}
    assert s["tcp_error_rms_calibrated_kinematics_m"] == s["tcp_error_rms_m"]["elastic_flat"] \
        != s["tcp_error_rms_m"]["full_friction_nominal"]
    # nominal kinematics: mm-level absolute error; calibrated: only the tracking error remains
    assert s["tcp_error_rms_nominal_kinematics_m"] > 5 * s["tcp_error_rms_calibrated_kinematics_m"]
    # a calibration without compliances: every joint's stiffness is nominal, and the report says what it is worth
    js = s["joint_stiffness"]
    assert js["nominal_joints"] == [1, 2, 3, 4, 5, 6] and js["gravity_model_factor"] == [1.0] * 6
    assert max(js["tcp_deflection_max_m"]) > 0 and "nominal stiffness" in res.report_md


@pytest.mark.parametrize("kwargs", [{"engine": "fortran"}, {"on_saturation": "ignore"}, {"variants": ["magic"]},
                                    {"setpoint_delay_samples": -1}, {"iso": {"plane": "vertical"}},
                                    {"iso": {"edge_m": 0.0}}])
def test_bad_config_is_a_config_error(kwargs):
    with pytest.raises(ConfigError, match="control"):
        ControlConfig(**kwargs)
