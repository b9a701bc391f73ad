"""Servo design: gains from the reflected inertia, discrete loops stable with margins."""

from __future__ import annotations

import numpy as np

from pipeline.control.design import design_gains, filter_alpha, reflected_inertia, servo_report


def test_gains_scale_with_inertia_and_loops_meet_bandwidths(rx130l):
    q = np.array([0.0, 0.3, 1.5, 0.0, 1.2, 0.0])
    J = reflected_inertia(rx130l, q)
    assert np.all(J >= rx130l.model.armature)  # rotor inertia is part of it
    g = design_gains(J, 2 * np.pi * 5.0, 2 * np.pi * 30.0)
    np.testing.assert_allclose(g.kv / J, 2 * np.pi * 30.0)
    rows = servo_report(g, 4e-4, 2, 1, filter_alpha(400.0, 2e-4))
    for r in rows:
        assert r["velocity"]["closed_loop_stable"] and r["position"]["closed_loop_stable"]
        assert r["velocity"]["phase_margin_deg"] > 45 and r["velocity"]["gain_margin_db"] > 6
        assert r["position"]["phase_margin_deg"] > 45
        assert 20.0 < r["velocity_bandwidth_hz"] < 60.0
        assert 3.0 < r["position_bandwidth_hz"] < 10.0


def test_too_aggressive_velocity_loop_loses_margin(rx130l):
    J = reflected_inertia(rx130l, np.zeros(6))
    g = design_gains(J, 2 * np.pi * 5.0, 2 * np.pi * 600.0)
    rows = servo_report(g, 4e-4, 2, 1, filter_alpha(400.0, 2e-4))
    assert all(r["velocity"]["phase_margin_deg"] < 30 or not r["velocity"]["closed_loop_stable"] for r in rows)
