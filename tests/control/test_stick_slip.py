"""Stick-slip floor of the velocity gain: Kv + viscous above the steepest fall of the Stribeck curve."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.control.config import ControlConfig
from pipeline.control.design import design_gains, reflected_inertia, stick_slip_gains
from pipeline.control.simulate import servo_gains, simulate_joint_trajectory
from pipeline.core.errors import ConfigError
from pipeline.robot.friction import stribeck_excess_torque, stribeck_slope_Nms_rad
from pipeline.sim.truth import RealRobot, TruthConfig

Q0 = np.array([0.1, 0.3, 1.5, 0.2, 1.0, -0.3])


def test_slope_is_the_steepest_fall_of_the_stribeck_term():
    fs, vs = np.array([2.0, 0.5]), np.array([0.05, 0.2])
    v = np.linspace(0.0, 1.0, 200001)[:, None] * np.ones(2)
    fall = -np.gradient(stribeck_excess_torque(v, fs, vs, 0.0), v[:, 0], axis=0)[1:-1]
    np.testing.assert_allclose(fall.max(axis=0), stribeck_slope_Nms_rad(fs, vs), rtol=1e-4)


def test_floor_raises_only_the_joints_below_it_keeps_the_pi_zero_and_stops_at_the_cap():
    J = np.array([1.0, 0.05, 0.02, 0.001])
    g = design_gains(J, 2 * np.pi * 5.0, 2 * np.pi * 30.0)
    slope, viscous = np.array([10.0, 10.0, 0.0, 10.0]), np.ones(4)
    w_max = 2 * np.pi * 150.0
    out = stick_slip_gains(g, slope, viscous, 1.5, w_max)
    assert np.all((out.kv + viscous >= 1.5 * slope - 1e-12) | np.isclose(out.kv, J * w_max))
    assert out.kv[0] == g.kv[0] and out.kv[2] == g.kv[2] and out.kv[1] > g.kv[1]
    assert np.isclose(out.kv[3], J[3] * w_max) and out.kv[3] + viscous[3] < 1.5 * slope[3]   # capped
    assert np.all(out.kv <= np.maximum(g.kv, J * w_max) * (1 + 1e-12))
    np.testing.assert_allclose(out.ki / out.kv, g.ki / g.kv)
    np.testing.assert_array_equal(out.kp, g.kp)


def test_servo_gains_use_the_identified_stribeck_term_only_when_asked(rx130l):
    plain = servo_gains(rx130l, Q0, ControlConfig())
    np.testing.assert_allclose(plain.kv, design_gains(reflected_inertia(rx130l, Q0), 2 * np.pi * 5.0,
                                                      2 * np.pi * 30.0).kv)       # no Stribeck term: design only
    model = rx130l.copy()
    model.spec.actuation.static_friction_excess_Nm = np.full(6, 0.5 * model.actuation.coulomb_Nm.max())
    model.spec.actuation.stribeck_velocity_rad_s = np.full(6, 0.05)
    raised = servo_gains(model, Q0, ControlConfig())
    assert np.all(raised.kv >= plain.kv) and np.any(raised.kv > plain.kv)
    np.testing.assert_allclose(servo_gains(model, Q0, ControlConfig(stick_slip_margin=0.0)).kv, plain.kv)
    with pytest.raises(ConfigError, match="stick_slip_margin"):
        ControlConfig(stick_slip_margin=-1.0)


@pytest.mark.parametrize("compliance_scale", [1.0, 0.0])
def test_floor_removes_stick_slip_of_a_joint_creeping_through_rest(rx130l, compliance_scale):
    """The hidden robot's own model as feedforward, one joint reversing slowly (peak 0.06 rad/s, in the
    Stribeck band): below the floor it sticks and slips; with Kv at the floor the error falls >= 10x."""
    real = RealRobot.create(rx130l, 0, TruthConfig(joint_compliance_scale=compliance_scale))
    tr = real.transmission
    model = real.truth.copy()
    if compliance_scale > 0:
        model.spec.actuation.joint_stiffness_Nm_rad = real.joint_stiffness_Nm_rad.copy()
    model.friction_torque = lambda w: tr.friction_torque(np.asarray(w, float))  # type: ignore[method-assign]
    design = design_gains(reflected_inertia(model, Q0), 2 * np.pi * 5.0, 2 * np.pi * 30.0)
    slope = stribeck_slope_Nms_rad(tr.static_excess_Nm, tr.stribeck_velocity_rad_s)
    j = int(np.argmax(slope / (design.kv + tr.viscous_Nms_rad)))
    assert slope[j] > design.kv[j] + tr.viscous_Nms_rad[j]        # the case under test: below the floor
    t = 4e-4 * np.arange(5001)
    w = 2 * np.pi * 0.5
    q, v, a = np.tile(Q0, (len(t), 1)), np.zeros((len(t), 6)), np.zeros((len(t), 6))
    q[:, j] += 0.02 * (1 - np.cos(w * t))
    v[:, j], a[:, j] = 0.02 * w * np.sin(w * t), 0.02 * w * w * np.cos(w * t)
    cfg = ControlConfig(on_saturation="clip", benchmark_python_seconds=0.0)
    variant = "elastic_flat" if compliance_scale > 0 else "full_friction"
    errors = []
    raised = stick_slip_gains(design, slope, tr.viscous_Nms_rad, 1.5, 2 * np.pi * cfg.velocity_filter_hz)
    assert raised.kv[j] + tr.viscous_Nms_rad[j] >= 1.5 * slope[j]                # not capped here
    for gains in (design, raised):
        res = simulate_joint_trajectory(real, model, t, q, v, a, cfg, variant, np.random.default_rng(0), gains=gains)
        errors.append(np.abs(res.q_link[:, j] - q[:, j]).max())
    assert errors[1] < errors[0] / 10
