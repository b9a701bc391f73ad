"""The joint stiffness of the elastic feedforward: gravity-model re-expression, sources, deflection budget."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.control.joint_stiffness import deflection_budget, feedforward_stiffness, stiffness_markdown
from pipeline.robot.handoff import ElastostaticRecord
from pipeline.robot.stiffness import nominal_joint_stiffness_Nm_rad, stiffness_for_gravity_model

IDENTIFIED = np.array([False, True, True, False, True, False])


def test_reexpressed_stiffness_inverts_the_least_squares_projection():
    """Deflections c' g' fitted against a wrong model g give c = c' <g, g'> / <g, g>; re-expressing
    1/c for g' returns 1/c' exactly on the identified joints and leaves the others alone."""
    rng = np.random.default_rng(0)
    g_true = rng.normal(0.0, 500.0, (40, 6))
    g_model = g_true * np.exp(0.15 * rng.standard_normal(6)) + rng.normal(0.0, 50.0, (40, 6))
    c_true = 1.0 / rng.uniform(1e4, 4e5, 6)
    c_fit = np.sum(c_true * g_true * g_model, axis=0) / np.sum(g_model**2, axis=0)
    k, s = stiffness_for_gravity_model(1.0 / c_fit, IDENTIFIED, g_model, g_true)
    np.testing.assert_allclose(k[IDENTIFIED], 1.0 / c_true[IDENTIFIED], rtol=1e-12)
    np.testing.assert_array_equal(k[~IDENTIFIED], 1.0 / c_fit[~IDENTIFIED])
    assert np.all(s[~IDENTIFIED] == 1.0)
    # the same gravity model: nothing changes; no load on a joint: nothing to re-express
    np.testing.assert_allclose(stiffness_for_gravity_model(1.0 / c_fit, IDENTIFIED, g_model, g_model)[1], 1.0)
    g0 = g_model.copy()
    g0[:, 1] = 0.0
    assert stiffness_for_gravity_model(1.0 / c_fit, IDENTIFIED, g0, g_true)[1][1] == 1.0


def _record(robot, Q, scale):
    g = np.array([robot.gravity_torque(q) for q in Q]) * scale
    return {"elastostatic_configurations_rad": Q, "elastostatic_torques_Nm": g,
            "elastostatic_payload_torques_Nm": np.zeros_like(g), "joint_stiffness_identified": IDENTIFIED}


def test_feedforward_stiffness_sources_and_gravity_factor(rx130l):
    """A calibration whose gravity model gave 0.8x the torques of the identified one under-estimated the
    compliances by that factor: its stiffness is scaled by 0.8 on the identified joints only."""
    robot = rx130l.copy()
    k_cal = nominal_joint_stiffness_Nm_rad(robot) * 1.1
    robot.spec.actuation.joint_stiffness_Nm_rad = k_cal
    Q = np.random.default_rng(1).uniform(-1.0, 1.0, (30, 6))
    rec = _record(robot, Q, 1.0 / 0.8)
    choice = feedforward_stiffness(robot, ElastostaticRecord.from_arrays(rec, 6), identified_inertias=True)
    loaded = IDENTIFIED & (np.abs(rec["elastostatic_torques_Nm"]).max(axis=0) > 1e-6)
    np.testing.assert_allclose(choice.stiffness_Nm_rad[loaded], 0.8 * k_cal[loaded], rtol=1e-9)
    np.testing.assert_array_equal(choice.stiffness_Nm_rad[~IDENTIFIED], k_cal[~IDENTIFIED])
    assert choice.nominal_joints == [1, 4, 6]
    assert choice.source[1] == "calibrated, identified gravity"
    # no identified inertias: the calibration's stiffness as it is; no record: every joint nominal
    same = feedforward_stiffness(robot, ElastostaticRecord.from_arrays(rec, 6), identified_inertias=False)
    np.testing.assert_array_equal(same.stiffness_Nm_rad, k_cal)
    assert same.source[1] == "calibrated" and np.all(same.gravity_factor == 1.0)
    assert feedforward_stiffness(robot, None, True).nominal_joints == [1, 2, 3, 4, 5, 6]
    # a stiffness that is not the nominal one but has no record behind it is named as handed on
    handed = feedforward_stiffness(robot, None, True, nominal_joint_stiffness_Nm_rad(rx130l))
    assert handed.source == ["as handed on"] * 6 and handed.nominal_joints == []


def test_deflection_budget_scales_with_the_compliance(rx130l):
    rng = np.random.default_rng(2)
    q = np.array([0.1, 0.4, 1.4, 0.2, 0.9, -0.3]) + 0.05 * rng.standard_normal((20, 6))
    v, a = rng.normal(0, 0.5, (20, 6)), rng.normal(0, 3.0, (20, 6))
    k = nominal_joint_stiffness_Nm_rad(rx130l)
    b1 = deflection_budget(rx130l, q, v, a, k, "tcp", stride=1)
    b2 = deflection_budget(rx130l, q, v, a, 2 * k, "tcp", stride=1)
    np.testing.assert_allclose(b2["tcp_deflection_max_m"], 0.5 * np.asarray(b1["tcp_deflection_max_m"]))
    assert all(t > 0 for t in b1["tcp_deflection_max_m"][:3])  # the main axes carry gravity
    choice = feedforward_stiffness(rx130l, None, False)
    md = stiffness_markdown(choice, b1)
    assert "Joints 1, 2, 3, 4, 5, 6: nominal stiffness" in md
    assert md.count("| nominal |") == 6


@pytest.mark.parametrize("bad", [np.zeros(6), -np.ones(6)])
def test_gravity_factor_needs_a_positive_correlation(bad, rx130l):
    """Torques that vanish or flip sign between the models carry no scale: the factor stays 1."""
    k, s = stiffness_for_gravity_model(np.ones(6), np.ones(6, bool), np.ones((5, 6)), bad * np.ones((5, 6)))
    assert np.all(s == 1.0) and np.all(k == 1.0)


def test_insignificant_compliance_falls_back_to_the_nominal_stiffness(rx130l):
    """A compliance within 3 standard deviations of zero (a barely loaded wrist) says little: nominal."""
    robot = rx130l.copy()
    k_nom = nominal_joint_stiffness_Nm_rad(robot)
    k_cal = k_nom * np.array([1.0, 1.2, 0.8, 1.0, 0.05, 1.0])        # joint 5: 20x too soft, poorly determined
    robot.spec.actuation.joint_stiffness_Nm_rad = k_cal
    rec = _record(robot, np.random.default_rng(3).uniform(-1.0, 1.0, (30, 6)), 1.0)
    rec["joint_compliance_std"] = np.where(IDENTIFIED, 0.1 / k_cal, np.nan)
    rec["joint_compliance_std"][4] = 0.5 / k_cal[4]                   # c = 2 sigma
    choice = feedforward_stiffness(robot, ElastostaticRecord.from_arrays(rec, 6), identified_inertias=True,
                                   nominal_Nm_rad=k_nom)
    assert choice.nominal_joints == [1, 4, 5, 6]
    assert choice.stiffness_Nm_rad[4] == k_nom[4] and choice.source[4].startswith("nominal (")
    np.testing.assert_allclose(choice.stiffness_Nm_rad[[1, 2]], k_cal[[1, 2]], rtol=1e-9)  # same gravity model
    assert choice.source[1] == "calibrated, identified gravity"
