"""A derived ISO path slowed to the torque limits: by the model's inverse dynamics before the runs
(:func:`pipeline.robot.reference.torque_time_scale`, exact for a time-scaled reference), and by the
closed loop's commands after them (:func:`pipeline.control.measure.runs_within_torque`); a cube given
in the config runs as given and its saturation is the error it was."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.control import stage
from pipeline.control.config import ControlConfig
from pipeline.control.design import IsoReference, iso_reference, slowed_reference
from pipeline.core.errors import InfeasibleError
from pipeline.core.progress import Progress
from pipeline.robot.reference import PATH_TORQUE_SHARE, cartesian_reference, torque_time_scale
from pipeline.sim.truth import RealRobot, TruthConfig
from pipeline.stage_api import StageContext, stage_rng

#: torque limits of the RX130L's axis 1 (vertical: no gravity torque) on the ISO line at the configured
#: 1 m/s, 5 m/s^2: the model's torque above PATH_TORQUE_SHARE of it; the model's within it, the closed
#: loop's commands (the servo's corrections, the hidden robot's deviations) above it
MODEL_LIMITED_AXIS_1_NM = 60.0
LOOP_LIMITED_AXIS_1_NM = 110.0


def _peak_ratio(robot, ref) -> float:
    tau = np.array([robot.inverse_dynamics(q, v, a) for q, v, a in zip(ref.q_d, ref.v_d, ref.a_d, strict=True)])
    return float(np.max(np.abs(tau) / robot.limits.effort_Nm))


def _weak(rx130l, axis_1_Nm: float):
    robot = rx130l.copy()
    robot.model.effortLimit[0] = axis_1_Nm
    return robot


@pytest.fixture(scope="module")
def weak_rx130l(rx130l):
    return _weak(rx130l, MODEL_LIMITED_AXIS_1_NM)


@pytest.fixture(scope="module")
def loop_limited_rx130l(rx130l):
    return _weak(rx130l, LOOP_LIMITED_AXIS_1_NM)


def _line_config() -> ControlConfig:
    cfg = ControlConfig(benchmark_python_seconds=0.0, settle_time_s=0.1)
    cfg.iso.segments = ["line"]
    return cfg


def test_the_time_scale_is_exact_for_the_slowed_reference(weak_rx130l):
    cfg = _line_config()
    full = iso_reference(weak_rx130l, cfg)
    assert full.time_scale < 1.0 and full.derived_cube
    given = cfg.iso
    unslowed = cartesian_reference(weak_rx130l, full.path, cfg.sample_time_s, given.speed_m_s, given.acceleration_m_s2,
                                   given.jerk_m_s3, full.q_start, full.frame)
    assert _peak_ratio(weak_rx130l, unslowed) > 1.0
    # the closed form tau(s) = s^2 (rnea - g) + g + friction(s v) against the regenerated reference
    s = torque_time_scale(weak_rx130l, unslowed)
    assert full.time_scale == np.floor(100 * s) / 100
    assert _peak_ratio(weak_rx130l, full.ref) <= PATH_TORQUE_SHARE
    unslowed_iso = IsoReference(unslowed, full.path, full.frame, full.seeds, full.q_start, given, 0.0)
    faster = slowed_reference(weak_rx130l, cfg, unslowed_iso, full.time_scale + 0.01 + 1e-9)    # one percent more
    assert _peak_ratio(weak_rx130l, faster.ref) > PATH_TORQUE_SHARE
    assert full.ref.t_s[-1] == pytest.approx(unslowed.t_s[-1] / full.time_scale, abs=2 * cfg.sample_time_s)
    assert full.iso.acceleration_m_s2 == pytest.approx(given.acceleration_m_s2 * full.time_scale**2)


def test_a_path_within_the_limits_is_not_slowed(rx130l):
    out = iso_reference(rx130l, _line_config())
    assert out.time_scale == 1.0 and out.iso.speed_m_s == 1.0 and out.iso.acceleration_m_s2 == 5.0


def _run(quick_config, robot, tmp_path, cfg):
    real = RealRobot.create(robot, 1, TruthConfig())
    ctx = StageContext(run=quick_config, config=cfg, robot=robot.copy(), real=real, upstream={}, out_dir=tmp_path,
                       rng=stage_rng(quick_config.seed, "control"), progress=Progress(enabled=False))
    return stage.run(ctx)


def test_a_derived_path_runs_within_the_torque_limits_and_says_so(quick_config, loop_limited_rx130l, tmp_path):
    cfg = _line_config()
    cfg.variants = ["none", "full_friction"]
    assert iso_reference(loop_limited_rx130l, cfg).time_scale == 1.0      # the model asks less than the share
    res = _run(quick_config, loop_limited_rx130l, tmp_path, cfg)
    s = res.summary
    assert s["path_time_scale"] < 1.0 and not s["saturation"]
    assert max(s["max_torque_ratio"].values()) <= cfg.saturation_ratio
    assert s["tcp_speed_m_s"] == pytest.approx(s["path_time_scale"])     # of the configured 1 m/s
    assert "The derived ISO path is slowed by" in res.report_md


def test_a_given_cube_is_not_slowed_and_its_saturation_is_an_error(quick_config, weak_rx130l, tmp_path):
    cfg = _line_config()
    derived = iso_reference(weak_rx130l, cfg)
    assert derived.time_scale < 1.0
    cfg.iso.centre_m, cfg.iso.edge_m = list(derived.iso.centre_m), float(derived.iso.edge_m)
    cfg.iso.tool_orientation = derived.iso.tool_orientation
    cfg.variants = ["full_friction"]
    assert iso_reference(weak_rx130l, cfg).time_scale == 1.0
    with pytest.raises(InfeasibleError, match="torque saturation .* on joint 1"):
        _run(quick_config, weak_rx130l, tmp_path, cfg)
